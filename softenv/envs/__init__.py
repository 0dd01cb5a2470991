"""The Gymnasium environments: scene config, scene building, parts, the single env and its batched
twin, rendering and the SB3 adapter. Registration (``register_envs``) uses string entry points, so
``import softenv`` stays light; the env modules load when an env is made."""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from .config import default_config, describe_config, make_config

# id -> scene overrides; every id steps 100 times per episode (task.horizon's default)
ENV_SCENES: dict[str, dict[str, Any]] = {
    "SoftSphere-v0": {},
    "SoftSphereViscoelastic-v0": {"dynamics": {"kind": "viscoelastic"}},
    "SoftSphereProcedure-v0": {"task": {"kind": "procedure"}},
}
MAX_EPISODE_STEPS = 100


def register_envs() -> None:
    """Register every SoftSphere id with Gymnasium (safe to call again)."""
    for env_id, scene in ENV_SCENES.items():
        if env_id in gym.registry:
            continue
        gym.register(id=env_id, entry_point="softenv.envs.soft_sphere:SoftSphereEnv",
                     vector_entry_point="softenv.envs.soft_sphere:SoftSphereVectorEnv",
                     max_episode_steps=MAX_EPISODE_STEPS, kwargs=scene)


__all__ = ["ENV_SCENES", "MAX_EPISODE_STEPS", "default_config", "describe_config", "make_config", "register_envs"]
