"""The simulated laryngoscope: a rigid blade in pymunk, dragged by a hand through a virtual coupling,
pressing the tongue and levering on the upper incisors.

Frame (SI units). The sagittal plane is pymunk's plane: ``X`` is the patient's front (the world's
``x``: the mouth), ``Y`` is up (the world's ``z``: the tongue's dorsum). The tongue is the scene's
sphere, centred at the origin. The lateral axis (the world's ``y``) is a degree of freedom of its
own (below).

Parts:

* **Blade** (dynamic body). A Macintosh 3: a straight 130 mm spatula whose underside presses the
  tongue, a 22 mm proximal flange on top (over 60 % of the length, tapering to 4 mm at the tip), and
  a 120 mm handle at 90 degrees (Macintosh blades attach at 90 degrees) held 70 mm above the heel.
  Mass: a stainless Macintosh 3 blade weighs about 80 g and a battery handle about 150 g
  (manufacturers' catalogue figures; 60-110 g and 120-250 g across makes); both are parameters.
  Centre of mass and moment of inertia follow from treating blade and handle as thin rods
  (``m L^2 / 12`` each, moved to the common centre by the parallel-axis theorem).
* **Hand** (kinematic body at the grip). Moved only by velocity (so the coupling's damper sees the
  motion); the action sets its velocity along the blade (insert), along the blade's normal into the
  tongue (press: the clinical "lift" of the tongue toward the mandible), sideways (sweep) and its
  pitch rate. Its workspace is a box (it stops at the walls: the velocity component that would
  leave it is reduced to reach the wall exactly).
* **Virtual coupling** hand -> blade (Colgate, Stanley & Brown 1995). Translation: two pymunk
  ``DampedSpring`` s along the hand's axes, each 1 m long at rest. A zero-length spring would damp
  only along the momentary separation, so its transverse motion would ring undamped; two long
  orthogonal springs give the stiffness ``k`` in every direction (to second order in the
  separation over 1 m) and pymunk's implicit damping along both axes. Rotation: a
  ``DampedRotarySpring``.
* **Upper incisors**: a static rounded bar (radius 4 mm) at the mouth, 3 cm in from the heel, its
  incisal edge 3 mm above the flange in the start pose, rising 3 cm up and back along the tooth and
  the maxilla (so the blade cannot slip up past it).
  pymunk solves that contact; its force is ``|total_impulse| / h`` summed over the substeps of a
  control period and divided by the period (the mean incisor force).
* **Tongue contact** (computed outside pymunk, applied each substep): the point of the blade's
  underside nearest the sphere's centre penetrates by ``delta``; the normal force follows
  :class:`~softenv.devices.contact.TongueContact`, applied along the sphere's normal there.
* **Lateral sweep**: the blade's lateral position ``y`` is a mass on a spring-damper to the hand's
  lateral position (the same ``k`` and ``c`` as the coupling), and the tongue holds it by the
  stick-slip law of :class:`TongueContact`: coupled to the sagittal motion through the normal force
  (the friction limit ``mu P``; no contact, no drag). Integrated as pymunk integrates its springs
  (explicit springs, implicit damping, symplectic Euler).

pymunk applies a spring's damping implicitly but after its explicit spring impulse (a first-order
split): the period and decay of a damped oscillation err by about ``0.5 zeta omega h``. The default
damping ratios (0.14 translational, 0.11 rotational) keep that under 1 % (tested against the
analytic damped oscillator); heavier damping is stable but less accurate at the same substep.

Time stepping. The physics substep is ``h = dt / n`` with ``n`` the smallest count that keeps
``h <= max_substep`` (1 ms: a 1 kHz haptic rate) and ``omega_max h <= 0.3`` (accuracy; explicit
springs are stable up to ``omega h < 2``), where ``omega_max`` is the stiffest mode of the blade with
all its springs (coupling, rotary coupling, and the tongue contact's explicit part wherever on the
underside it acts: the design force's stiffness, capped where it would add substeps), or of the lateral sweep (:meth:`LaryngoscopeParams.omega_max`).

Two implementations share the contact's arithmetic (:func:`_tongue_substep`, written once against
``ops``): :class:`Laryngoscope` steps one device with Python floats and pymunk's C functions (the single
env: a 1 kHz tick in microseconds; its substep loop is compiled per scene into plain float code by
:func:`softenv._specialise.scalar_kernel`, the same operations without a Python call per ``ops``
function), :class:`LaryngoscopeBatch` steps ``N`` devices in one pymunk space with numpy and
``pymunk.batch``. Both compute the same IEEE operations in the same order. In the batch, device ``i`` sits at its own
place in the plane (a grid 1 m apart, so no shapes of two devices ever meet): positions there carry
the offset, which changes their rounding, so device 0 (at the origin) equals a single device bit for
bit and the others agree to rounding (tested).

Reproducibility. No contact state crosses a control period: at the start of each, a device whose
blade touched the incisors during the last one has them removed and added again (dropping pymunk's
cached contact impulses) and its blade's position-correction velocity cleared, so a device rebuilt
from :meth:`state` (pickle, deepcopy, reset) continues bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

try:
    import pymunk
    import pymunk.batch
    from pymunk._chipmunk import ffi as _ffi
    from pymunk._chipmunk import lib as _lib
except ImportError as exc:  # pragma: no cover - the device extra is part of every test install
    raise ImportError("the simulated laryngoscope needs pymunk >= 7: pip install 'softenv[device]'") from exc

from .._ops import ArrayOps, ScalarOps
from . import ANGLE_SCALE, LATERAL_SCALE, LATERAL_SPEED_SCALE, POSITION_SCALE, SPEED_SCALE, SPIN_SCALE
from .._specialise import scalar_kernel
from .contact import TongueContact
from .presets import PRESETS, HapticPreset, render_components

BLADE_TYPE, INCISOR_TYPE = 1, 2
SPRING_LENGTH = 1.0           # m, rest length of the two coupling springs
GRID_SPACING = 1.0            # m between devices in a batch
START_GAP = 0.005             # m between the blade's underside and the tongue at the start
INCISOR_RADIUS = 0.004        # m
INCISOR_CLEARANCE = 0.003     # m above the flange in the start pose
INCISOR_SETBACK = 0.03        # m from the heel toward the tip
INCISOR_CROWN = (-0.008, 0.03)  # m: the tooth and the maxilla above it, up and back from the incisal edge
COLLISION_SLOP = 1e-4         # m (pymunk's default 0.1 assumes pixels)
SOLVER_ITERATIONS = 3         # pymunk's contact solver (default 10): one contact a blade, warm-started over 20+ substeps
CONTACT_DAMPING_RATIO = 1.0    # the tongue contact: critically damped (tissue is viscous)
ACCURACY = 0.3                # omega_max h
# hand workspace around the start grip (m, m, rad)
HAND_REACH = {"insert": 0.025, "withdraw": 0.05, "up": 0.04}   # further in, the handle would be in the mouth
PITCH_LIMIT = 0.5


@dataclass(frozen=True)
class LaryngoscopeParams:
    """Every number of the device (SI units); see the module docstring. Built by :meth:`from_config`."""

    radius: float                       # tongue sphere radius (m)
    dt: float                           # control period (s)
    blade_length: float = 0.13
    flange_height: float = 0.022
    blade_mass: float = 0.08
    handle_mass: float = 0.15
    handle_length: float = 0.12
    grip_height: float = 0.07
    tip_height: float = 0.004
    flange_share: float = 0.6
    coupling_stiffness: float = 2000.0
    coupling_damping: float = 6.0
    rotational_stiffness: float = 30.0
    rotational_damping: float = 0.03
    max_hand_speed: float = 0.2
    max_sweep_speed: float = 0.1
    max_pitch_rate: float = 1.0
    friction: float = 0.5
    max_substep: float = 1e-3
    preset: str = "omega"
    max_normal_force: float = 40.0
    max_sideways_force: float = 10.0

    @classmethod
    def from_config(cls, config: dict[str, dict[str, Any]]) -> "LaryngoscopeParams":
        dev = config["device"]
        keys = ("blade_mass", "handle_mass", "coupling_stiffness", "coupling_damping", "rotational_stiffness",
                "rotational_damping", "max_hand_speed", "max_sweep_speed", "max_pitch_rate", "friction", "max_substep",
                "max_normal_force", "max_sideways_force")
        return cls(radius=config["tissue"]["radius"], dt=config["dynamics"]["dt"], preset=dev["haptic_preset"],
                   **{k: dev[k] for k in keys})

    @property
    def haptic(self) -> HapticPreset:
        return PRESETS[self.preset]

    @property
    def mass(self) -> float:
        return self.blade_mass + self.handle_mass

    @property
    def com(self) -> tuple[float, float]:
        """Centre of mass in the heel frame (x toward the heel from the tip, y toward the flange)."""
        return (-0.5 * self.blade_length * self.blade_mass / self.mass,
                0.5 * self.handle_length * self.handle_mass / self.mass)

    @property
    def moment(self) -> float:
        cx, cy = self.com
        L, H = self.blade_length, self.handle_length
        blade = self.blade_mass * (L * L / 12 + (-L / 2 - cx) ** 2 + cy ** 2)
        handle = self.handle_mass * (H * H / 12 + cx ** 2 + (H / 2 - cy) ** 2)
        return blade + handle

    def body_point(self, x: float, y: float) -> tuple[float, float]:
        """A heel-frame point relative to the centre of mass (the pymunk body's frame)."""
        cx, cy = self.com
        return (x - cx, y - cy)

    @property
    def heel(self) -> tuple[float, float]:
        return self.body_point(0.0, 0.0)

    @property
    def tip(self) -> tuple[float, float]:
        return self.body_point(-self.blade_length, 0.0)

    @property
    def grip(self) -> tuple[float, float]:
        return self.body_point(0.0, self.grip_height)

    @property
    def handle_top(self) -> tuple[float, float]:
        return self.body_point(0.0, self.handle_length)

    @property
    def outline(self) -> list[tuple[float, float]]:
        """The blade's side profile (convex, counter-clockwise), body frame."""
        L = self.blade_length
        return [self.body_point(*p) for p in ((-L, 0.0), (0.0, 0.0), (0.0, self.flange_height),
                                              (-self.flange_share * L, self.flange_height), (-L, self.tip_height))]

    @property
    def heel_start(self) -> tuple[float, float]:
        return (self.radius + 0.04, self.radius + START_GAP)

    @property
    def body_start(self) -> tuple[float, float]:
        (hx, hy), (cx, cy) = self.heel_start, self.com
        return (hx + cx, hy + cy)

    @property
    def grip_start(self) -> tuple[float, float]:
        hx, hy = self.heel_start
        return (hx, hy + self.grip_height)

    @property
    def incisor(self) -> tuple[float, float]:
        """Centre of the incisal edge's rounding (local frame)."""
        hx, hy = self.heel_start
        return (hx - INCISOR_SETBACK, hy + self.flange_height + INCISOR_CLEARANCE + INCISOR_RADIUS)

    @property
    def incisor_segment(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """The upper incisors' static shape: a rounded bar (radius 4 mm) from the incisal edge up and
        back along the tooth and the maxilla, so the blade cannot pass beside it."""
        ix, iy = self.incisor
        return (ix, iy), (ix + INCISOR_CROWN[0], iy + INCISOR_CROWN[1])

    @property
    def hand_box(self) -> tuple[tuple[float, float, float, float], tuple[float, float, float, float]]:
        """``(low, high)`` of the hand: grip x, grip z (m), pitch (rad), lateral y (m). The floor keeps a
        level blade above the tongue's centre (it can never be pushed through the tongue)."""
        gx, gy = self.grip_start
        low = (gx - HAND_REACH["insert"], gy - (self.radius + START_GAP), -PITCH_LIMIT, -self.radius)
        high = (gx + HAND_REACH["withdraw"], gy + HAND_REACH["up"], PITCH_LIMIT, self.radius)
        return low, high

    def effective_mass(self, r: float) -> float:
        """Smallest effective mass of the blade at distance ``r`` from its centre of mass."""
        return 1.0 / (1.0 / self.mass + r * r / self.moment)

    def reach(self) -> float:
        """Largest distance from the centre of mass to a point of the blade's underside."""
        return max(math.hypot(*self.heel), math.hypot(*self.tip))

    def omega_max(self, contact: TongueContact) -> float:
        """The stiffest mode's angular frequency (rad/s), over where the tongue may touch.

        Sagittal: the largest eigenvalue of ``M^-1 K`` for the blade's ``(x, y, angle)`` with the
        coupling springs at the grip, the rotary spring, and the contact's explicit part
        (:meth:`explicit_contact_stiffness`) at any point of the underside in any direction.
        Lateral: ``(k + k_t) / m``.
        """
        return self._mode_omega(self.explicit_contact_stiffness(contact), contact.lateral_stiffness)

    def explicit_contact_stiffness(self, contact: TongueContact) -> float:
        """The tongue contact's stiffness integrated explicitly (N/m): the design force's stiffness,
        capped where it would add substeps to those that ``max_substep``, the coupling and the lateral
        spring need anyway. The stiffness above it goes to the implicit
        barrier (:func:`_tongue_substep`), which is stable at any stiffness and exact at rest, so a
        stiffer tongue costs no substeps and a held press still settles on the law."""
        k_ref, lateral = contact.reference_stiffness, contact.lateral_stiffness
        count = substep_count(self.dt, self._mode_omega(0.0, lateral), self.max_substep)   # needed without it
        allowed = ACCURACY * count / self.dt
        if self._mode_omega(k_ref, lateral) <= allowed:
            return k_ref
        low, high = 0.0, k_ref                      # omega grows with the contact's stiffness: bisect
        for _ in range(60):
            mid = 0.5 * (low + high)
            low, high = (mid, high) if self._mode_omega(mid, lateral) <= allowed else (low, mid)
        return low

    def _mode_omega(self, contact_stiffness: float, lateral_stiffness: float) -> float:
        """The stiffest mode (rad/s) with the contact at this stiffness (see :meth:`omega_max`)."""
        gx, gy = self.grip
        k = self.coupling_stiffness
        base = k * (np.outer([1, 0, -gy], [1, 0, -gy]) + np.outer([0, 1, gx], [0, 1, gx])) \
            + self.rotational_stiffness * np.outer([0, 0, 1], [0, 0, 1])
        scale = 1.0 / np.sqrt([self.mass, self.mass, self.moment])
        (hx, hy), (tx, ty) = self.heel, self.tip
        t = np.linspace(0.0, 1.0, 11)[:, None]
        beta = np.linspace(0.0, np.pi, 13)[None, :]
        rx, ry = hx + t * (tx - hx), hy + t * (ty - hy)
        nx, ny = np.cos(beta) + 0.0 * rx, np.sin(beta) + 0.0 * rx
        j = np.stack([nx, ny, rx * ny - ry * nx], axis=-1).reshape(-1, 3)      # every point and direction
        K = base + contact_stiffness * j[:, :, None] * j[:, None, :]
        worst = float(np.linalg.eigvalsh(K * np.outer(scale, scale)).max())
        return math.sqrt(max(worst, (k + lateral_stiffness) / self.mass))

    def substeps(self, contact: TongueContact) -> int:
        """Physics substeps per control period."""
        return substep_count(self.dt, self.omega_max(contact), self.max_substep)


@dataclass
class _Constants:
    """Per-scene numbers the substep arithmetic reads (attributes: fast in the scalar path)."""

    R: float
    h: float
    inv_m: float
    inv_I: float
    h_over_m: float
    k: float
    c: float
    k_t: float
    mu: float
    k_ref: float
    damping: float
    step: float
    inv_step: float
    top: int
    k_rot: float
    c_rot: float
    grip: tuple[float, float]
    heel: tuple[float, float]
    tip: tuple[float, float]
    low: tuple[float, ...]
    high: tuple[float, ...]


def _nearest_point(px: Any, py: Any, cos_a: Any, sin_a: Any, c: _Constants, ops: Any) -> tuple[Any, Any, Any]:
    """The point of the blade's underside (heel to tip) nearest the tongue's centre, and its distance."""
    hx, hy = c.heel
    tx, ty = c.tip
    ex = px + cos_a * hx - sin_a * hy
    ey = py + sin_a * hx + cos_a * hy
    dx = (px + cos_a * tx - sin_a * ty) - ex
    dy = (py + sin_a * tx + cos_a * ty) - ey
    t = ops.clip(-(ex * dx + ey * dy) / (dx * dx + dy * dy), 0.0, 1.0)
    cx = ex + t * dx
    cy = ey + t * dy
    return cx, cy, ops.sqrt(cx * cx + cy * cy) + 1e-300


def _tongue_substep(blade: tuple, hand: tuple, lateral: tuple, hl: Any, loads: Any, slopes: Any, c: _Constants,
                    ops: Any) -> tuple[Any, ...]:
    """One substep of the tongue's contact: the arithmetic both devices share (the single device runs
    it inlined into its compiled substep loop).

    ``blade`` is ``(x, y, angle, cos, sin, vx, vy, spin)``, ``hand`` is ``(x, y, pitch, vx, vy, spin)``,
    ``lateral`` is ``(blade y, blade vy, hand y, anchor)`` with the hand's ``y`` already moved this
    substep at its velocity ``hl``. Returns ``(fx, fy, torque, P, Q, cx, cy, lat_y, lat_v, anchor)``:
    the tongue's push on the blade and its torque, the normal and sideways force, the contact point,
    and the lateral state after the substep.

    **Normal force**, at the blade's point ``(cx, cy)`` nearest the tongue's centre. The law's
    stiffness up to ``K_ref`` is explicit; the excess ``K_ex`` (the steepest slope between here and
    where this substep's approach speed would take the blade), with a critical damper
    ``c_ex = 2 sqrt(K_ex m)`` so that the stiff barrier does not ring, is applied by backward Euler
    along the normal, with the blade's effective mass ``m`` there and the coupling's push predicted
    from the current state: with ``s = K_ex h + c_ex``,
    ``P (1 + s h / m) = P(delta) + (c + s) v + s h a``, where ``v`` is the approach speed and ``a`` the
    coupling's acceleration of that point into the tongue. At rest ``a = P / m``, so a held press
    settles exactly on the law, however stiff it is there; the prediction uses forces of this instant
    (not the last contact force), so it does not feed energy back.

    **Lateral**: the blade's lateral mass between the hand's spring-damper and the tongue's
    stick-slip grip, as pymunk integrates its springs: explicit springs, implicit damping, then the
    position (symplectic Euler; stable for ``omega h < 2``, which the substep keeps below 0.3).
    """
    px, py, a, cos_a, sin_a, vx, vy, w = blade
    lat_y, lat_v, hand_lat, anchor = lateral
    cx, cy, dist = _nearest_point(px, py, cos_a, sin_a, c, ops)
    touching = dist < c.R
    if ops is ScalarOps and not touching:       # off the tongue P is 0: the single device skips its arithmetic
        fx = fy = torque = P = 0.0
    else:
        depth = c.R - dist
        nx = cx / dist
        ny = cy / dist
        rx = cx - px
        ry = cy - py
        approach = -((vx - w * ry) * nx + (vy + w * rx) * ny)     # speed of that point into the tongue
        rn = rx * ny - ry * nx
        inv_meff = c.inv_m + rn * rn * c.inv_I
        i = ops.index(ops.positive(depth) * c.inv_step, c.top)
        slope = ops.take(slopes, i)
        law = ops.take(loads, i) + (depth - i * c.step) * slope
        ahead = ops.take(slopes, ops.index(ops.positive(depth + c.h * approach) * c.inv_step, c.top))
        slope = ops.where(ahead > slope, ahead, slope)
        excess = ops.positive(slope - c.k_ref)
        # the excess spring, critically damped, both implicit: K_ex h + c_ex, with c_ex = 2 sqrt(K_ex m)
        stiff = excess * c.h + 2.0 * ops.sqrt(excess / inv_meff)
        # the coupling's acceleration of the contact point into the tongue, predicted from this instant
        # (where stiff = 0 it is multiplied by 0)
        Fx, Fy, tau = _coupling_force(blade, hand, c)
        push = -(Fx * nx + Fy * ny) * c.inv_m - tau * rn * c.inv_I
        beta = stiff * c.h * inv_meff
        P = ops.positive((law + (c.damping + stiff) * approach + stiff * c.h * push) / (1.0 + beta)) * touching
        fx = P * nx
        fy = P * ny
        torque = rx * fy - ry * fx
    k_s = c.k_t * touching
    lat_v = (lat_v + c.h_over_m * (c.k * (hand_lat - lat_y) + c.c * hl - k_s * (lat_y - anchor))) / \
        (1.0 + c.h_over_m * c.c)
    lat_y = lat_y + c.h * lat_v
    stuck = k_s * (lat_y - anchor)
    limit = c.mu * P
    Q = ops.clip(stuck, -limit, limit)                         # Coulomb: past mu P the anchor slides
    anchor = ops.where(touching, ops.where(Q != stuck, lat_y - Q / c.k_t, anchor), lat_y)
    return fx, fy, torque, P, Q, cx, cy, lat_y, lat_v, anchor


def _grip_offset(cos_a: Any, sin_a: Any, c: _Constants) -> tuple[Any, Any]:
    """The grip's offset (m) from the blade's centre of mass, in the world frame."""
    return cos_a * c.grip[0] - sin_a * c.grip[1], sin_a * c.grip[0] + cos_a * c.grip[1]


def _coupling_force(blade: tuple, hand: tuple, c: _Constants) -> tuple[Any, Any, Any]:
    """The coupling's force ``(Fx, Fy)`` and torque on the blade now: the hand's springs at the grip
    and the wrist spring, each with its damper (the hand feels the opposite)."""
    px, py, a, cos_a, sin_a, vx, vy, w = blade
    gx, gy, pitch, hvx, hvy, hw = hand
    qx, qy = _grip_offset(cos_a, sin_a, c)
    Fx = c.k * (gx - px - qx) + c.c * (hvx - vx + w * qy)
    Fy = c.k * (gy - py - qy) + c.c * (hvy - vy - w * qx)
    return Fx, Fy, qx * Fy - qy * Fx + c.k_rot * (pitch - a) + c.c_rot * (hw - w)


def _near_walls(pose: tuple[float, ...], velocity: tuple[float, ...], low: tuple[float, ...],
                high: tuple[float, ...], period: float) -> list[bool]:
    """For each axis of a hand at ``pose`` moving at ``velocity`` for ``period`` s: whether it comes
    within 1e-6 (m or rad) of its box. Where it does not, every substep's wall clip returns the
    velocity unchanged: the clip's bounds ``(low - x) / h`` and ``(high - x) / h`` are ~1e-6 / h away
    from it, and the rounding of ``x`` is ~1e-17."""
    return [min(x, x + v * period) < lo + 1e-6 or max(x, x + v * period) > hi - 1e-6
            for x, v, lo, hi in zip(pose, velocity, low, high)]


def _hand_command(action: Any, pitch: Any, p: LaryngoscopeParams, ops: Any) -> tuple[Any, Any, Any, Any]:
    """World velocities ``(vX, vY, spin, v_lateral)`` of the hand for normalised actions, in the hand's
    frame at the start of the control period: insert along the blade toward its tip, press along the
    blade's normal into the tongue, sweep toward +y, pitch counter-clockwise (tip down)."""
    cos_a, sin_a = ops.cos(pitch), ops.sin(pitch)
    v = p.max_hand_speed
    return (v * (-action[0] * cos_a + action[1] * sin_a), v * (-action[0] * sin_a - action[1] * cos_a),
            p.max_pitch_rate * action[3], p.max_sweep_speed * action[2])


def hand_action(vX: float, vY: float, spin: float, v_lateral: float, pitch: float,
                p: LaryngoscopeParams) -> tuple[float, float, float, float]:
    """The action whose :func:`_hand_command` at hand pitch ``pitch`` is the world velocity ``(vX, vY,
    spin, v_lateral)`` (its exact inverse; not clipped to ``[-1, 1]``)."""
    cos_a, sin_a = math.cos(pitch), math.sin(pitch)
    v = p.max_hand_speed
    return (-(vX * cos_a + vY * sin_a) / v, (vX * sin_a - vY * cos_a) / v, v_lateral / p.max_sweep_speed,
            spin / p.max_pitch_rate)


def _features(cx: Any, cy: Any, anchor: Any, P: Any, Q: Any, R: float, ops: Any) -> tuple[Any, Any, Any, Any]:
    """Force features of the contact: insertion and lateral arc (m), normal and sideways force (N)."""
    return R * ops.atan2(cy, cx), R * ops.asin(ops.clip(anchor / R, -1.0, 1.0)), P, Q


def _squash(x: Any) -> Any:
    """``x / (1 + |x|)``: bounded in (-1, 1), slope 1 at 0, exact arithmetic (no ``tanh``: numpy's and
    the C library's differ in the last bit)."""
    return x / (1.0 + abs(x))


def virtual_coupling(hand: pymunk.Body, body: pymunk.Body, anchor: tuple[float, float],
                     p: LaryngoscopeParams) -> tuple[pymunk.Constraint, ...]:
    """The hand -> blade coupling: two 1 m ``DampedSpring`` s along the hand's axes meeting at
    ``anchor`` (body frame) and a ``DampedRotarySpring`` (see the module docstring)."""
    k, c = p.coupling_stiffness, p.coupling_damping
    return (pymunk.DampedSpring(hand, body, (-SPRING_LENGTH, 0.0), anchor, SPRING_LENGTH, k, c),
            pymunk.DampedSpring(hand, body, (0.0, SPRING_LENGTH), anchor, SPRING_LENGTH, k, c),
            pymunk.DampedRotarySpring(hand, body, 0.0, p.rotational_stiffness, p.rotational_damping))


def substep_count(dt: float, omega: float, max_substep: float) -> int:
    """Substeps per period ``dt``: ``h <= max_substep`` and ``omega h <= 0.3``."""
    h = min(max_substep, ACCURACY / omega)
    return max(1, math.ceil(dt / h - 1e-9))


class _Space:
    """The pymunk space of ``n`` devices (hands, blades, couplings, incisors) at their grid places."""

    def __init__(self, p: LaryngoscopeParams, n: int) -> None:
        # Chipmunk's "hasty" space on one thread: the same deterministic step, 10 % faster at 1,024
        # devices (an ordinary space where pymunk has none, on Windows)
        self.space = pymunk.Space(threaded=True)
        self.space.threads = 1
        self.space.collision_slop = COLLISION_SLOP
        self.space.iterations = SOLVER_ITERATIONS
        self.step = _lib.cpHastySpaceStep if self.space.threaded else _lib.cpSpaceStep
        side = math.ceil(math.sqrt(n))
        self.offsets = np.array([[GRID_SPACING * (i % side), GRID_SPACING * (i // side)] for i in range(n)])
        self.hands: list[pymunk.Body] = []
        self.blades: list[pymunk.Body] = []
        self.incisors: list[pymunk.Circle] = []
        for ox, oy in self.offsets.tolist():
            hand = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
            blade = pymunk.Body(p.mass, p.moment)
            # one shape a side, so one contact a device: with two, the solver's order of them would
            # depend on the spatial index's history, and a rebuilt device would not continue bit for bit
            shape = pymunk.Poly(blade, p.outline)
            shape.collision_type, shape.friction, shape.elasticity = BLADE_TYPE, 0.3, 0.0
            (ax, ay), (bx, by) = p.incisor_segment
            incisor = pymunk.Segment(self.space.static_body, (ox + ax, oy + ay), (ox + bx, oy + by), INCISOR_RADIUS)
            incisor.collision_type, incisor.friction, incisor.elasticity = INCISOR_TYPE, 0.3, 0.0
            self.space.add(hand, blade, shape, incisor, *virtual_coupling(hand, blade, p.grip, p))
            self.hands.append(hand)
            self.blades.append(blade)
            self.incisors.append(incisor)
        self._incisor_shapes = [shape._shape for shape in self.incisors]      # the C handles flush uses
        self._blade_bodies = [body._body for body in self.blades]

    def place(self, i: int, blade_pose: tuple[float, float, float], blade_velocity: tuple[float, float, float],
              hand_pose: tuple[float, float, float]) -> None:
        """Put device ``i`` at local poses (x, y, angle) and velocities, dropping its contact state."""
        ox, oy = self.offsets[i].tolist()
        blade, hand = self.blades[i], self.hands[i]
        blade.position = (ox + blade_pose[0], oy + blade_pose[1])
        blade.angle = blade_pose[2]
        blade.velocity = blade_velocity[:2]
        blade.angular_velocity = blade_velocity[2]
        hand.position = (ox + hand_pose[0], oy + hand_pose[1])
        hand.angle = hand_pose[2]
        hand.velocity = (0.0, 0.0)
        hand.angular_velocity = 0.0
        self.flush(i)

    def flush(self, *devices: int) -> None:
        """Drop the contact state of these devices that their poses and velocities do not show: pymunk's
        cached contact impulses (remove and add their incisors again) and the blades'
        position-correction velocities, which Chipmunk's solver leaves for the next step's position
        update (a position update over zero time applies nothing and clears them)."""
        # through the C API: pymunk's Python bookkeeping stays valid (the same shape goes straight back)
        space, remove, add, update = self.space._space, _lib.cpSpaceRemoveShape, _lib.cpSpaceAddShape, \
            _lib.cpBodyUpdatePosition
        for i in devices:
            remove(space, self._incisor_shapes[i])
            add(space, self._incisor_shapes[i])
            update(self._blade_bodies[i], 0.0)


@dataclass
class DeviceState:
    """The full state of ``n`` devices as arrays (pickling, tests, the haptic loop)."""

    blade: np.ndarray        # (n, 6) x, y, angle, vx, vy, spin (local frame)
    hand: np.ndarray         # (n, 3) grip x, y, pitch
    lateral: np.ndarray      # (n, 4) blade y, blade vy, hand y, anchor
    contact: np.ndarray      # (n, 5) P, Q, contact x, contact y, incisor force
    hand_velocity: np.ndarray  # (n, 4) the hand's last velocities: x, y, pitch rate, lateral


def _constants(p: LaryngoscopeParams, contact: TongueContact, h: float) -> _Constants:
    m_eff = p.effective_mass(p.reach())
    k_explicit = p.explicit_contact_stiffness(contact)
    damping = min(2.0 * CONTACT_DAMPING_RATIO * math.sqrt(k_explicit * m_eff), m_eff / h)
    low, high = p.hand_box
    return _Constants(R=p.radius, h=h, inv_m=1.0 / p.mass, inv_I=1.0 / p.moment, h_over_m=h / p.mass,
                      k=p.coupling_stiffness, c=p.coupling_damping, k_t=contact.lateral_stiffness, mu=p.friction,
                      k_ref=k_explicit, damping=damping, step=contact.step, inv_step=contact.inv_step,
                      top=contact.top, k_rot=p.rotational_stiffness, c_rot=p.rotational_damping, grip=p.grip,
                      heel=p.heel, tip=p.tip, low=low, high=high)


class _DeviceBase:
    """What the single and batched devices share: parameters, contact law, space, constants."""

    def __init__(self, params: LaryngoscopeParams, contact: TongueContact, n: int) -> None:
        self.params = params
        self.contact = contact
        self.n_substeps = params.substeps(contact)
        self.h = params.dt / self.n_substeps
        self.c = _constants(params, contact, self.h)
        self.n = n
        self._space = _Space(params, n)
        self._forget()

    def _forget(self) -> None:
        """Drop what was derived from the bodies' state: it has just changed (substeps, a new state)."""
        self._kin: Any = None
        self._pull: Any = None

    def _kinematics(self) -> Any:
        """Blade x, y, angle, vx, vy, spin and hand x, y, pitch (local frame), read once per state."""
        if self._kin is None:
            self._kin = self._read_kinematics()
        return self._kin

    def _coupling_pull(self, ops: Any) -> tuple[Any, Any, Any, Any]:
        """``(cos, sin)`` of the blade's angle and the coupling's force ``(Fx, Fy)`` on it now (the
        clinical record and the haptic force both need them; computed once per state)."""
        if self._pull is None:
            x, y, a, vx, vy, w, gx, gy, pitch = self._kinematics()
            hvx, hvy, hw, _ = self._hand_v_state()
            ca, sa = ops.cos(a), ops.sin(a)
            Fx, Fy, _ = _coupling_force((x, y, a, ca, sa, vx, vy, w), (gx, gy, pitch, hvx, hvy, hw), self.c)
            self._pull = (ca, sa, Fx, Fy)
        return self._pull

    @property
    def space(self) -> pymunk.Space:
        return self._space.space

    def energy(self) -> np.ndarray:
        """Mechanical energy (J) of each device: kinetic, coupling springs, tongue (normal and lateral)."""
        s, p = self.state(), self.params
        x, y, a, vx, vy, w = s.blade.T
        gx, gy, pitch = s.hand.T
        ly, lv, hy, anchor = s.lateral.T
        kinetic = 0.5 * p.mass * (vx * vx + vy * vy + lv * lv) + 0.5 * p.moment * w * w
        qx, qy = p.grip
        grip_x = x + np.cos(a) * qx - np.sin(a) * qy
        grip_y = y + np.sin(a) * qx + np.cos(a) * qy
        ux, uy = grip_x - gx, grip_y - gy
        ca, sa = np.cos(pitch), np.sin(pitch)
        lengths = [np.hypot(ux + SPRING_LENGTH * ca, uy + SPRING_LENGTH * sa),
                   np.hypot(ux + SPRING_LENGTH * sa, uy - SPRING_LENGTH * ca)]
        k = p.coupling_stiffness
        coupling = sum(0.5 * k * (L - SPRING_LENGTH) ** 2 for L in lengths) + 0.5 * k * (ly - hy) ** 2 \
            + 0.5 * p.rotational_stiffness * (a - pitch) ** 2
        depth = self.params.radius - _nearest_point(x, y, np.cos(a), np.sin(a), self.c, ArrayOps)[2]
        touching = depth > 0
        tongue = np.where(touching, self.contact.potential(depth) + 0.5 * self.contact.lateral_stiffness
                          * (ly - anchor) ** 2, 0.0)
        return kinetic + coupling + tongue

    def _clinical(self, ops: Any) -> tuple[Any, ...]:
        """Each device's values in :data:`softenv.clinical.COLUMNS` order: tongue and incisor force (N),
        the hand's x, z and lateral y (m), and the moments (N m) about the incisal edge of the
        coupling's pull on the blade, split into the wrist's (rotary spring and damper: levering)
        and that of the force at the grip (lifting)."""
        c = self.c
        x, y, a, vx, vy, w, gx, gy, pitch = self._kinematics()
        hand_lat = self._lateral_state()[2]
        hw = self._hand_v_state()[2]
        ca, sa, Fx, Fy = self._coupling_pull(ops)
        wrist = c.k_rot * (pitch - a) + c.c_rot * (hw - w)
        ix, iy = self.params.incisor_segment[0]
        qx, qy = _grip_offset(ca, sa, c)
        lift = (x + qx - ix) * Fy - (y + qy - iy) * Fx
        return self.tongue_force, self.incisor_force, gx, gy, hand_lat, wrist, lift

    def start_state(self, n: int) -> DeviceState:
        p = self.params
        bx, by = p.body_start
        gx, gy = p.grip_start
        return DeviceState(np.tile([bx, by, 0.0, 0.0, 0.0, 0.0], (n, 1)), np.tile([gx, gy, 0.0], (n, 1)),
                           np.zeros((n, 4)), np.zeros((n, 5)), np.zeros((n, 4)))

    def blade_pose(self) -> np.ndarray:
        """``(n, 4)``: x, z (m), pitch (rad) of the blade's centre of mass and its lateral y (m)."""
        x, y, a = self._kinematics()[:3]
        return np.stack([np.asarray(v, dtype=np.float64).reshape(-1) for v in (x, y, a, self._lateral_state()[0])],
                        axis=-1)

    def drawing(self) -> list[dict[str, Any]]:
        """What a renderer draws of each device, in the local sagittal frame (m)."""
        s, p = self.state(), self.params
        outline = np.array(p.outline)
        out = []
        for (x, y, a), (gx, gy, pitch), (P, Q, cx, cy, incisor) in zip(s.blade[:, :3], s.hand, s.contact):
            rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
            out.append({"outline": outline @ rot.T + (x, y), "incisor": (*p.incisor_segment, INCISOR_RADIUS),
                        "handle": np.array([p.heel, p.handle_top]) @ rot.T + (x, y),
                        "hand": (gx, gy, pitch), "contact": (cx, cy) if P > 0 else None,
                        "tongue_force": float(math.hypot(P, Q)), "incisor_force": float(incisor),
                        "radius": p.radius})
        return out

    def haptic_force(self) -> np.ndarray:
        """Force ``(n, 3)`` (world x, y, z; N) that the preset device renders to the hand: the coupling's
        pull on the hand, scaled and saturated (:func:`softenv.devices.presets.render_force`)."""
        return np.stack(self._rendered(ArrayOps), axis=-1)

    def _rendered(self, ops: Any) -> tuple[Any, Any, Any]:
        """The coupling's pull on the hand (world x, y, z), as the preset renders it."""
        c = self.c
        lat_y, lat_v, hand_lat, _ = self._lateral_state()
        hl = self._hand_v_state()[3]
        Fx, Fy = self._coupling_pull(ops)[2:]
        return render_components(-Fx, c.k * (lat_y - hand_lat) + c.c * (lat_v - hl), -Fy, c.k, self.params.haptic, ops)


class Laryngoscope(_DeviceBase):
    """One simulated laryngoscope, stepped with Python floats (the single env and the haptic loop)."""

    def __init__(self, params: LaryngoscopeParams, contact: TongueContact) -> None:
        super().__init__(params, contact, 1)
        self._hand, self._blade = self._space.hands[0], self._space.blades[0]
        self._chand, self._cblade, self._cspace = self._hand._body, self._blade._body, self.space._space
        self._loads, self._slopes = contact.loads_list, contact.slopes_list
        # the substep loop as plain float code for this scene, the contact's arithmetic inlined (the same
        # bits as the loop run as written, with ScalarOps: tested)
        self._loop = scalar_kernel(Laryngoscope._substep_loop, self.c,
                                   helpers=(_tongue_substep, _nearest_point, _coupling_force, _grip_offset))
        self._touched = False
        self._listen_to_incisors()
        self.reset()

    def _listen_to_incisors(self) -> None:
        """Sum ``|total_impulse|`` of the blade's contact with the incisors after each substep's solve.

        pymunk's post-solve handler builds an ``Arbiter`` and looks up its data on every call (2.4 us,
        a third of a substep); a cffi callback straight on Chipmunk's handler reads the impulse in
        0.5 us. Where the platform refuses write+execute memory for cffi callbacks (hardened
        runtimes), pymunk's handler does the same sum.
        """
        self.space.on_collision(BLADE_TYPE, INCISOR_TYPE, post_solve=self._on_incisor)
        total_impulse = _lib.cpArbiterTotalImpulse

        def post_solve(arbiter: Any, space: Any, data: Any) -> None:
            j = total_impulse(arbiter)
            self._impulse += math.sqrt(j.x * j.x + j.y * j.y)
            self._touched = True

        try:
            self._post_solve = _ffi.callback("void(cpArbiter *, cpSpace *, cpDataPointer)", post_solve)
        except (MemoryError, RuntimeError):        # pragma: no cover - platform dependent
            return
        self.space._handlers[(BLADE_TYPE, INCISOR_TYPE)]._handler.postSolveFunc = self._post_solve

    def _on_incisor(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data: Any) -> None:
        jx, jy = arbiter.total_impulse
        self._impulse += math.sqrt(jx * jx + jy * jy)
        self._touched = True

    def reset(self) -> None:
        self.load_state(self.start_state(1))

    def control_step(self, action: list[float]) -> None:
        """Advance one control period with the hand commanded by ``action`` (4 floats in [-1, 1])."""
        vX, vY, spin, v_lat = _hand_command(action, self._hand_pose[2], self.params, ScalarOps)
        self.substeps(vX, vY, spin, v_lat, self.n_substeps)

    def substeps(self, vX: float, vY: float, spin: float, v_lat: float, count: int) -> None:
        """``count`` physics substeps with the hand's commanded world velocities."""
        self._loop(self, vX, vY, spin, v_lat, count)

    def _substep_loop(self, vX: float, vY: float, spin: float, v_lat: float, count: int) -> None:
        """:meth:`substeps` as written; ``__init__`` compiles it for the scene (:func:`scalar_kernel`).

        The loop talks to Chipmunk through pymunk's C bindings (``pymunk._chipmunk.lib``): pymunk's
        Python properties cost 1.5 us each, a tenth of a 1 kHz tick's budget. Away from the tongue it
        skips the normal-force arithmetic (whose result there is zero) and leaves the blade's force at
        the zero Chipmunk resets it to after every step.
        """
        if self._touched:
            self._space.flush(0)
            self._touched = False
        c, lo, hi, h = self.c, self.c.low, self.c.high, self.c.h
        blade, hand, space, step = self._cblade, self._chand, self._cspace, self._space.step
        get_p, get_v, get_a, get_w = _lib.cpBodyGetPosition, _lib.cpBodyGetVelocity, _lib.cpBodyGetAngle, \
            _lib.cpBodyGetAngularVelocity
        loads, slopes, cos, sin = self._loads, self._slopes, math.cos, math.sin
        set_force, set_torque = _lib.cpBodySetForce, _lib.cpBodySetTorque
        lat_y, lat_v, hand_lat, anchor = self._lateral
        # the kinematic hand moves exactly as Chipmunk integrates it (p += (v + 0) h), so it is tracked
        # here rather than read back
        gx, gy, pitch = self._hand_pose
        # the hand's walls clip its velocity each substep; along an axis whose whole path this period
        # stays clear of them, that clip returns the command itself, so it is skipped
        wall_x, wall_y, wall_p, wall_l = _near_walls((gx, gy, pitch, hand_lat), (vX, vY, spin, v_lat), lo, hi,
                                                     h * count)
        hvx, hvy, hw, hl = vX, vY, spin, v_lat
        written = None
        self._impulse = 0.0
        self._space.space._locked = True                    # as pymunk's Space.step does around the C step
        try:
            for _ in range(count):
                p, v = get_p(blade), get_v(blade)
                px, py, vx, vy, a, w = p.x, p.y, v.x, v.y, get_a(blade), get_w(blade)
                if wall_x:                                  # ScalarOps.clip, inlined
                    x, low, high = vX, (lo[0] - gx) / h, (hi[0] - gx) / h
                    hvx = low if x < low else (high if x > high else x)
                if wall_y:
                    x, low, high = vY, (lo[1] - gy) / h, (hi[1] - gy) / h
                    hvy = low if x < low else (high if x > high else x)
                if wall_p:
                    x, low, high = spin, (lo[2] - pitch) / h, (hi[2] - pitch) / h
                    hw = low if x < low else (high if x > high else x)
                if wall_l:
                    x, low, high = v_lat, (lo[3] - hand_lat) / h, (hi[3] - hand_lat) / h
                    hl = low if x < low else (high if x > high else x)
                hand_lat = hand_lat + h * hl
                ca, sa = cos(a), sin(a)
                fx, fy, torque, P, Q, cx, cy, lat_y, lat_v, anchor = _tongue_substep(
                    (px, py, a, ca, sa, vx, vy, w), (gx, gy, pitch, hvx, hvy, hw), (lat_y, lat_v, hand_lat, anchor), hl,
                    loads, slopes, c, ScalarOps)
                if P != 0.0:                                # off the tongue Chipmunk's reset force of 0 stands
                    set_force(blade, (fx, fy))
                    set_torque(blade, torque)
                if written != (hvx, hvy, hw):
                    written = (hvx, hvy, hw)
                    _lib.cpBodySetVelocity(hand, (hvx, hvy))
                    _lib.cpBodySetAngularVelocity(hand, hw)
                step(space, h)
                gx, gy, pitch = gx + (hvx + 0.0) * h, gy + (hvy + 0.0) * h, pitch + (hw + 0.0) * h
        finally:
            self._space.space._locked = False
        self._hand_pose = (gx, gy, pitch)
        self._lateral = (lat_y, lat_v, hand_lat, anchor)
        self._hand_v = (hvx, hvy, hw, hl)
        self._contact = (P, Q, cx, cy)
        self._incisor = self._impulse / (count * h)
        self._forget()

    def features(self) -> list[float] | None:
        """Force features of the contact, or None without contact."""
        P, Q, cx, cy = self._contact
        if P == 0.0 and Q == 0.0:
            return None
        return list(_features(cx, cy, self._lateral[3], P, Q, self.c.R, ScalarOps))

    def observation(self) -> list[float]:
        """The device part of the observation (15 values in (-1, 1); names in
        :data:`softenv.devices.LARYNGOSCOPE_OBS`)."""
        p = self.params
        (bx, by), (gx, gy) = p.body_start, p.grip_start
        px, py, a, vx, vy, w, hx, hy, pitch = self._kinematics()
        lat_y, lat_v, hand_lat, _ = self._lateral
        P, Q = self._contact[0], self._contact[1]
        raw = ((px - bx) / POSITION_SCALE, (py - by) / POSITION_SCALE, a / ANGLE_SCALE, lat_y / LATERAL_SCALE,
               vx / SPEED_SCALE, vy / SPEED_SCALE, w / SPIN_SCALE, lat_v / LATERAL_SPEED_SCALE,
               (hx - gx) / POSITION_SCALE, (hy - gy) / POSITION_SCALE, pitch / ANGLE_SCALE,
               hand_lat / LATERAL_SCALE, P / p.max_normal_force, Q / p.max_sideways_force,
               self._incisor / p.max_normal_force)
        return [_squash(x) for x in raw]

    @property
    def tongue_force(self) -> float:
        P, Q = self._contact[0], self._contact[1]
        return math.sqrt(P * P + Q * Q)

    @property
    def normal_force(self) -> float:
        return self._contact[0]

    @property
    def sideways_force(self) -> float:
        return self._contact[1]

    @property
    def incisor_force(self) -> float:
        return self._incisor

    def hand_velocity(self) -> np.ndarray:
        return np.array([self._hand_v])

    def haptic_force(self) -> np.ndarray:
        return np.array([self._rendered(ScalarOps)])

    def incisor_clearance(self) -> float:
        """Distance (m) between the incisors and the blade; negative: they overlap by that much."""
        incisor, blade = self._space.incisors[0], next(iter(self._blade.shapes))
        try:
            touching = blade.shapes_collide(incisor).points
        except AssertionError:                 # pymunk 7 asserts instead of returning no points
            touching = []
        if touching:
            return min(point.distance for point in touching)
        a, b = np.array(incisor.a), np.array(incisor.b)
        corners = [np.array(blade.body.local_to_world(v)) for v in blade.get_vertices()]
        ends = min(blade.point_query(tuple(a)).distance, blade.point_query(tuple(b)).distance)
        t = [float(np.clip(np.dot(v - a, b - a) / np.dot(b - a, b - a), 0.0, 1.0)) for v in corners]
        sides = min(float(np.linalg.norm(v - (a + u * (b - a)))) for v, u in zip(corners, t))
        return min(ends, sides) - incisor.radius

    def penetration(self) -> float:
        """How deep (m) the blade's underside reaches into the undeformed tongue (negative: clear of it)."""
        x, y, a = self._kinematics()[:3]
        return self.c.R - _nearest_point(x, y, math.cos(a), math.sin(a), self.c, ScalarOps)[2]

    @property
    def hand_pose(self) -> tuple[float, float, float, float]:
        """The hand: grip x, z (m), pitch (rad), lateral y (m)."""
        return (*self._hand_pose, self._lateral[2])

    def blade_pose(self) -> np.ndarray:
        x, y, a = self._kinematics()[:3]
        return np.array([[x, y, a, self._lateral[0]]])

    def _read_kinematics(self) -> tuple[float, ...]:
        b = self._cblade
        p, v = _lib.cpBodyGetPosition(b), _lib.cpBodyGetVelocity(b)
        return (p.x, p.y, _lib.cpBodyGetAngle(b), v.x, v.y, _lib.cpBodyGetAngularVelocity(b), *self._hand_pose)

    def _lateral_state(self) -> tuple[float, ...]:
        return self._lateral

    def _hand_v_state(self) -> tuple[float, ...]:
        return self._hand_v

    def state(self) -> DeviceState:
        b, hd = self._blade, self._hand
        (px, py), (vx, vy), (gx, gy) = b.position, b.velocity, hd.position
        return DeviceState(np.array([[px, py, b.angle, vx, vy, b.angular_velocity]]), np.array([[gx, gy, hd.angle]]),
                           np.array([self._lateral]), np.array([[*self._contact, self._incisor]]),
                           np.array([self._hand_v]))

    def load_state(self, s: DeviceState) -> None:
        self._space.place(0, tuple(s.blade[0, :3]), tuple(s.blade[0, 3:]), tuple(s.hand[0]))
        self._hand_pose = tuple(s.hand[0].tolist())
        self._lateral = tuple(s.lateral[0].tolist())
        P, Q, cx, cy, incisor = s.contact[0].tolist()
        self._contact, self._incisor, self._touched = (P, Q, cx, cy), incisor, False     # place() flushed
        self._hand_v = tuple(s.hand_velocity[0].tolist())
        self._impulse = 0.0
        self._forget()


class LaryngoscopeBatch(_DeviceBase):
    """``n`` simulated laryngoscopes in one pymunk space, stepped with numpy and ``pymunk.batch``."""

    _READ = pymunk.batch.BodyFields.POSITION | pymunk.batch.BodyFields.ANGLE | pymunk.batch.BodyFields.VELOCITY \
        | pymunk.batch.BodyFields.ANGULAR_VELOCITY
    _WRITE = pymunk.batch.BodyFields.VELOCITY | pymunk.batch.BodyFields.ANGULAR_VELOCITY \
        | pymunk.batch.BodyFields.FORCE | pymunk.batch.BodyFields.TORQUE
    _ARBITERS = pymunk.batch.ArbiterFields.BODY_A_ID | pymunk.batch.ArbiterFields.BODY_B_ID \
        | pymunk.batch.ArbiterFields.TOTAL_IMPULSE

    def __init__(self, params: LaryngoscopeParams, contact: TongueContact, n: int) -> None:
        super().__init__(params, contact, n)
        self._read = pymunk.batch.Buffer()
        self._arbiters = pymunk.batch.Buffer()
        self._out = np.zeros((2 * n + 1, 6))             # hands and blades interleaved, then the static body
        self._write = pymunk.batch.Buffer()
        self._write.set_float_buf(self._out)
        ids = np.array([b.id for b in self._space.blades], dtype=np.uint64)
        self._id_order = np.argsort(ids)
        self._sorted_ids = ids[self._id_order]
        self._static_id = np.uint64(self.space.static_body.id)
        self._origin = np.zeros((n, 2, 6))
        self._origin[:, :, :2] = self._space.offsets[:, None, :]
        self._lateral = np.zeros((n, 4))
        self._contact = np.zeros((n, 4))
        self._incisor = np.zeros(n)
        self._touched = np.zeros(n, dtype=bool)
        self._hand_v = np.zeros((n, 4))
        self.load_state(self.start_state(n))

    def _bodies(self) -> np.ndarray:
        """``(n, 2, 6)`` local x, y, angle, vx, vy, spin of every hand (0) and blade (1)."""
        self._read.clear()
        pymunk.batch.get_space_bodies(self.space, self._READ, self._read)
        rows = np.frombuffer(self._read.float_buf(), dtype=np.float64)[:12 * self.n].reshape(self.n, 2, 6)
        return rows - self._origin                        # local frame (a new array: the buffer is reused)

    def control_step(self, actions: np.ndarray, moving: np.ndarray | None = None) -> None:
        """Advance one control period; ``actions`` ``(n, 4)`` in [-1, 1]; rows outside ``moving`` hold
        their hands still (their results are discarded by the caller)."""
        if moving is not None:
            actions = np.where(moving[:, None], actions, 0.0)
        bodies = self._bodies()
        vX, vY, spin, v_lat = _hand_command(actions.T, bodies[:, 0, 2], self.params, ArrayOps)
        self.substeps(vX, vY, spin, v_lat, self.n_substeps)

    def substeps(self, vX: np.ndarray, vY: np.ndarray, spin: np.ndarray, v_lat: np.ndarray, count: int) -> None:
        self._space.flush(*np.flatnonzero(self._touched).tolist())
        self._touched[:] = False
        c, h, out = self.c, self.h, self._out
        lo, hi = c.low, c.high
        lat_y, lat_v, hand_lat, anchor = (col.copy() for col in self._lateral.T)
        impulse = np.zeros(self.n)
        loads, slopes = self.contact.loads, self.contact.slopes
        for _ in range(count):
            bodies = self._bodies()
            gx, gy, pitch = bodies[:, 0, 0], bodies[:, 0, 1], bodies[:, 0, 2]
            px, py, a, vx, vy, w = bodies[:, 1].T
            hvx = ArrayOps.clip(vX, (lo[0] - gx) / h, (hi[0] - gx) / h)
            hvy = ArrayOps.clip(vY, (lo[1] - gy) / h, (hi[1] - gy) / h)
            hw = ArrayOps.clip(spin, (lo[2] - pitch) / h, (hi[2] - pitch) / h)
            hl = ArrayOps.clip(v_lat, (lo[3] - hand_lat) / h, (hi[3] - hand_lat) / h)
            hand_lat = hand_lat + h * hl
            ca, sa = np.cos(a), np.sin(a)
            fx, fy, torque, P, Q, cx, cy, lat_y, lat_v, anchor = _tongue_substep(
                (px, py, a, ca, sa, vx, vy, w), (gx, gy, pitch, hvx, hvy, hw), (lat_y, lat_v, hand_lat, anchor), hl,
                loads, slopes, c, ArrayOps)
            hands, blades = out[0:2 * self.n:2], out[1:2 * self.n:2]
            hands[:, 0], hands[:, 1], hands[:, 2] = hvx, hvy, hw
            blades[:, 0], blades[:, 1], blades[:, 2] = vx, vy, w
            blades[:, 3], blades[:, 4], blades[:, 5] = fx, fy, torque
            pymunk.batch.set_space_bodies(self.space, self._WRITE, self._write)
            self.space.step(h)
            self._add_incisor_impulses(impulse)
        self._lateral = np.stack([lat_y, lat_v, hand_lat, anchor], axis=1)
        self._hand_v = np.stack([hvx, hvy, hw, hl], axis=1)
        self._contact = np.stack([P, Q, cx, cy], axis=1)
        self._incisor = impulse / (count * h)
        self._forget()

    def _add_incisor_impulses(self, impulse: np.ndarray) -> None:
        """Add ``|total_impulse|`` of this substep's contact with the incisors to each device's sum (one
        shape a side, so at most one contact a device: one addition each, as the single device's
        callback makes it)."""
        self._arbiters.clear()
        pymunk.batch.get_space_arbiters(self.space, self._ARBITERS, self._arbiters)
        ids = np.frombuffer(self._arbiters.int_buf(), dtype=np.uint64).reshape(-1, 2)
        if len(ids):
            j = np.frombuffer(self._arbiters.float_buf(), dtype=np.float64).reshape(-1, 2)
            blade = np.where(ids[:, 0] == self._static_id, ids[:, 1], ids[:, 0])   # the other body is static
            envs = self._id_order[np.searchsorted(self._sorted_ids, blade)]
            impulse[envs] += np.sqrt(j[:, 0] * j[:, 0] + j[:, 1] * j[:, 1])
            self._touched[envs] = True

    def features(self) -> tuple[np.ndarray, np.ndarray]:
        """Force features ``(n, 4)`` of the contacts and a mask of the devices in contact."""
        P, Q, cx, cy = self._contact.T
        feats = np.stack(_features(cx, cy, self._lateral[:, 3], P, Q, self.c.R, ArrayOps), axis=1)
        return feats, (P != 0.0) | (Q != 0.0)

    def observation(self) -> np.ndarray:
        """``(n, 15)`` device observations (see :meth:`Laryngoscope.observation`)."""
        p = self.params
        bodies = self._bodies()
        (bx, by), (gx, gy) = p.body_start, p.grip_start
        hand, blade = bodies[:, 0], bodies[:, 1]
        lat_y, lat_v, hand_lat, _ = self._lateral.T
        P, Q = self._contact[:, 0], self._contact[:, 1]
        raw = np.stack([(blade[:, 0] - bx) / POSITION_SCALE, (blade[:, 1] - by) / POSITION_SCALE,
                        blade[:, 2] / ANGLE_SCALE, lat_y / LATERAL_SCALE, blade[:, 3] / SPEED_SCALE,
                        blade[:, 4] / SPEED_SCALE, blade[:, 5] / SPIN_SCALE, lat_v / LATERAL_SPEED_SCALE,
                        (hand[:, 0] - gx) / POSITION_SCALE, (hand[:, 1] - gy) / POSITION_SCALE,
                        hand[:, 2] / ANGLE_SCALE, hand_lat / LATERAL_SCALE, P / p.max_normal_force,
                        Q / p.max_sideways_force, self._incisor / p.max_normal_force], axis=1)
        return _squash(raw)

    @property
    def tongue_force(self) -> np.ndarray:
        P, Q = self._contact[:, 0], self._contact[:, 1]
        return np.sqrt(P * P + Q * Q)

    @property
    def normal_force(self) -> np.ndarray:
        return self._contact[:, 0].copy()

    @property
    def sideways_force(self) -> np.ndarray:
        return self._contact[:, 1].copy()

    @property
    def incisor_force(self) -> np.ndarray:
        return self._incisor.copy()

    def hand_velocity(self) -> np.ndarray:
        return self._hand_v.copy()

    def _read_kinematics(self) -> np.ndarray:
        """``(9, n)``: blade x, y, angle, vx, vy, spin and hand x, y, pitch (local frame)."""
        bodies = self._bodies()
        return np.concatenate([bodies[:, 1].T, bodies[:, 0, :3].T])

    def _lateral_state(self) -> np.ndarray:
        return self._lateral.T

    def _hand_v_state(self) -> np.ndarray:
        return self._hand_v.T

    def state(self) -> DeviceState:
        bodies = self._bodies()
        return DeviceState(bodies[:, 1].copy(), bodies[:, 0, :3].copy(), self._lateral.copy(),
                           np.concatenate([self._contact, self._incisor[:, None]], axis=1), self._hand_v.copy())

    def load_state(self, s: DeviceState, rows: np.ndarray | None = None) -> None:
        """Set the state of the devices in ``rows`` (all by default) from the matching rows of ``s``."""
        idx = np.arange(self.n) if rows is None else np.flatnonzero(rows)
        src = np.arange(len(idx)) if len(s.blade) == len(idx) else idx
        for i, j in zip(idx.tolist(), src.tolist()):
            self._space.place(i, tuple(s.blade[j, :3]), tuple(s.blade[j, 3:]), tuple(s.hand[j]))
        self._lateral[idx] = s.lateral[src]
        self._contact[idx] = s.contact[src, :4]
        self._incisor[idx] = s.contact[src, 4]
        self._touched[idx] = False                         # place() flushed them
        self._hand_v[idx] = s.hand_velocity[src]
        self._forget()
