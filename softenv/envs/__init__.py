"""The Gymnasium environments: scene config, scene building, the task, the single env and its batched
twin (one class each for every device: ``softenv.devices``), the torch twin, rendering and the SB3
adapter. Registration (``register_envs``) uses string entry points, so
``import softenv`` stays light; the env modules load when an env is made.

Every id is registered with its scene overrides as the ``base_scene`` keyword; the sections a user
passes to ``gym.make`` are merged into it key by key (so ``gym.make("SoftSphereHaptic-v0",
device={"coupling_stiffness": 1e4})`` keeps the laryngoscope)."""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from .config import default_config, describe_config, make_config
from .wrappers import NumpyInfo

# ideal-device ids -> scene overrides; each steps 100 times per episode (task.horizon's default)
ENV_SCENES: dict[str, dict[str, Any]] = {
    "SoftSphere-v0": {},
    "SoftSphereViscoelastic-v0": {"dynamics": {"kind": "viscoelastic"}},
    "SoftSphereProcedure-v0": {"task": {"kind": "procedure"}},
}

# laryngoscope ids: 50 Hz control (20 substeps of 1 ms), 5 s to reach, 10 s for the procedure
_HAPTIC = {"device": {"kind": "laryngoscope"}, "dynamics": {"dt": 0.02}}
HAPTIC_SCENES: dict[str, dict[str, Any]] = {
    "SoftSphereHaptic-v0": {**_HAPTIC, "task": {"horizon": 250}},
    "SoftSphereHapticProcedure-v0": {**_HAPTIC, "task": {"kind": "procedure", "horizon": 500}},
}
# graded airways (softenv.airway; pass airway={"grade": g}): one device range for every grade, so that agents
# trained on one grade are evaluated on another in the same spaces. 60 N: the hardest grade's targets need up
# to 57.5 N (Bucx et al. 1995, manikin: the groups' peak tongue forces 60.5-74.2 N); 15 N: its 11.5 N sideways
AIRWAY_DEVICE = {"max_normal_force": 60.0, "max_sideways_force": 15.0}
HAPTIC_SCENES["SoftSphereAirway-v0"] = {**_HAPTIC, "device": {"kind": "laryngoscope", **AIRWAY_DEVICE},
                                        "task": {"horizon": 250}}


def airway_scene(grade: int) -> dict[str, Any]:
    """SoftSphereAirway-v0 at ``grade``, as sections over SoftSphereHaptic-v0's scene (what a hand log records)."""
    return {"device": dict(AIRWAY_DEVICE), "airway": {"grade": grade}}


def register_envs() -> None:
    """Register every SoftSphere id with Gymnasium (safe to call again)."""
    for env_id, scene in {**ENV_SCENES, **HAPTIC_SCENES}.items():
        if env_id in gym.registry:
            continue
        # no max_episode_steps: the episode length is the scene's task.horizon and the env truncates
        # there itself, so a horizon passed to gym.make, gym.make_vec (any mode) or the torch backend
        # is honoured alike (a registered limit would cap a longer horizon and override a vector env's)
        gym.register(id=env_id, entry_point="softenv.envs.single:SoftSphereEnv",
                     vector_entry_point="softenv.envs.make:make_vector_env", kwargs={"base_scene": scene})


__all__ = ["AIRWAY_DEVICE", "ENV_SCENES", "NumpyInfo", "HAPTIC_SCENES", "airway_scene", "default_config", "describe_config", "make_config",
           "register_envs"]
