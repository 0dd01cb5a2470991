"""Shared by the laryngoscope engine tests: a blade levered on the incisors until the tongue's normal
force reaches a target, the case where the tongue contact's barrier must predict the teeth's push; and how
deep a blade presses the lower incisors, read from its state. The lever is ``scripts/incisor_reach.py``'s (loaded from the
script, so the tests step the law its results use)."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

from softenv.devices.laryngoscope.physics import jaw_contact
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


def jaw_depth(single: Laryngoscope) -> float:
    """The lower incisal edge's depth into the blade's underside (m; positive: pressing) at the end of the
    last control period (-inf without lower incisors)."""
    if single.c.jaw is None:
        return -math.inf
    x, y, a = single.kinematics()[:3]
    return jaw_contact(x, y, math.cos(a), math.sin(a), single.c)[0]
