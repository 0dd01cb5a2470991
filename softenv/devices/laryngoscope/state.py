"""The laryngoscope's engine-neutral parts: its state, the readings of it, and the constants of the blade's
coupling and its contact with the incisors, as every engine keeps and reads them (pymunk's in
:mod:`.single` and :mod:`.batch`, the Warp kernel's in :mod:`.warp_kernel`, the Triton kernel's in
:mod:`.fused`). Nothing here imports an engine.

The constants are Chipmunk's as pymunk sets them for the device (:mod:`.space`): the solver's iterations
and slop, the arbiter's persistence, the bias of position correction, ``CPFLOAT_MIN`` that divisions add.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..._ops import ArrayOps, PhysicsOps
from ..contact import TongueContact
from ..haptic_presets import render_components
from . import ANGLE_SCALE, LATERAL_SCALE, LATERAL_SPEED_SCALE, POSITION_SCALE, SPEED_SCALE, SPIN_SCALE
from .params import INCISOR_RADIUS, SHAPE_FRICTION, SPRING_LENGTH, LaryngoscopeParams
from .physics import (contact_features, coupling_force, grip_offset, hand_command, jaw_contact, nearest_point, squash,
                      substep_constants)
from .physics import jaw_force as jaw_push      # the push (fx, fy, torque); jaw_force below is its size

COLLISION_SLOP = 1e-4         # m (pymunk's default 0.1 assumes pixels)
SOLVER_ITERATIONS = 3         # pymunk's contact solver (default 10): one contact a blade, warm-started over 20+ substeps
PERSISTENCE = 3               # pymunk's collision_persistence: steps an arbiter outlives its contact
TINY = float(np.finfo(np.float64).tiny)      # CPFLOAT_MIN, which Chipmunk adds to keep divisions finite
# the hand-frame anchors of the coupling's two springs, in the order the space adds them
HAND_ANCHORS = ((-SPRING_LENGTH, 0.0), (0.0, SPRING_LENGTH))


@dataclass(frozen=True)
class Coupling:
    """What one step of the coupled blade reads: the blade's inverse mass and moment, the grip (the
    springs' anchor on the blade, body frame), the springs' stiffness and damping."""

    m_inv: float
    i_inv: float
    grip: tuple[float, float]
    k: float
    c: float
    k_rot: float
    c_rot: float

    @classmethod
    def of(cls, p: LaryngoscopeParams) -> Coupling:
        return cls(1.0 / p.mass, 1.0 / p.moment, p.grip, p.coupling_stiffness, p.coupling_damping,
                   p.rotational_stiffness, p.rotational_damping)


def polygon_planes(outline: Any) -> tuple[np.ndarray, np.ndarray]:
    """The blade's vertices ``(V, 2)`` (body frame, pymunk's order) and each vertex's plane normal: that
    of the edge ending there (``cpPolyShape``'s ``planes``)."""
    v = np.asarray(outline, dtype=np.float64)
    edge = v - np.roll(v, 1, axis=0)
    rperp = np.stack([edge[:, 1], -edge[:, 0]], axis=1)
    length = np.sqrt(rperp[:, 0] * rperp[:, 0] + rperp[:, 1] * rperp[:, 1])
    return v, rperp * (1.0 / (length + TINY))[:, None]


def segment_normal(ends: np.ndarray) -> np.ndarray:
    """``cpSegmentShape``'s normal: ``rperp`` of the unit direction from ``a`` to ``b``."""
    delta = ends[1] - ends[0]
    unit = delta * (1.0 / (np.sqrt(delta[0] * delta[0] + delta[1] * delta[1]) + TINY))
    return np.array([unit[1], -unit[0]])


@dataclass(frozen=True)
class IncisorContact:
    """The contact's constants: the incisors' segment (``ends``, its normal, its radius), the blade's
    polygon (vertices and plane normals, body frame), the friction (the product of the shapes'), the
    space's slop and the bias of position correction over a substep, and Chipmunk's ``dt_coef`` (the
    ratio of a step to the last: 1, the space having stepped before)."""

    ends: np.ndarray
    seg_normal: np.ndarray
    radius: float
    local: np.ndarray
    local_normals: np.ndarray
    friction: float
    slop: float
    bias_coef: float
    dt_coef: float = 1.0

    @classmethod
    def of(cls, p: LaryngoscopeParams, h: float) -> IncisorContact:
        bias = math.pow(float(np.float32(1.0) - np.float32(0.1)), 60.0)     # Chipmunk's default: (1 - 0.1f)^60
        ends = np.array(p.incisor_segment, dtype=np.float64)
        local, local_normals = polygon_planes(p.outline)
        return cls(ends, segment_normal(ends), INCISOR_RADIUS, local, local_normals, SHAPE_FRICTION * SHAPE_FRICTION,
                   COLLISION_SLOP, 1.0 - math.pow(bias, h))


@dataclass
class DeviceState:
    """The full state of ``n`` devices as arrays (pickling, tests, the haptic loop)."""

    blade: np.ndarray        # (n, 6) x, y, angle, vx, vy, spin (local frame)
    hand: np.ndarray         # (n, 3) grip x, y, pitch
    lateral: np.ndarray      # (n, 4) blade y, blade vy, hand y, anchor
    contact: np.ndarray      # (n, 5) P, Q, contact x, contact y, incisor force
    hand_velocity: np.ndarray  # (n, 4) the hand's last velocities: x, y, pitch rate, lateral



class LaryngoscopeBase:
    """What every device shares, whatever steps it: parameters, contact law, constants, and the readings
    of its state (written once against ``ops``: floats for one device, arrays for a batch)."""

    ops: PhysicsOps                     # ScalarOps (one device) or ArrayOps (a batch)
    _own: Any                                 # a copy of a reading the caller may keep (float or np.copy)
    _rows: Any                                # readings as (n, m) rows, column by column
    # the state both keep in their own form: floats and tuples (one device) or arrays (a batch)
    _incisor: Any                             # the incisors' mean force over the last period (N)
    _hand_v: Any                              # the hand's last velocities: x, z, pitch rate, lateral

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

    def energy(self) -> np.ndarray:
        """Mechanical energy (J) of each device: kinetic, coupling springs, tongue (normal and lateral) and
        the jaw's spring where there is one."""
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
        if self.c.jaw is None:
            return kinetic + coupling + tongue
        jaw_depth, pressed = jaw_contact(x, y, np.cos(a), np.sin(a), self.c)[:2]
        jaw = np.where(pressed, 0.5 * self.c.k_jaw * jaw_depth ** 2, 0.0)
        return kinetic + coupling + tongue + jaw

    def clinical_values(self) -> tuple[Any, ...]:
        """Each device's values in :data:`softenv.devices.laryngoscope.clinical.COLUMNS` order: tongue and incisor force (N),
        the hand's x, z and lateral y (m), the moments (N m) about the incisal edge of the
        coupling's pull on the blade, split into the wrist's (rotary spring and damper: levering)
        and that of the force at the grip (lifting), and the jaw's push (N) now."""
        c = self.c
        x, y, a, vx, vy, w, gx, gy, pitch = self.kinematics()
        hand_lat = self._lateral_state()[2]
        hw = self._hand_v_state()[2]
        ca, sa, Fx, Fy = self._coupling_pull()
        wrist = c.k_rot * (pitch - a) + c.c_rot * (hw - w)
        ix, iy = self.params.incisor_segment[0]
        qx, qy = grip_offset(ca, sa, c)
        lift = (x + qx - ix) * Fy - (y + qy - iy) * Fx
        jaw = self.jaw_force if c.jaw is not None else self._own(0.0 * x)
        return self.tongue_force, self.incisor_force, gx, gy, hand_lat, wrist, lift, jaw

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
        outline, lower = np.array(p.outline), p.lower_incisor_segment
        out = []
        for (x, y, a), (gx, gy, pitch), (P, Q, cx, cy, incisor) in zip(s.blade[:, :3], s.hand, s.contact):
            rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
            out.append({"outline": outline @ rot.T + (x, y), "incisor": (*p.incisor_segment, INCISOR_RADIUS),
                        "lower_incisor": None if lower is None else (*lower, INCISOR_RADIUS),
                        "handle": np.array([p.heel, p.handle_top]) @ rot.T + (x, y),
                        "hand": (gx, gy, pitch), "contact": (cx, cy) if P > 0 else None,
                        "tongue_force": float(math.hypot(P, Q)), "incisor_force": float(incisor),
                        "radius": p.radius})
        return out

    def haptic_force(self) -> Any:
        """Force ``(n, 3)`` (world x, y, z; N) that the preset device renders to the hand: the coupling's
        pull on the hand, scaled and saturated (:func:`softenv.devices.haptic_presets.render_force`)."""
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

    @property
    def jaw_force(self) -> Any:
        """The jaw's push on the blade (N) in the current state (:func:`~.physics.jaw_force`): 0 without
        lower incisors or clear of them."""
        x, y, a, vx, vy, w = self.kinematics()[:6]
        if self.c.jaw is None:
            return self._own(0.0 * x)
        fx, fy, _ = jaw_push((x, y, a, self.ops.cos(a), self.ops.sin(a), vx, vy, w), self.c, self.ops)
        return self.ops.sqrt(fx * fx + fy * fy)

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



class ArrayLaryngoscopes(LaryngoscopeBase):
    """What every batch engine shares: ``n`` devices' state as arrays and its readings. An engine
    supplies :meth:`substeps`, :meth:`_bodies`, :meth:`_flush` and :meth:`_place`."""

    ops: Any = ArrayOps
    xp: Any = np                        # the arrays' namespace (numpy; torch's through array_api_compat)
    _own: Any = staticmethod(np.copy)

    def _rows(self, *columns: Any) -> Any:
        return self.xp.stack(columns, axis=-1)

    def _array(self, value: Any) -> Any:
        """A host value (numpy) as an array of this batch's namespace."""
        return np.asarray(value)

    def __init__(self, params: LaryngoscopeParams, contact: TongueContact, n: int) -> None:
        super().__init__(params, contact, n)
        array = self._array
        self._lateral = array(np.zeros((n, 4)))
        self._contact = array(np.zeros((n, 4)))
        self._incisor = array(np.zeros(n))
        self._hand_v = array(np.zeros((n, 4)))
        self._loads, self._slopes = array(contact.loads), array(contact.slopes)

    def _bodies(self) -> np.ndarray:
        """``(n, 2, 6)`` local x, y, angle, vx, vy, spin of every hand (0) and blade (1)."""
        raise NotImplementedError

    def _flush(self, mask: Any) -> None:
        """Drop the contact state of the masked devices that their poses do not show."""
        raise NotImplementedError

    def _place(self, rows: np.ndarray, blade: np.ndarray, hand: np.ndarray) -> None:
        """Put the devices ``rows`` (indices) at ``blade`` (x, y, angle, vx, vy, spin) and ``hand`` (x, y,
        pitch) rows, the hands at rest, their contact state dropped."""
        raise NotImplementedError

    def control_step(self, actions: Any, moving: Any = None) -> None:
        """Advance one control period; ``actions`` ``(n, 4)`` in [-1, 1]; rows outside ``moving`` hold
        their hands still (their results are discarded by the caller)."""
        if moving is not None:
            actions = self.xp.where(moving[:, None], actions, 0.0)
        bodies = self._bodies()
        vX, vY, spin, v_lat = hand_command(actions.T, bodies[:, 0, 2], self.params, self.ops)
        self.substeps(vX, vY, spin, v_lat, self.n_substeps)

    def substeps(self, vX: Any, vY: Any, spin: Any, v_lat: Any, count: int) -> None:
        """``count`` substeps with the hands commanded at these velocities (the engine's own)."""
        raise NotImplementedError

    def features(self) -> tuple[Any, Any]:
        """Force features ``(n, 4)`` of the contacts and a mask of the devices in contact."""
        P, Q, cx, cy = self._contact.T
        feats = self.xp.stack(contact_features(cx, cy, self._lateral[:, 3], P, Q, self.c.R, self.ops), axis=1)
        return feats, (P != 0.0) | (Q != 0.0)

    def observation(self) -> Any:
        """``(n, 15)`` device observations (see :meth:`Laryngoscope.observation`)."""
        return squash(self.xp.stack(self._observation_values(), axis=1))

    def _read_kinematics(self) -> np.ndarray:
        """``(9, n)``: blade x, y, angle, vx, vy, spin and hand x, y, pitch (local frame)."""
        bodies = self._bodies()
        return self.xp.concat([bodies[:, 1].T, bodies[:, 0, :3].T])

    def _lateral_state(self) -> np.ndarray:
        return self._lateral.T

    def _hand_v_state(self) -> np.ndarray:
        return self._hand_v.T

    def _contact_state(self) -> np.ndarray:
        return self._contact.T

    def state(self) -> DeviceState:
        bodies = self._bodies()
        return DeviceState(bodies[:, 1].copy(), bodies[:, 0, :3].copy(), self._lateral.copy(),
                           np.concatenate([self._contact, self._incisor[:, None]], axis=1), self._hand_v.copy())

    def load_state(self, s: DeviceState, rows: np.ndarray | None = None) -> None:
        """Set the state of the devices in ``rows`` (all by default) from the matching rows of ``s``."""
        idx = np.arange(self.n) if rows is None else np.flatnonzero(rows)
        src = np.arange(len(idx)) if len(s.blade) == len(idx) else idx
        self._place(idx, s.blade[src], s.hand[src])
        self._lateral[idx] = s.lateral[src]
        self._contact[idx] = s.contact[src, :4]
        self._incisor[idx] = s.contact[src, 4]
        self._hand_v[idx] = s.hand_velocity[src]
        self._forget()


class KernelLaryngoscopes(ArrayLaryngoscopes):
    """What the kernels' engines share (:mod:`.warp_kernel`, :mod:`.fused`): each device's blade ``(n, 6)``
    and hand ``(n, 3)`` in its own local frame, the coupling's and the contact's constants; an engine
    overrides :meth:`control_step` or :meth:`substeps`. A kernel keeps
    no contact state across a control period (each opens with no arbiter and no bias velocity), so
    placing a device drops nothing."""

    def __init__(self, params: LaryngoscopeParams, contact: TongueContact, n: int) -> None:
        super().__init__(params, contact, n)
        self.coupling = Coupling.of(params)
        self.incisors = IncisorContact.of(params, self.h)
        self._blade = self._array(np.zeros((n, 6)))
        self._hand = self._array(np.zeros((n, 3)))
        self.load_state(self.start_state(n))

    def _bodies(self) -> Any:
        xp = self.xp
        hands = xp.concat([self._hand, self._hand_v[:, :3]], axis=1)
        return xp.stack([hands, self._blade], axis=1)

    def _flush(self, mask: Any) -> None:
        """Nothing to drop: no contact state outlives a control period."""

    def _place(self, rows: np.ndarray, blade: np.ndarray, hand: np.ndarray) -> None:
        self._blade[rows] = blade
        self._hand[rows] = hand
