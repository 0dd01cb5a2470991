"""``n`` simulated laryngoscopes in one pymunk space, stepped together with numpy and ``pymunk.batch``
(:class:`LaryngoscopeBatch`): the tongue's substep on arrays (:func:`~.physics.tongue_substep`), the blades,
their couplings and the incisors in Chipmunk. Device 0 equals a single :class:`~.single.Laryngoscope`
bit for bit, the others to rounding (each sits at its own place in the space: :mod:`.space`)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pymunk
import pymunk.batch

from ..contact import TongueContact
from .params import LaryngoscopeParams
from .physics import jaw_force, tongue_substep
from .space import DeviceSpace, listen_to_incisors, teeth_on_blade
from .state import ArrayLaryngoscopes

Vec3 = tuple[Any, Any, Any]       # x, y and angular components, one entry a device
Vec4 = tuple[Any, Any, Any, Any]


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
        self._touched = np.zeros(n, dtype=bool)           # devices whose blades met the incisors this period
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
        # the incisors' force and torque on each blade in the last substep, and in this one (the listener's)
        self._teeth, self._teeth_next = np.zeros((n, 3)), np.zeros((n, 3))
        self._device_of = {blade._body: i for i, blade in enumerate(self._space.blades)}
        self._post_solve = listen_to_incisors(self.space, self._on_incisors)
        self.load_state(self.start_state(n))

    @property
    def space(self) -> pymunk.Space:
        return self._space.space

    def _on_incisors(self, arbiter: Any) -> None:
        blade = arbiter.body_b if arbiter.body_b in self._device_of else arbiter.body_a
        self._teeth_next[self._device_of[blade]] = teeth_on_blade(arbiter, blade, self.h)

    def substeps(self, vX: Any, vY: Any, spin: Any, v_lat: Any, count: int) -> None:
        xp = self.xp
        self._flush(self._touched)
        self._touched = xp.zeros_like(self._touched)
        self._teeth[:] = 0.0                              # no contact state crosses a period
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
        blade = (px, py, a, ca, sa, vx, vy, w)
        teeth = tuple(self._teeth.T)
        if c.jaw is not None:                             # the jaw's push now, with the incisors' last
            jaw = jaw_force(blade, c, ops)
            teeth = tuple(t + j for t, j in zip(teeth, jaw))
        fx, fy, torque, P, Q, cx, cy, lat_y, lat_v, anchor = tongue_substep(
            blade, (gx, gy, pitch, hvx, hvy, hw), (lat_y, lat_v, hand_lat, anchor), hl, teeth, self._loads,
            self._slopes, c, ops)
        if c.jaw is not None:
            fx, fy, torque = fx + jaw[0], fy + jaw[1], torque + jaw[2]
        self._teeth_next[:] = 0.0
        self._advance((hvx, hvy, hw), (vx, vy, w), (fx, fy, torque), impulse)
        self._teeth, self._teeth_next = self._teeth_next, self._teeth
        return (lat_y, lat_v, hand_lat, anchor), (hvx, hvy, hw, hl), (P, Q, cx, cy)

    def _bodies(self) -> np.ndarray:
        """``(n, 2, 6)`` local x, y, angle, vx, vy, spin of every hand (0) and blade (1)."""
        self._read.clear()
        pymunk.batch.get_space_bodies(self.space, self._READ, self._read)
        rows = np.frombuffer(self._read.float_buf(), dtype=np.float64)[:12 * self.n].reshape(self.n, 2, 6)
        return rows - self._origin                        # local frame (a new array: the buffer is reused)

    def _advance(self, hand_v: Vec3, blade_v: Vec3, force: Vec3, impulse: np.ndarray) -> None:
        """One substep of the blades and hands: the hands at ``hand_v``, the blades with their velocities
        ``blade_v`` under ``force`` (x, y, torque); adds each device's incisor impulse to ``impulse``."""
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
        self._touched[rows] = False                       # place() flushed them
