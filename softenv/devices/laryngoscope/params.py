"""The laryngoscope's numbers: blade, handle, hand, coupling and incisors, and the substep they need.

Frame (SI units). The sagittal plane is pymunk's plane: ``X`` is the patient's front (the world's
``x``: the mouth), ``Y`` is up (the world's ``z``: the tongue's dorsum). The tongue is the scene's
sphere, centred at the origin. The lateral axis (the world's ``y``) is a degree of freedom of its
own (:mod:`.physics`).

* **Blade**. A Macintosh 3: a straight 130 mm spatula whose underside presses the tongue, a 22 mm
  proximal flange on top (over 60 % of the length, tapering to 4 mm at the tip), and a 120 mm
  handle at 90 degrees (Macintosh blades attach at 90 degrees) held 70 mm above the heel. Mass: a
  stainless Macintosh 3 blade weighs about 80 g and a battery handle about 150 g (manufacturers'
  catalogue figures; 60-110 g and 120-250 g across makes); both are parameters. Centre of mass and
  moment of inertia follow from treating blade and handle as thin rods (``m L^2 / 12`` each, moved
  to the common centre by the parallel-axis theorem).
* **Hand** at the grip, moved by velocity within a box (it stops at the walls).
* **Upper incisors**: a rounded bar (radius 4 mm) at the mouth, 3 cm in from the heel, its incisal
  edge ``incisor_clearance`` above the flange in the start pose (the airway's mouth opening: 3 mm on
  the normal airway), rising 3 cm up and back along the tooth and the maxilla (so the blade cannot
  slip up past it).
* **Lower incisors** (where the airway has them: ``interincisal_gap``): a rounded edge (radius 4 mm)
  under the blade at the upper incisors' place, ``lower_clearance`` below the underside in the start
  pose, on a jaw that yields: a frictionless spring of ``JAW_STIFFNESS``, critically damped, pushing the
  underside up where it presses the edge (:func:`~.physics.jaw_force`). Computed outside pymunk, as the
  tongue's contact is: a second Chipmunk contact would be solved in an order that depends on the
  spatial index's history (its pair cache), which no other engine can follow, and a rebuilt device
  would not continue bit for bit. A blade pressed down at the mouth rests on the jaw; pressing the
  tongue deeper then means pressing the jaw or turning the blade between the teeth.
* **Neck extension**: the hand may pitch the blade at most ``pitch_limit`` either way (0.5 rad on
  the normal airway; :mod:`softenv.airway`).

Time stepping. The physics substep is ``h = dt / n`` with ``n`` the smallest count that keeps
``h <= max_substep`` (1 ms: a 1 kHz haptic rate) and ``omega_max h <= 0.3`` (accuracy; explicit
springs are stable up to ``omega h < 2``), where ``omega_max`` is the stiffest mode of the blade with
all its springs (coupling, rotary coupling, and the tongue contact's explicit part wherever on the
underside it acts: the design force's stiffness, capped where it would add substeps), or of the
lateral sweep (:meth:`LaryngoscopeParams.omega_max`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from collections.abc import Mapping
from typing import Any

import numpy as np

from ...airway import airway
from ..contact import TongueContact
from ..haptic_presets import PRESETS, HapticPreset
from ...sections import SceneConfig

SPRING_LENGTH = 1.0           # m, rest length of the two coupling springs
# the scene parameters a kernel reads per device (its engine's ``scene_params`` columns), which the torch
# twin can track for gradients: each a value of this class but the tongue's stiffness and the stiffening
# law's depth, factors on the scene's
SCENE_COLUMNS = ("coupling_stiffness", "coupling_damping", "tissue_stiffness", "rotational_stiffness",
                 "rotational_damping", "stiffening_depth")
FACTOR_COLUMNS = ("tissue_stiffness", "stiffening_depth")
START_GAP = 0.005             # m between the blade's underside and the tongue at the start
INCISOR_RADIUS = 0.004        # m
SHAPE_FRICTION = 0.3          # of the blade's and the incisors' shapes (pymunk's contact takes their product)
INCISOR_SETBACK = 0.03        # m from the heel toward the tip
INCISOR_CROWN = (-0.008, 0.03)  # m: the tooth and the maxilla above it, up and back from the incisal edge
LOWER_CROWN = (-0.008, -0.03)   # m: the lower tooth and the mandible, down and back from its incisal edge (drawn)
# N/m: a jaw held by its muscles and joint yields 5 mm under 50 N (a stated choice); stiffer costs substeps
# (omega_max: 34 a period at 1e4 N/m against 20 without the jaw)
JAW_STIFFNESS = 1e4
ACCURACY = 0.3                # omega_max h
# hand workspace around the start grip (m, m, rad)
HAND_REACH = {"insert": 0.025, "withdraw": 0.05, "up": 0.04}   # further in, the handle would be in the mouth


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
    incisor_clearance: float = 0.003    # m above the flange in the start pose (the airway's mouth opening)
    pitch_limit: float = 0.5            # rad either way (the airway's neck extension)
    lower_clearance: float | None = None  # m below the underside in the start pose; None: no lower incisors

    @classmethod
    def from_config(cls, config: SceneConfig) -> "LaryngoscopeParams":
        dev: Mapping[str, Any] = config["device"]
        keys = ("blade_mass", "handle_mass", "coupling_stiffness", "coupling_damping", "rotational_stiffness",
                "rotational_damping", "max_hand_speed", "max_sweep_speed", "max_pitch_rate", "friction", "max_substep",
                "max_normal_force", "max_sideways_force")
        patient = airway(config["airway"])
        lower = None
        if patient.interincisal_gap is not None:
            least = patient.mouth_opening + cls.flange_height * 1e3
            if patient.interincisal_gap < least:
                raise ValueError(f"airway.interincisal_gap = {patient.interincisal_gap:g} mm leaves the blade no room: "
                                 f"allowed >= mouth_opening + the flange's {cls.flange_height * 1e3:g} mm = {least:g} mm")
            lower = (patient.interincisal_gap - least) * 1e-3
        return cls(radius=config["tissue"]["radius"], dt=config["dynamics"]["dt"], preset=dev["haptic_preset"],
                   incisor_clearance=patient.mouth_opening * 1e-3, pitch_limit=patient.neck_extension,
                   lower_clearance=lower, **{k: dev[k] for k in keys})

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
        return (hx - INCISOR_SETBACK, hy + self.flange_height + self.incisor_clearance + INCISOR_RADIUS)

    @property
    def incisor_segment(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """The upper incisors' static shape: a rounded bar (radius 4 mm) from the incisal edge up and
        back along the tooth and the maxilla, so the blade cannot pass beside it."""
        ix, iy = self.incisor
        return (ix, iy), (ix + INCISOR_CROWN[0], iy + INCISOR_CROWN[1])

    @property
    def jaw(self) -> tuple[float, float] | None:
        """Centre of the lower incisal edge's rounding (local frame), or None: no lower incisors."""
        if self.lower_clearance is None:
            return None
        hx, hy = self.heel_start
        return (hx - INCISOR_SETBACK, hy - self.lower_clearance - INCISOR_RADIUS)

    @property
    def lower_incisor_segment(self) -> tuple[tuple[float, float], tuple[float, float]] | None:
        """The lower incisors as drawn: a bar from the edge down and back along the tooth, or None."""
        if self.jaw is None:
            return None
        ix, iy = self.jaw
        return (ix, iy), (ix + LOWER_CROWN[0], iy + LOWER_CROWN[1])

    @property
    def hand_box(self) -> tuple[tuple[float, float, float, float], tuple[float, float, float, float]]:
        """``(low, high)`` of the hand: grip x, grip z (m), pitch (rad), lateral y (m). The floor keeps a
        level blade above the tongue's centre (it can never be pushed through the tongue)."""
        gx, gy = self.grip_start
        low = (gx - HAND_REACH["insert"], gy - (self.radius + START_GAP), -self.pitch_limit, -self.radius)
        high = (gx + HAND_REACH["withdraw"], gy + HAND_REACH["up"], self.pitch_limit, self.radius)
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
        barrier (:func:`tongue_substep`), which is stable at any stiffness and exact at rest, so a
        stiffer tongue costs no substeps and a held press still settles on the law (levered on the
        incisors too: the barrier predicts their push)."""
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
        """The stiffest mode (rad/s) with the contact at this stiffness (see :meth:`omega_max`), and the
        jaw's spring, where there is one, pushing the underside up at any point of it."""
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
        if self.jaw is not None:             # the jaw at each point of the underside, with the tongue's anywhere
            up = np.stack([0.0 * t[:, 0], 1.0 + 0.0 * t[:, 0], rx[:, 0]], axis=-1)   # body frame: level blade
            K = (K[None] + JAW_STIFFNESS * up[:, None, :, None] * up[:, None, None, :]).reshape(-1, 3, 3)
        worst = float(np.linalg.eigvalsh(K * np.outer(scale, scale)).max())
        return math.sqrt(max(worst, (k + lateral_stiffness) / self.mass))

    def substeps(self, contact: TongueContact) -> int:
        """Physics substeps per control period."""
        return substep_count(self.dt, self.omega_max(contact), self.max_substep)



def substep_count(dt: float, omega: float, max_substep: float) -> int:
    """Substeps per period ``dt``: ``h <= max_substep`` and ``omega h <= 0.3``."""
    h = min(max_substep, ACCURACY / omega)
    return max(1, math.ceil(dt / h - 1e-9))

