"""``n`` simulated laryngoscopes stepped together on numpy arrays. The physics is :mod:`.physics`, run
with ``ArrayOps``, on one of two engines for the blade, its coupling and the incisors:

* :class:`LaryngoscopeBatch`: one pymunk space, stepped through ``pymunk.batch``. Device 0 equals a
  single :class:`~.single.Laryngoscope` bit for bit, the others to rounding (:mod:`.space`).
* :class:`LaryngoscopeArrays`: Chipmunk's step written out on arrays (:mod:`.rigid`, :mod:`.incisors`),
  no pymunk space: every device equals a single one bit for bit.

:class:`ArrayLaryngoscopes` holds what both share: the substep loop, the state and its readings."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pymunk
import pymunk.batch

from ..._ops import ArrayOps
from ..contact import TongueContact
from . import incisors
from .params import INCISOR_RADIUS, SHAPE_FRICTION, LaryngoscopeParams
from .physics import contact_features, hand_command, squash, tongue_substep
from .rigid import Coupling, Incisors, coupling_step
from .space import COLLISION_SLOP, SOLVER_ITERATIONS, DeviceSpace, DeviceState, LaryngoscopeBase


Vec3 = tuple[Any, Any, Any]       # x, y and angular components, one entry a device
Vec4 = tuple[Any, Any, Any, Any]


class ArrayLaryngoscopes(LaryngoscopeBase):
    """What the two batch engines share: ``n`` devices' state as arrays, the substep loop, the readings.
    An engine supplies :meth:`_bodies`, :meth:`_advance`, :meth:`_flush` and :meth:`_place`."""

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
        self._touched = array(np.zeros(n, dtype=bool))
        self._hand_v = array(np.zeros((n, 4)))
        self._loads, self._slopes = array(contact.loads), array(contact.slopes)

    def _bodies(self) -> np.ndarray:
        """``(n, 2, 6)`` local x, y, angle, vx, vy, spin of every hand (0) and blade (1)."""
        raise NotImplementedError

    def _advance(self, hand_v: Vec3, blade_v: Vec3, force: Vec3, impulse: np.ndarray) -> None:
        """One substep of the blades and hands: the hands at ``hand_v``, the blades with their velocities
        ``blade_v`` under ``force`` (x, y, torque); adds each device's incisor impulse to ``impulse``."""
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
        xp = self.xp
        self._flush(self._touched)
        self._touched = xp.zeros_like(self._touched)
        lateral = tuple(self._own(col) for col in self._lateral.T)
        impulse = xp.zeros_like(self._incisor)
        for _ in range(count):
            lateral, hand_v, contact = self._substep((vX, vY, spin, v_lat), lateral, impulse)
        self._lateral = xp.stack(lateral, axis=1)
        self._hand_v = xp.stack(hand_v, axis=1)
        self._contact = xp.stack(contact, axis=1)
        self._incisor = impulse / (count * self.h)
        self._forget()

    def _substep(self, command: Vec4, lateral: Vec4, impulse: Any) -> tuple[Vec4, Vec4, Vec4]:
        """One substep: the hands commanded to ``command`` (x, y, pitch and lateral velocity, within the
        workspace), the tongue's contact and lateral sweep from ``lateral`` (y, velocity, hand's lateral
        position, anchor), the blades and hands advanced (incisor impulses added to ``impulse``). Returns
        the new lateral state, the hands' velocities and the tongue contact (P, Q, cx, cy)."""
        ops, c, h = self.ops, self.c, self.h
        lo, hi = c.low, c.high
        vX, vY, spin, v_lat = command
        lat_y, lat_v, hand_lat, anchor = lateral
        bodies = self._bodies()
        gx, gy, pitch = bodies[:, 0, 0], bodies[:, 0, 1], bodies[:, 0, 2]
        px, py, a, vx, vy, w = bodies[:, 1].T
        hvx = ops.clip(vX, (lo[0] - gx) / h, (hi[0] - gx) / h)
        hvy = ops.clip(vY, (lo[1] - gy) / h, (hi[1] - gy) / h)
        hw = ops.clip(spin, (lo[2] - pitch) / h, (hi[2] - pitch) / h)
        hl = ops.clip(v_lat, (lo[3] - hand_lat) / h, (hi[3] - hand_lat) / h)
        hand_lat = hand_lat + h * hl
        ca, sa = ops.cos(a), ops.sin(a)
        fx, fy, torque, P, Q, cx, cy, lat_y, lat_v, anchor = tongue_substep(
            (px, py, a, ca, sa, vx, vy, w), (gx, gy, pitch, hvx, hvy, hw), (lat_y, lat_v, hand_lat, anchor), hl,
            self._loads, self._slopes, c, ops)
        self._advance((hvx, hvy, hw), (vx, vy, w), (fx, fy, torque), impulse)
        return (lat_y, lat_v, hand_lat, anchor), (hvx, hvy, hw, hl), (P, Q, cx, cy)

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
        self._touched[idx] = False                         # _place() flushed them
        self._hand_v[idx] = s.hand_velocity[src]
        self._forget()



