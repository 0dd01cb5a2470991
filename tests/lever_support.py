"""Shared by the laryngoscope engine tests: a blade levered on the incisors until the tongue's normal
force reaches a target, the case where the tongue contact's barrier must predict the teeth's push; and the
jaw's push on a blade, read from its state. The lever is ``scripts/incisor_reach.py``'s (loaded from the
script, so the tests step the law its results use)."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

from softenv._ops import ScalarOps
from softenv.devices.laryngoscope.physics import jaw_contact, jaw_force
from softenv.devices.laryngoscope.single import Laryngoscope

_spec = importlib.util.spec_from_file_location("incisor_reach", Path(__file__).resolve().parent.parent / "scripts"
                                               / "incisor_reach.py")
assert _spec is not None and _spec.loader is not None
incisor_reach = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(incisor_reach)


def lever_actions(single: Laryngoscope, target: float, periods: int, held: int) -> list[list[float]]:
    """Turn the hand about the incisal edge, tip down, until the tongue's normal force is ``target`` (N),
    for ``periods`` control periods, then hold still for ``held``; ``single`` is stepped along."""
    actions = []
    for period in range(periods + held):
        actions.append(incisor_reach.lever_action(single, target) if period < periods else [0.0] * 4)
        single.control_step(actions[-1])
    return actions


def jaw_push(single: Laryngoscope) -> tuple[float, float]:
    """The lower incisal edge's depth into the blade's underside (m; positive: pressing) and the jaw's
    force on the blade (N) at the end of the last control period (0 without lower incisors)."""
    if single.c.jaw is None:
        return -math.inf, 0.0
    x, y, a, vx, vy, w = single.kinematics()[:6]
    blade = (x, y, a, math.cos(a), math.sin(a), vx, vy, w)
    fx, fy, _ = jaw_force(blade, single.c, ScalarOps)
    return jaw_contact(*blade[:2], *blade[3:5], single.c)[0], math.hypot(fx, fy)
