"""The laryngoscope in pymunk: the space of ``n`` devices, their state, and what single and batch read
from it alike (observation, forces, clinical values, energy, drawing, the force a haptic device renders).

* **Blade**: a dynamic body, one convex shape. **Hand**: a kinematic body at the grip, moved only by
  velocity (so the coupling's damper sees the motion). **Coupling**: :func:`virtual_coupling`.
  **Incisors**: a static rounded segment; pymunk solves that contact, and its force is
  ``|total_impulse| / h`` summed over the substeps of a control period and divided by the period.
* In a batch, device ``i`` sits at its own place in the plane (a grid 1 m apart, so no shapes of two
  devices ever meet): positions there carry the offset, which changes their rounding, so device 0
  (at the origin) equals a single device bit for bit and the others agree to rounding (tested).

Reproducibility. No contact state crosses a control period: at the start of each, a device whose
blade touched the incisors during the last one has them removed and added again (dropping pymunk's
cached contact impulses) and its blade's position-correction velocity cleared, so a device rebuilt
from :meth:`LaryngoscopeBase.state` (pickle, deepcopy, reset) continues bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

try:
    import pymunk
    from pymunk._chipmunk import lib as _lib
except ImportError as exc:  # pragma: no cover - the device extra is part of every test install
    raise ImportError("the simulated laryngoscope needs pymunk >= 7: pip install 'softenv[device]'") from exc

from ..._ops import ArrayOps, PhysicsOps
from ..contact import TongueContact
from ..presets import render_components
from . import ANGLE_SCALE, LATERAL_SCALE, LATERAL_SPEED_SCALE, POSITION_SCALE, SPEED_SCALE, SPIN_SCALE
from .params import INCISOR_RADIUS, SHAPE_FRICTION, SPRING_LENGTH, LaryngoscopeParams
from .physics import coupling_force, grip_offset, nearest_point, substep_constants

BLADE_TYPE, INCISOR_TYPE = 1, 2
GRID_SPACING = 1.0            # m between devices in a batch
COLLISION_SLOP = 1e-4         # m (pymunk's default 0.1 assumes pixels)
SOLVER_ITERATIONS = 3         # pymunk's contact solver (default 10): one contact a blade, warm-started over 20+ substeps


def virtual_coupling(hand: pymunk.Body, body: pymunk.Body, anchor: tuple[float, float],
                     p: LaryngoscopeParams) -> tuple[pymunk.Constraint, ...]:
    """The hand -> blade coupling: two 1 m ``DampedSpring`` s along the hand's axes meeting at
    ``anchor`` (body frame) and a ``DampedRotarySpring`` (see the module docstring)."""
    k, c = p.coupling_stiffness, p.coupling_damping
    return (pymunk.DampedSpring(hand, body, (-SPRING_LENGTH, 0.0), anchor, SPRING_LENGTH, k, c),
            pymunk.DampedSpring(hand, body, (0.0, SPRING_LENGTH), anchor, SPRING_LENGTH, k, c),
            pymunk.DampedRotarySpring(hand, body, 0.0, p.rotational_stiffness, p.rotational_damping))



class DeviceSpace:
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
        self.incisors: list[pymunk.Segment] = []
        for ox, oy in self.offsets.tolist():
            hand = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
            blade = pymunk.Body(p.mass, p.moment)
            # one shape a side, so one contact a device: with two, the solver's order of them would
            # depend on the spatial index's history, and a rebuilt device would not continue bit for bit
            shape = pymunk.Poly(blade, p.outline)
            shape.collision_type, shape.friction, shape.elasticity = BLADE_TYPE, SHAPE_FRICTION, 0.0
            (ax, ay), (bx, by) = p.incisor_segment
            incisor = pymunk.Segment(self.space.static_body, (ox + ax, oy + ay), (ox + bx, oy + by), INCISOR_RADIUS)
            incisor.collision_type, incisor.friction, incisor.elasticity = INCISOR_TYPE, SHAPE_FRICTION, 0.0
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



class LaryngoscopeBase:
    """What the single and batched devices share: parameters, contact law, space, constants, and the
    readings of their state (written once against ``ops``: floats for one device, arrays for a batch)."""

    ops: PhysicsOps                     # ScalarOps (one device) or ArrayOps (a batch)
    _own: Any                                 # a copy of a reading the caller may keep (float or np.copy)
    _rows: Any                                # readings as (n, m) rows, column by column
    # the state both keep in their own form: floats and tuples (one device) or arrays (a batch)
    _incisor: Any                             # the incisors' mean force over the last period (N)
    _hand_v: Any                              # the hand's last velocities: x, z, pitch rate, lateral
    _space: DeviceSpace                       # pymunk's (the single device, the pymunk batch)

    def __init__(self, params: LaryngoscopeParams, contact: TongueContact, n: int) -> None:
        self.params = params
        self.contact = contact
        self.n_substeps = params.substeps(contact)
        self.h = params.dt / self.n_substeps
        self.c = substep_constants(params, contact, self.h)
        self.n = n
        self._forget()

    def _forget(self) -> None:
        """Drop what was derived from the bodies' state: it has just changed (substeps, a new state)."""
        self._kin: Any = None
        self._pull: Any = None

    def kinematics(self) -> Any:
        """Blade x, y, angle, vx, vy, spin and hand x, y, pitch (local frame), read once per state."""
        if self._kin is None:
            self._kin = self._read_kinematics()
        return self._kin

    def _coupling_pull(self) -> tuple[Any, Any, Any, Any]:
        """``(cos, sin)`` of the blade's angle and the coupling's force ``(Fx, Fy)`` on it now (the
        clinical record and the haptic force both need them; computed once per state)."""
        if self._pull is None:
            x, y, a, vx, vy, w, gx, gy, pitch = self.kinematics()
            hvx, hvy, hw, _ = self._hand_v_state()
            ca, sa = self.ops.cos(a), self.ops.sin(a)
            Fx, Fy, _ = coupling_force((x, y, a, ca, sa, vx, vy, w), (gx, gy, pitch, hvx, hvy, hw), self.c)
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
        depth = self.params.radius - nearest_point(x, y, np.cos(a), np.sin(a), self.c, ArrayOps)[2]
        touching = depth > 0
        tongue = np.where(touching, self.contact.potential(depth) + 0.5 * self.contact.lateral_stiffness
                          * (ly - anchor) ** 2, 0.0)
        return kinetic + coupling + tongue

    def clinical_values(self) -> tuple[Any, ...]:
        """Each device's values in :data:`softenv.clinical.COLUMNS` order: tongue and incisor force (N),
        the hand's x, z and lateral y (m), and the moments (N m) about the incisal edge of the
        coupling's pull on the blade, split into the wrist's (rotary spring and damper: levering)
        and that of the force at the grip (lifting)."""
        c = self.c
        x, y, a, vx, vy, w, gx, gy, pitch = self.kinematics()
        hand_lat = self._lateral_state()[2]
        hw = self._hand_v_state()[2]
        ca, sa, Fx, Fy = self._coupling_pull()
        wrist = c.k_rot * (pitch - a) + c.c_rot * (hw - w)
        ix, iy = self.params.incisor_segment[0]
        qx, qy = grip_offset(ca, sa, c)
        lift = (x + qx - ix) * Fy - (y + qy - iy) * Fx
        return self.tongue_force, self.incisor_force, gx, gy, hand_lat, wrist, lift

    def start_state(self, n: int) -> DeviceState:
        p = self.params
        bx, by = p.body_start
        gx, gy = p.grip_start
        return DeviceState(np.tile([bx, by, 0.0, 0.0, 0.0, 0.0], (n, 1)), np.tile([gx, gy, 0.0], (n, 1)),
                           np.zeros((n, 4)), np.zeros((n, 5)), np.zeros((n, 4)))

    def blade_pose(self) -> Any:
        """``(n, 4)``: x, z (m), pitch (rad) of the blade's centre of mass and its lateral y (m)."""
        x, y, a = self.kinematics()[:3]
        return self._rows(x, y, a, self._lateral_state()[0])

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

    def haptic_force(self) -> Any:
        """Force ``(n, 3)`` (world x, y, z; N) that the preset device renders to the hand: the coupling's
        pull on the hand, scaled and saturated (:func:`softenv.devices.presets.render_force`)."""
        return self._rows(*self._rendered())

    def _rendered(self) -> tuple[Any, Any, Any]:
        """The coupling's pull on the hand (world x, y, z), as the preset renders it."""
        c = self.c
        lat_y, lat_v, hand_lat, _ = self._lateral_state()
        hl = self._hand_v_state()[3]
        Fx, Fy = self._coupling_pull()[2:]
        return render_components(-Fx, c.k * (lat_y - hand_lat) + c.c * (lat_v - hl), -Fy, c.k, self.params.haptic,
                                 self.ops)

    def _observation_values(self) -> tuple[Any, ...]:
        """The device part of the observation before squashing, in :data:`LARYNGOSCOPE_OBS` order: poses
        relative to the start, over their scales (module constants of :mod:`softenv.devices.laryngoscope`)."""
        p = self.params
        (bx, by), (gx, gy) = p.body_start, p.grip_start
        px, py, a, vx, vy, w, hx, hy, pitch = self.kinematics()
        lat_y, lat_v, hand_lat, _ = self._lateral_state()
        P, Q = self._contact_state()[:2]
        return ((px - bx) / POSITION_SCALE, (py - by) / POSITION_SCALE, a / ANGLE_SCALE, lat_y / LATERAL_SCALE,
                vx / SPEED_SCALE, vy / SPEED_SCALE, w / SPIN_SCALE, lat_v / LATERAL_SPEED_SCALE,
                (hx - gx) / POSITION_SCALE, (hy - gy) / POSITION_SCALE, pitch / ANGLE_SCALE,
                hand_lat / LATERAL_SCALE, P / p.max_normal_force, Q / p.max_sideways_force,
                self._incisor / p.max_normal_force)

    @property
    def tongue_force(self) -> Any:
        """The tongue's contact force (N): ``sqrt(P^2 + Q^2)``."""
        P, Q = self._contact_state()[:2]
        return self.ops.sqrt(P * P + Q * Q)

    @property
    def normal_force(self) -> Any:
        """The tongue's normal force ``P`` (N)."""
        return self._own(self._contact_state()[0])

    @property
    def sideways_force(self) -> Any:
        """The tongue's sideways force ``Q`` (N)."""
        return self._own(self._contact_state()[1])

    @property
    def incisor_force(self) -> Any:
        """The incisors' force (N), the mean over the last control period."""
        return self._own(self._incisor)

    def hand_velocity(self) -> np.ndarray:
        """``(n, 4)``: the hand's last velocities x, z (m/s), pitch rate (rad/s), lateral (m/s)."""
        return np.array(self._hand_v, ndmin=2)

    # what single and batch keep in their own form (tuples of floats, or arrays)
    def _read_kinematics(self) -> Any:
        raise NotImplementedError

    def _lateral_state(self) -> Any:
        raise NotImplementedError

    def _hand_v_state(self) -> Any:
        raise NotImplementedError

    def _contact_state(self) -> Any:
        raise NotImplementedError

    def state(self) -> DeviceState:
        raise NotImplementedError

