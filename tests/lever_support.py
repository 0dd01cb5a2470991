"""Shared by the laryngoscope engine tests: a blade levered on the incisors until the tongue's normal
force reaches a target, the case where the tongue contact's barrier must predict the teeth's push."""

from __future__ import annotations

import numpy as np

from softenv.devices.laryngoscope.params import INCISOR_RADIUS
from softenv.devices.laryngoscope.physics import hand_action
from softenv.devices.laryngoscope.single import Laryngoscope


def lever_actions(single: Laryngoscope, target: float, periods: int, held: int) -> list[list[float]]:
    """Turn the hand about the incisal edge, tip down, until the tongue's normal force is ``target`` (N),
    for ``periods`` control periods, then hold still for ``held``; ``single`` is stepped along."""
    p = single.params
    ix, iy = p.incisor
    actions = []
    for period in range(periods + held):
        gx, gy, pitch, _ = single.hand_pose
        spin = float(np.clip(0.025 * (target - single.normal_force), -p.max_pitch_rate, p.max_pitch_rate))
        rx, ry = gx - ix, gy - (iy - INCISOR_RADIUS)
        action = list(hand_action(-spin * ry, spin * rx, spin, 0.0, pitch, p)) if period < periods else [0.0] * 4
        actions.append(np.clip(action, -1.0, 1.0).tolist())
        single.control_step(actions[-1])
    return actions
