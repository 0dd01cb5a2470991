"""Small Gymnasium wrappers for clients with other conventions than Gymnasium's and SB3's."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np


class NumpyInfo(gym.Wrapper):
    """Info values as numpy arrays (0-d for scalars) instead of Python floats and bools.

    SoftSphere envs put Python scalars in ``info`` (cheap, JSON-ready, what SB3's Monitor and loggers
    take). TorchRL's ``default_info_dict_reader`` reads ``value.dtype``, so it needs numpy values::

        from torchrl.envs import GymWrapper, default_info_dict_reader
        env = GymWrapper(NumpyInfo(gym.make("softenv:SoftSphere-v0")))
        env.set_info_dict_reader(default_info_dict_reader(["is_success", "normalized_score"]))
    """

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        return obs, _as_numpy(info)

    def step(self, action: Any) -> tuple[Any, Any, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, reward, terminated, truncated, _as_numpy(info)


def _as_numpy(info: dict[str, Any]) -> dict[str, Any]:
    return {key: np.asarray(value) for key, value in info.items()}
