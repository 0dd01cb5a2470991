"""Clinical metrics of a laryngoscopy: forces, technique, smoothness and the view of the glottis.

Pure numpy, no device and no plotting: the haptic envs feed :class:`ClinicalRecorder` every step
and report its :meth:`~ClinicalRecorder.summary` in ``info["clinical"]`` at an episode's last step;
trainee scoring and the benchmark read the same summary.

Smoothness (of the hand's speed, sampled at the control rate ``fs``):

* **SPARC**, spectral arc length (Balasubramanian, Melendez-Calderon, Roby-Brami & Burdet 2015,
  J NeuroEng Rehabil 12:112): minus the arc length of the speed's Fourier magnitude spectrum,
  normalised to 1 at 0 Hz, over ``[0, fc]`` with frequency normalised to ``fc``, where ``fc`` is the
  last frequency below 10 Hz whose magnitude reaches 0.05; the signal zero-padded 4 levels. One
  smooth movement scores about -1.4 to -1.6; every extra submovement or tremor lowers it.
* **LDLJ**, log dimensionless jerk (Balasubramanian et al. 2012, 2015; Hogan & Sternad 2009):
  ``-ln(T^3 / v_peak^2 * integral (d^2 v / dt^2)^2 dt)`` over the movement's duration ``T``. A
  minimum-jerk movement scores ``-ln(720 / 1.875^2) = -5.32``; less smooth movements lower it.

Both are NaN for a hand that never moved or fewer than 3 speed samples (the start and 2 steps):
smoothness is undefined there, not perfect.

Levering (``lever_share``): the share of the hand's moment about the incisal edge (the wrist's plus
that of its force at the grip, in absolute value, summed over the steps) applied while the blade
bears on the incisors. A blade that presses the tongue along the handle, clear of the teeth, scores
0. A blade pivoted on the teeth to press the tongue with its tip uses them as the fulcrum of a lever:
in equilibrium the hand's moment about the incisal edge then balances the tongue's (the incisors'
own force passes through the edge, up to its friction on the round bar), so every newton-metre the
hand turns the blade by is levered on the teeth, and a trainee who only levers scores 1. Resting the
blade on the teeth with nothing to turn against applies no moment about them: that is pressing on
the teeth, caught by the incisor force and contact time, not levering.

The glottic-view proxy (a POGO-like percentage of glottic opening). In the sagittal plane ``y = 0``
(``+x`` toward the mouth, ``+z`` up; the tongue's rest centre at the origin, radius ``R``), the
laryngoscopist's eye sits at ``EYE = (3.0, 1.6) R``, in front of and above the tongue, and the glottic
opening is the vertical segment ``x = -1.3 R``, ``z`` from ``0.2 R`` to ``0.9 R``, behind it (placed so
that the line of sight grazes the dorsum where the targets press, 75-110 deg of arc from the front). A point
of the opening is visible when the straight line from the eye to it passes above the deformed
tongue's sagittal profile (the triangulated surface cut by ``y = 0``). The profile is piecewise
linear, so the line clears it iff it clears the profile's vertices; the highest vertex as seen from
the eye, projected onto the opening, is where the view begins. The view is the visible share of the
opening, 0-100 %. The rest tongue leaves 19 % of it in view (the tangent from the eye to the circle:
:func:`rest_view_analytic`, tested against the mesh); pressing the dorsum down or sweeping the
tongue aside opens more (a top flattened to 0.8 R: 37 %).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

EYE = (3.0, 1.6)                        # in tongue radii: in front of and above the dorsum
GLOTTIS_X = -1.3                        # the opening's plane, behind the tongue (radii)
GLOTTIS_Z = (0.2, 0.9)                  # its lower and upper ends (radii)


def sparc(speed: np.ndarray, fs: float, padlevel: int = 4, fc: float = 10.0, amp_th: float = 0.05) -> float:
    """Spectral arc length of a speed profile sampled at ``fs`` Hz (see the module docstring)."""
    v = np.asarray(speed, dtype=np.float64).reshape(-1)
    if v.size < 3 or not np.any(v):
        return math.nan
    nfft = int(2 ** (math.ceil(math.log2(v.size)) + padlevel))
    f = np.arange(nfft) * (fs / nfft)
    magnitude = np.abs(np.fft.fft(v, nfft))
    magnitude = magnitude / magnitude.max()
    keep = f <= fc
    f, magnitude = f[keep], magnitude[keep]
    above = np.flatnonzero(magnitude >= amp_th)
    f, magnitude = f[above[0]:above[-1] + 1], magnitude[above[0]:above[-1] + 1]
    if f.size < 2:
        return math.nan
    return float(-np.sum(np.sqrt((np.diff(f) / (f[-1] - f[0])) ** 2 + np.diff(magnitude) ** 2)))


def ldlj(speed: np.ndarray, fs: float) -> float:
    """Log dimensionless jerk of a speed profile sampled at ``fs`` Hz (see the module docstring)."""
    v = np.asarray(speed, dtype=np.float64).reshape(-1)
    peak = float(np.max(np.abs(v))) if v.size else 0.0
    if v.size < 3 or peak == 0.0:
        return math.nan
    dt = 1.0 / fs
    duration = (v.size - 1) * dt
    second = np.diff(v, 2) / dt ** 2
    # trapezoidal rule over the interior samples of d^2v/dt^2
    integral = float(np.sum(second * second) * dt)
    return -math.log(max(duration ** 3 / peak ** 2 * integral, 1e-300))


def sagittal_profile(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """``(m, 2)`` points ``(x, z)`` where the triangulated surface crosses the plane ``y = 0``: each
    edge with ends on opposite sides contributes its crossing (vertices on the plane count too)."""
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    t = np.asarray(triangles)
    edges = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    a, b = v[edges[:, 0]], v[edges[:, 1]]
    ya, yb = a[:, 1], b[:, 1]
    cross = (ya * yb < 0.0)
    s = ya[cross] / (ya[cross] - yb[cross])
    points = a[cross] + s[:, None] * (b[cross] - a[cross])
    on_plane = v[v[:, 1] == 0.0]
    return np.concatenate([points[:, [0, 2]], on_plane[:, [0, 2]]])


def glottic_view(profile: np.ndarray, radius: float) -> float:
    """Visible share (%) of the glottic opening past a sagittal ``profile`` ``(m, 2)`` (metres; see
    the module docstring)."""
    p = np.asarray(profile, dtype=np.float64).reshape(-1, 2) / radius
    ex, ez = EYE
    between = (p[:, 0] > GLOTTIS_X) & (p[:, 0] < ex)
    low, high = GLOTTIS_Z
    if not between.any():
        return 100.0
    x, z = p[between, 0], p[between, 1]
    # where the line from the eye over each profile point meets the opening's plane
    shadow = float(np.max(ez + (z - ez) * (GLOTTIS_X - ex) / (x - ex)))
    return 100.0 * float(np.clip((high - shadow) / (high - low), 0.0, 1.0))


def rest_view_analytic(radius: float = 1.0) -> float:
    """The view past the undeformed sphere in closed form: the tangent from the eye to the circle."""
    ex, ez = EYE
    d2 = ex * ex + ez * ez
    # the upper tangent point of the unit circle seen from (ex, ez)
    root = math.sqrt(d2 - 1.0)
    tx, tz = (ex - ez * root) / d2, (ez + ex * root) / d2
    if tz < 0 or (ex * tx + ez * tz) < 1.0 - 1e-12:
        tx, tz = (ex + ez * root) / d2, (ez - ex * root) / d2
    shadow = ez + (tz - ez) * (GLOTTIS_X - ex) / (tx - ex)
    low, high = GLOTTIS_Z
    return 100.0 * min(max((high - shadow) / (high - low), 0.0), 1.0)


COLUMNS = ("tongue_force_N", "incisor_force_N", "hand_x_m", "hand_z_m", "hand_y_m", "wrist_moment_Nm",
           "lift_moment_Nm", "jaw_force_N")


class ClinicalRecorder:
    """A log of ``n`` devices' episodes, one row per control step, and their clinical metrics.

    Each step writes per-device :data:`COLUMNS`: tongue and incisor force (N), the hand's position
    (m), the two parts of the hand's moment about the incisal edge (N m): the wrist's (the rotary
    coupling) and that of the hand's force at the grip, and the jaw's push (N; 0 without lower
    incisors). Row 0 holds
    the start pose. :meth:`summary` computes everything from one device's rows, so one env and the
    batched twin's env ``i`` get the same numbers bit for bit.
    """

    def __init__(self, n: int, dt: float, horizon: int) -> None:
        self.dt = dt
        self.log = np.zeros((horizon + 1, n, len(COLUMNS)))
        self.steps = np.zeros(n, dtype=np.int64)

    def start(self, rows: Any, values: np.ndarray | tuple[float, ...]) -> None:
        """Begin episodes of these devices with their rest values ``(len(rows), 8)`` (a single env's: a tuple)."""
        self.steps[rows] = 0
        self.log[0, rows] = values

    def record_one(self, values: tuple[float, ...]) -> None:
        """One step of device 0 (a single env): a tuple of Python floats in :data:`COLUMNS` order."""
        t = self.steps[0] = min(self.steps[0] + 1, len(self.log) - 1)
        self.log[t, 0] = values

    def record(self, rows: np.ndarray, values: np.ndarray) -> None:
        """One step of the devices ``rows`` (indices): ``values`` ``(len(rows), 8)``."""
        t = self.steps[rows] = np.minimum(self.steps[rows] + 1, len(self.log) - 1)
        self.log[t, rows] = values

    def summary(self, i: int, view_pct: float) -> dict[str, float]:
        """Device ``i``'s episode so far, with the glottic view (%) of its current shape."""
        return episode_metrics(np.ascontiguousarray(self.log[:self.steps[i] + 1, i]), self.dt, view_pct)


def episode_metrics(log: np.ndarray, dt: float, view_pct: float) -> dict[str, float]:
    """Clinical metrics of one episode's log ``(steps + 1, 8)`` (row 0: the start; :data:`COLUMNS`)."""
    steps = len(log) - 1
    duration = steps * dt
    rows = log[1:]
    tongue, incisor = rows[:, 0], rows[:, 1]
    # the hand's whole moment about the incisal edge: the wrist's plus that of its force at the grip
    moment = np.abs(rows[:, 5] + rows[:, 6])
    moves = np.sqrt(np.sum(np.diff(log[:, 2:5], axis=0) ** 2, axis=1))
    speed = np.concatenate([[0.0], moves / dt])                 # the hand at rest before the episode
    moments = float(np.sum(moment))
    return {"duration_s": duration,
            "peak_tongue_force_N": float(tongue.max(initial=0.0)),
            "mean_tongue_force_N": float(np.mean(tongue)) if steps else 0.0,
            "tongue_force_time_Ns": float(np.sum(tongue) * dt),
            "peak_incisor_force_N": float(incisor.max(initial=0.0)),
            "incisor_contact_s": float(np.count_nonzero(incisor > 0.0) * dt),
            "peak_jaw_force_N": float(rows[:, 7].max(initial=0.0)),
            "lever_share": float(np.sum(moment[incisor > 0.0])) / moments if moments > 0.0 else 0.0,
            "hand_path_m": float(np.sum(moves)),
            "sparc": sparc(speed, 1.0 / dt), "ldlj": ldlj(speed, 1.0 / dt),
            "glottic_view_pct": float(view_pct)}
