"""One simulated laryngoscope, stepped with Python floats: the single env's device and the 1 kHz
haptic loop's (:mod:`softenv.haptics`). The physics is :mod:`.physics`: its contact arithmetic
written out for floats (``tongue_substep_floats``, held bit for bit to the ``ops`` version the batch
(:mod:`.batch`) runs on arrays)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pymunk
from pymunk._chipmunk import lib as _lib

from ..._ops import ScalarOps
from ..contact import TongueContact
from .params import LaryngoscopeParams
from .physics import (NO_TEETH, contact_features, hand_command, jaw_force, near_walls, nearest_point, squash,
                      tongue_substep_floats)
from .space import DeviceSpace, listen_to_incisors, teeth_on_blade
from .state import DeviceState, LaryngoscopeBase


class Laryngoscope(LaryngoscopeBase):
    """One simulated laryngoscope, stepped with Python floats (the single env and the haptic loop)."""

    ops = ScalarOps
    _own = staticmethod(float)

    @staticmethod
    def _rows(*columns: float) -> np.ndarray:
        return np.array([columns])
    _impulse: float                              # the incisors' impulse summed over this period's substeps
    _teeth: tuple[float, float, float]           # their force and torque on the blade in the last substep
    _lateral: tuple[float, float, float, float]  # blade y, blade vy, hand y, anchor
    _hand_pose: tuple[float, float, float]       # grip x, y, pitch

    def __init__(self, params: LaryngoscopeParams, contact: TongueContact) -> None:
        super().__init__(params, contact, 1)
        self._space = DeviceSpace(params, 1)
        self._hand, self._blade = self._space.hands[0], self._space.blades[0]
        self._chand, self._cblade, self._cspace = self._hand._body, self._blade._body, self.space._space
        self._loads, self._slopes = contact.loads_list, contact.slopes_list
        self._touched = False
        self._teeth = NO_TEETH
        self._post_solve = listen_to_incisors(self.space, self._on_incisors)
        self.reset()

    @property
    def space(self) -> pymunk.Space:
        return self._space.space

    def _on_incisors(self, arbiter: Any) -> None:
        """After a substep's solve: add the incisors' ``|total_impulse|`` to the period's sum and keep
        their force and torque on the blade for the next substep's tongue contact."""
        j = _lib.cpArbiterTotalImpulse(arbiter)
        self._impulse += math.sqrt(j.x * j.x + j.y * j.y)
        self._teeth = teeth_on_blade(arbiter, self._cblade, self.c.h)
        self._touched = True

    def reset(self) -> None:
        self.load_state(self.start_state(1))

    def control_step(self, action: list[float]) -> None:
        """Advance one control period with the hand commanded by ``action`` (4 floats in [-1, 1])."""
        vX, vY, spin, v_lat = hand_command(action, self._hand_pose[2], self.params, ScalarOps)
        self.substeps(vX, vY, spin, v_lat, self.n_substeps)

    def substeps(self, vX: float, vY: float, spin: float, v_lat: float, count: int) -> None:
        """``count`` physics substeps with the hand's commanded world velocities.

        The loop talks to Chipmunk through pymunk's C bindings (``pymunk._chipmunk.lib``): pymunk's
        Python properties cost 1.5 us each, a tenth of a 1 kHz tick's budget. Away from the tongue it
        skips the normal-force arithmetic (whose result there is zero) and leaves the blade's force at
        the zero Chipmunk resets it to after every step.
        """
        if self._touched:
            self._space.flush(0)
            self._touched = False
        c, lo, hi, h = self.c, self.c.low, self.c.high, self.c.h
        jaw = c.jaw is not None
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
        wall_x, wall_y, wall_p, wall_l = near_walls((gx, gy, pitch, hand_lat), (vX, vY, spin, v_lat), lo, hi,
                                                     h * count)
        hvx, hvy, hw, hl = vX, vY, spin, v_lat
        written = None
        self._impulse = 0.0
        self._teeth = NO_TEETH
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
                teeth = self._teeth
                if jaw:                                     # the jaw's push now, with the incisors' last
                    jfx, jfy, jtq = jaw_force((px, py, a, ca, sa, vx, vy, w), c, ScalarOps)
                    teeth = (teeth[0] + jfx, teeth[1] + jfy, teeth[2] + jtq)
                fx, fy, torque, P, Q, cx, cy, lat_y, lat_v, anchor = tongue_substep_floats(
                    (px, py, a, ca, sa, vx, vy, w), (gx, gy, pitch, hvx, hvy, hw), (lat_y, lat_v, hand_lat, anchor), hl,
                    teeth, loads, slopes, c)
                if jaw:
                    fx, fy, torque = fx + jfx, fy + jfy, torque + jtq
                if P != 0.0 or jaw:                         # off the tongue and the jaw Chipmunk's reset force of 0 stands
                    set_force(blade, (fx, fy))
                    set_torque(blade, torque)
                if written != (hvx, hvy, hw):
                    written = (hvx, hvy, hw)
                    _lib.cpBodySetVelocity(hand, (hvx, hvy))
                    _lib.cpBodySetAngularVelocity(hand, hw)
                self._teeth = NO_TEETH                      # unless the incisors' callback sets it
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
        return list(contact_features(cx, cy, self._lateral[3], P, Q, self.c.R, ScalarOps))

    def observation(self) -> list[float]:
        """The device part of the observation (15 values in (-1, 1); names in
        :data:`softenv.devices.laryngoscope.LARYNGOSCOPE_OBS`)."""
        return [squash(x) for x in self._observation_values()]

    def incisor_clearance(self) -> float:
        """Distance (m) between the incisors and the blade; negative: they overlap by that much."""
        incisor, blade = self._space.incisors[0], next(iter(self._blade.shapes))
        try:
            touching = blade.shapes_collide(incisor).points
        except AssertionError:                 # pymunk 7 asserts instead of returning no points
            touching = ()
        if touching:
            return min(point.distance for point in touching)
        a, b = np.array(incisor.a), np.array(incisor.b)
        corners = [np.array(self._blade.local_to_world(v)) for v in blade.get_vertices()]
        ends = min(blade.point_query(tuple(a)).distance, blade.point_query(tuple(b)).distance)
        t = [float(np.clip(np.dot(v - a, b - a) / np.dot(b - a, b - a), 0.0, 1.0)) for v in corners]
        sides = min(float(np.linalg.norm(v - (a + u * (b - a)))) for v, u in zip(corners, t))
        return min(ends, sides) - incisor.radius

    def penetration(self) -> float:
        """How deep (m) the blade's underside reaches into the undeformed tongue (negative: clear of it)."""
        x, y, a = self.kinematics()[:3]
        return self.c.R - nearest_point(x, y, math.cos(a), math.sin(a), self.c, ScalarOps)[2]

    @property
    def hand_pose(self) -> tuple[float, float, float, float]:
        """The hand: grip x, z (m), pitch (rad), lateral y (m)."""
        return (*self._hand_pose, self._lateral[2])

    def _read_kinematics(self) -> tuple[float, ...]:
        b = self._cblade
        p, v = _lib.cpBodyGetPosition(b), _lib.cpBodyGetVelocity(b)
        return (p.x, p.y, _lib.cpBodyGetAngle(b), v.x, v.y, _lib.cpBodyGetAngularVelocity(b), *self._hand_pose)

    def _lateral_state(self) -> tuple[float, ...]:
        return self._lateral

    def _hand_v_state(self) -> tuple[float, ...]:
        return self._hand_v

    def _contact_state(self) -> tuple[float, ...]:
        return self._contact

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