class LaryngoscopeBatch(ArrayLaryngoscopes):
    """``n`` simulated laryngoscopes in one pymunk space, stepped with numpy and ``pymunk.batch``."""

    _READ = pymunk.batch.BodyFields.POSITION | pymunk.batch.BodyFields.ANGLE | pymunk.batch.BodyFields.VELOCITY \
        | pymunk.batch.BodyFields.ANGULAR_VELOCITY
    _WRITE = pymunk.batch.BodyFields.VELOCITY | pymunk.batch.BodyFields.ANGULAR_VELOCITY \
        | pymunk.batch.BodyFields.FORCE | pymunk.batch.BodyFields.TORQUE
    _ARBITERS = pymunk.batch.ArbiterFields.BODY_A_ID | pymunk.batch.ArbiterFields.BODY_B_ID \
        | pymunk.batch.ArbiterFields.TOTAL_IMPULSE

    def __init__(self, params: LaryngoscopeParams, contact: TongueContact, n: int) -> None:
        super().__init__(params, contact, n)
        self._space = DeviceSpace(params, n)
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
        self.load_state(self.start_state(n))

    def _bodies(self) -> np.ndarray:
        """``(n, 2, 6)`` local x, y, angle, vx, vy, spin of every hand (0) and blade (1)."""
        self._read.clear()
        pymunk.batch.get_space_bodies(self.space, self._READ, self._read)
        rows = np.frombuffer(self._read.float_buf(), dtype=np.float64)[:12 * self.n].reshape(self.n, 2, 6)
        return rows - self._origin                        # local frame (a new array: the buffer is reused)

    def _advance(self, hand_v: Vec3, blade_v: Vec3, force: Vec3, impulse: np.ndarray) -> None:
        out = self._out
        hands, blades = out[0:2 * self.n:2], out[1:2 * self.n:2]
        hands[:, 0], hands[:, 1], hands[:, 2] = hand_v
        blades[:, 0], blades[:, 1], blades[:, 2] = blade_v
        blades[:, 3], blades[:, 4], blades[:, 5] = force
        pymunk.batch.set_space_bodies(self.space, self._WRITE, self._write)
        self.space.step(self.h)
        self._add_incisor_impulses(impulse)

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

    def _flush(self, mask: np.ndarray) -> None:
        self._space.flush(*np.flatnonzero(mask).tolist())

    def _place(self, rows: np.ndarray, blade: np.ndarray, hand: np.ndarray) -> None:
        for i, b, g in zip(rows.tolist(), blade.tolist(), hand.tolist()):
            self._space.place(i, tuple(b[:3]), tuple(b[3:]), tuple(g))


class LaryngoscopeArrays(ArrayLaryngoscopes):
    """``n`` simulated laryngoscopes on numpy arrays alone: Chipmunk's step for the blades, their
    couplings and the incisors written out (:func:`~.rigid.coupling_step`), every device in its own
    local frame, so each equals a single pymunk :class:`~.single.Laryngoscope` bit for bit."""

    def __init__(self, params: LaryngoscopeParams, contact: TongueContact, n: int) -> None:
        super().__init__(params, contact, n)
        h, xp = self.h, self.xp
        bias = math.pow(float(np.float32(1.0) - np.float32(0.1)), 60.0)     # Chipmunk's default: (1 - 0.1f)^60
        solver = incisors.Solver.of(params.incisor_segment, INCISOR_RADIUS, params.outline, 1.0 / params.mass,
                                    1.0 / params.moment, SHAPE_FRICTION * SHAPE_FRICTION, h, COLLISION_SLOP,
                                    1.0 - math.pow(bias, h), self._array)
        self._coupling = Coupling.of(params)
        zero = self._array(np.zeros(n))
        self._teeth = Incisors(solver, incisors.Arbiters.none(n, xp, zero.device), [zero, zero, zero], xp)
        self._blade = self._array(np.zeros((n, 6)))
        self._hand = self._array(np.zeros((n, 3)))
        self.load_state(self.start_state(n))

    def _bodies(self) -> Any:
        xp = self.xp
        hands = xp.concat([self._hand, self._hand_v[:, :3]], axis=1)
        return xp.stack([hands, self._blade], axis=1)

    def _advance(self, hand_v: Vec3, blade_v: Vec3, force: Vec3, impulse: Any) -> None:
        xp = self.xp
        blade = (*self._blade[:, :3].T, *blade_v)
        moved, hand = coupling_step(blade, tuple(self._hand.T), hand_v, force, self.h, self._coupling,
                                    SOLVER_ITERATIONS, self.ops, self._teeth)
        self._blade = xp.stack(moved, axis=1)
        self._hand = xp.stack(hand, axis=1)
        self._hand_v[:, :3] = xp.stack(hand_v, axis=1)
        arbiters = self._teeth.arbiters
        touching = arbiters.alive & (arbiters.ticks == 0)
        assert arbiters.normal is not None
        total = xp.zeros_like(arbiters.normal)
        for slot in range(2):                       # cpArbiterTotalImpulse: the contacts' impulses summed
            on = (touching & arbiters.exists[:, slot])[:, None]
            jx, jy = incisors.rotate(arbiters.normal, arbiters.jn[:, slot], arbiters.jt[:, slot])
            total = xp.where(on, total + xp.stack([jx, jy], axis=1), total)
        impulse += xp.where(touching, xp.sqrt(total[:, 0] * total[:, 0] + total[:, 1] * total[:, 1]), 0.0)
        self._touched |= touching

    def _flush(self, mask: Any) -> None:
        # as the pymunk space's flush: the arbiters dropped, the bias velocities spent over zero time
        xp = self.xp
        self._teeth.arbiters.drop(mask, xp)
        self._teeth.bias = [xp.where(mask, 0.0, b) for b in self._teeth.bias]

    def _place(self, rows: np.ndarray, blade: np.ndarray, hand: np.ndarray) -> None:
        self._blade[rows] = blade
        self._hand[rows] = hand
        mask = np.zeros(self.n, dtype=bool)
        mask[rows] = True
        self._flush(mask)
