"""``n`` simulated laryngoscopes stepped together: one pymunk space, numpy and ``pymunk.batch``. The
physics is :mod:`.physics`, run with ``ArrayOps``: device 0 equals a single
:class:`~.single.Laryngoscope` bit for bit, the others to rounding (:mod:`.space`)."""

from __future__ import annotations

import numpy as np
import pymunk
import pymunk.batch

from ..._ops import ArrayOps
from ..contact import TongueContact
from .params import LaryngoscopeParams
from .physics import contact_features, hand_command, squash, tongue_substep
from .space import DeviceState, LaryngoscopeBase


class LaryngoscopeBatch(LaryngoscopeBase):
    """``n`` simulated laryngoscopes in one pymunk space, stepped with numpy and ``pymunk.batch``."""

    ops = ArrayOps
    _own = staticmethod(np.copy)

    @staticmethod
    def _rows(*columns: np.ndarray) -> np.ndarray:
        return np.stack(columns, axis=-1)

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
        vX, vY, spin, v_lat = hand_command(actions.T, bodies[:, 0, 2], self.params, ArrayOps)
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
            fx, fy, torque, P, Q, cx, cy, lat_y, lat_v, anchor = tongue_substep(
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
        feats = np.stack(contact_features(cx, cy, self._lateral[:, 3], P, Q, self.c.R, ArrayOps), axis=1)
        return feats, (P != 0.0) | (Q != 0.0)

    def observation(self) -> np.ndarray:
        """``(n, 15)`` device observations (see :meth:`Laryngoscope.observation`)."""
        return squash(np.stack(self._observation_values(), axis=1))

    def _read_kinematics(self) -> np.ndarray:
        """``(9, n)``: blade x, y, angle, vx, vy, spin and hand x, y, pitch (local frame)."""
        bodies = self._bodies()
        return np.concatenate([bodies[:, 1].T, bodies[:, 0, :3].T])

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
        for i, j in zip(idx.tolist(), src.tolist()):
            self._space.place(i, tuple(s.blade[j, :3]), tuple(s.blade[j, 3:]), tuple(s.hand[j]))
        self._lateral[idx] = s.lateral[src]
        self._contact[idx] = s.contact[src, :4]
        self._incisor[idx] = s.contact[src, 4]
        self._touched[idx] = False                         # place() flushed them
        self._hand_v[idx] = s.hand_velocity[src]
        self._forget()

