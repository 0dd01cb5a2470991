"""Hand control of the simulated laryngoscope: realise a force on the tongue through the coupling.

The paper learns the haptic link force -> shape ``b``. Used in reverse, a target shape ``b*`` gives
the force that should reach it (invert a force -> b model, or fit b -> force directly); on the
SoftSphereHaptic scenes nobody commands that force: a hand moves the handle, and the force arises
in the tongue through the blade. :class:`HandController` closes that loop from the observation, the
way the textbook procedure is taught:

1. **Insert** (blade clear of the tongue): bring the blade's pitch to the one whose underside touches
   the tongue at the target's insertion angle (the underside's point nearest the tongue's centre
   lies at ``90 deg + pitch`` from the front), move the hand sideways to the target's lateral offset,
   and slide the blade ``insert_depth`` in along itself toward the vallecula. Tipping the blade up
   turns its flange up into the incisors (it turns about the grip), so the blade tips up only once
   it rests on the tongue; should the teeth still be touched, the controller stops tipping up and
   lifts until they are clear.
2. **Lift** along the handle (the handle stands at 90 degrees on the blade, so the press action
   moves the hand along it, into the tongue), with the wrist held (no pitch torque is added to
   level the blade: levering on the incisors is what the procedure avoids), until the tongue's
   normal force is the target's.
3. **Sweep** right (+y) once the lift holds ``sweep_share`` of its force, until the tongue's
   sideways force is the target's.

Every phase is a proportional law on what the observation shows (hand pose, blade pitch, tongue
forces), so the controller keeps no memory: it serves one env or a batch, and any autoreset.
Forces rise in the coupling as ``k (hand motion)``: the press gain ``k_p`` keeps
``k_p * max_hand_speed * dt * coupling_stiffness`` below one, so the loop does not overshoot.
"""

from __future__ import annotations

import math

import numpy as np

from . import ANGLE_SCALE, LATERAL_SCALE, POSITION_SCALE
from ...sections import SceneConfig

# the device slice of the observation (softenv.devices.laryngoscope.LARYNGOSCOPE_OBS)
_BLADE_PITCH, _HAND_X, _HAND_PITCH, _HAND_Y, _NORMAL, _SIDEWAYS, _INCISOR = 2, 8, 10, 11, 12, 13, 14
HAND_POSE = slice(_HAND_X, _HAND_Y + 1)      # the hand's x, z, pitch, y in the device slice


def unsquash(s: np.ndarray) -> np.ndarray:
    """Invert the observation's ``x / (1 + |x|)``."""
    s = np.asarray(s, dtype=np.float64)
    return s / (1.0 - np.abs(s))


class HandController:
    """Stateless force-tracking hand controller for a SoftSphereHaptic scene (see the module docstring).

    Args:
        config: the scene's validated config (``World.config``).
        insert_depth: how far (m) the hand slides the blade in along itself before lifting.
        k_p: normal-force gain (action units per newton).
        k_q: sideways-force gain (action units per newton).
        settle: share of each pose error closed per control step (pitch, lateral, insertion).
        sweep_share: the lift's share of its target force at which the sweep starts.
    """

    def __init__(self, config: SceneConfig, insert_depth: float = 0.01, k_p: float = 0.02, k_q: float = 0.05,
                 settle: float = 0.5, sweep_share: float = 0.9) -> None:
        dev = config["device"]
        self.radius = config["tissue"]["radius"]
        self.dt = config["dynamics"]["dt"]
        self.max_normal = dev["max_normal_force"]
        self.max_sideways = dev["max_sideways_force"]
        self.speed, self.sweep_speed, self.pitch_rate = dev["max_hand_speed"], dev["max_sweep_speed"], dev["max_pitch_rate"]
        self.insert_depth, self.k_p, self.k_q, self.settle, self.sweep_share = insert_depth, k_p, k_q, settle, sweep_share

    def act(self, device_obs: np.ndarray, target: np.ndarray) -> np.ndarray:
        """Actions ``(n, 4)`` for device observations ``(n, 15)`` and target force features ``(n, 4)``
        (insertion and lateral arc in m, normal and sideways force in N)."""
        d = unsquash(device_obs)
        target = np.asarray(target, dtype=np.float64)
        blade_pitch = d[:, _BLADE_PITCH] * ANGLE_SCALE
        hand_x, hand_y = d[:, _HAND_X] * POSITION_SCALE, d[:, _HAND_Y] * LATERAL_SCALE
        P, Q, incisor = d[:, _NORMAL] * self.max_normal, d[:, _SIDEWAYS] * self.max_sideways, d[:, _INCISOR]
        pitch_goal = target[:, 0] / self.radius - math.pi / 2
        lateral_goal = self.radius * np.sin(np.clip(target[:, 1] / self.radius, -math.pi / 2, math.pi / 2))
        touching = P > 0.0
        a = np.zeros((len(d), 4))
        step = self.settle / self.dt
        # 1. insert: pitch (always held at the goal), lateral offset and depth while clear of the tongue
        # tipping the blade up (about the grip) raises its flange toward the incisors: clear of the
        # tongue it tips up no further than level; once it rests on the tongue, the press gives room
        pitch_goal = np.where(touching, pitch_goal, np.maximum(pitch_goal, 0.0))
        a[:, 3] = (pitch_goal - blade_pitch) * step / self.pitch_rate
        a[:, 2] = np.where(touching, 0.0, (lateral_goal - hand_y) * step / self.sweep_speed)
        a[:, 0] = np.where(touching, 0.0, (hand_x + self.insert_depth) * step / self.speed)
        ready = touching | ((np.abs(pitch_goal - blade_pitch) < 0.01) & (np.abs(lateral_goal - hand_y) < 5e-4))
        # 2. lift along the handle to the target's normal force
        a[:, 1] = np.where(ready, self.k_p * (target[:, 2] - P), 0.0)
        # 3. sweep to the target's sideways force once the lift holds
        sweeping = touching & (P >= self.sweep_share * target[:, 2])
        a[:, 2] = np.where(sweeping, self.k_q * (target[:, 3] - Q), a[:, 2])
        # the teeth touched: stop tipping up, and lift until they are clear
        a[:, 3] = np.where(incisor > 0.0, np.maximum(a[:, 3], 0.0), a[:, 3])
        a[:, 1] = np.where(incisor > 0.0, np.maximum(a[:, 1], 0.3), a[:, 1])
        return np.clip(a, -1.0, 1.0)
