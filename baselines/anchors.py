"""The normalized score's anchors on a scene's test targets: no force (0) and the oracle (100), the
summed shape errors every benchmark report (``softenv compare``, ``baselines.ppo_torch``) scales by."""

from __future__ import annotations

from typing import Any

import numpy as np

from softenv.envs.config import make_config
from softenv.envs.world import World

from .evaluate import Episodes, evaluate, scene_kwargs
from .planner import TrajectoryOracle
from .policies import PlanningOracle, ZeroPolicy, make_baseline


def anchor_job(scene: str, episodes: int, oracle_settings: dict[str, Any]
               ) -> tuple[np.ndarray, np.ndarray, Episodes | None]:
    """The normalized score's anchors on the scene's test targets: the summed shape error of no force
    (0) and of the oracle (100). On the ideal device the oracle is :class:`PlanningOracle` (its row
    comes from its own baseline job); on the laryngoscope it is :class:`TrajectoryOracle`, which plans
    every episode through the device from the scripted expert's actions, and its episodes are
    returned too (the table's oracle row)."""
    _, kwargs = scene_kwargs(scene)
    kwargs.pop("obs_mode")
    world = World(make_config(**kwargs))
    zero = evaluate(ZeroPolicy(world), scene, episodes)
    if world.device_kind.name == "ideal":
        return zero.values["error_sum_mm"], evaluate(PlanningOracle(world), scene, episodes).values["error_sum_mm"], None
    planner = TrajectoryOracle(scene, **oracle_settings)
    planner.plan(make_baseline("expert", world), episodes)
    oracle = evaluate(planner, scene, episodes)
    return zero.values["error_sum_mm"], oracle.values["error_sum_mm"], oracle
