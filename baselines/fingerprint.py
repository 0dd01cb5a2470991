"""What a trained learner depends on beyond its settings: the dynamics it trained on and the libraries
that trained it. A run kept across sessions and code changes is reused only when both still match, so a
simulator change retrains it and a refactor that leaves every step's floats alone does not.

The dynamics' digest is SHA-256 of what a learner's vector envs return (observations, rewards, episode
ends, bit for bit) to seeded random actions from a seeded reset, on the training and the test targets,
over one episode and into the next (the autoreset). A change no random step reaches (a branch only a
policy's deliberate action takes) must bump the learner's format version instead.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from importlib.metadata import version
from typing import Any

import gymnasium as gym
import numpy as np

from softenv.envs.config import make_config

LIBRARIES = ("stable-baselines3", "torch", "gymnasium", "numpy")
PROBE_ENVS = 2                   # envs of a probe: two, so a batch's envs are seen to step apart
SPLITS = ("train", "test")


def library_versions(names: tuple[str, ...] = LIBRARIES) -> dict[str, str]:
    """The installed versions of ``names`` (distribution names)."""
    return {name: version(name) for name in names}


def probe_steps(scene_kwargs: dict[str, Any]) -> int:
    """Steps of a probe on a scene of these ``gym.make`` kwargs (its sections and ``obs_mode``): its
    horizon and ten into the next episode."""
    return int(make_config(**{k: v for k, v in scene_kwargs.items() if k != "obs_mode"})["task"]["horizon"]) + 10


def _host(part: Any) -> np.ndarray:
    """An array's bytes in host memory (torch tensors leave their device and graph)."""
    return np.ascontiguousarray(part.detach().cpu().numpy() if hasattr(part, "detach") else part)


def rollout_digest(make_env: Callable[[str], Any], steps: int) -> str:
    """SHA-256 of ``steps`` seeded random steps of ``make_env(split)`` on each split: a Gymnasium vector env
    (numpy or torch) or a stable-baselines3 ``VecEnv`` of :data:`PROBE_ENVS` envs and 4-vector actions."""
    digest = hashlib.sha256()
    rng = np.random.default_rng(0)
    for split in SPLITS:
        env = make_env(split)
        try:
            if isinstance(env, gym.vector.VectorEnv):
                obs, _ = env.reset(seed=0)

                def step(action: np.ndarray, env: Any = env) -> tuple[Any, Any, Any]:
                    obs, reward, terminated, truncated, _ = env.step(action)
                    return obs, reward, terminated | truncated
            else:                                           # stable-baselines3's VecEnv
                env.seed(0)
                obs = env.reset()

                def step(action: np.ndarray, env: Any = env) -> tuple[Any, Any, Any]:
                    return env.step(action)[:3]
            for _ in range(steps):
                for part in (obs[k] for k in sorted(obs)) if isinstance(obs, dict) else (obs,):
                    digest.update(_host(part).tobytes())
                obs, reward, done = step(rng.uniform(-1.0, 1.0, (PROBE_ENVS, 4)).astype(np.float32))
                digest.update(_host(reward).tobytes() + _host(done).tobytes())
        finally:
            env.close()
    return digest.hexdigest()
