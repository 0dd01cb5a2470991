"""A thin stable-baselines3 ``VecEnv`` over the natively batched SoftSphere env.

SB3 resets finished envs in the same step and expects ``infos`` as a list of dicts with
``terminal_observation`` and ``TimeLimit.truncated``; this adapter runs the batched twin in
``same_step`` autoreset mode and builds those dicts straight from the twin's info arrays
(:meth:`SoftSphereVectorEnv.step_values`), column by column. By default each dict carries what SB3 reads
(``is_success``): 1.1-1.2x the twin's own step at 256-1,024 envs; with ``info_keys="all"`` (every key
of the env's info) 1.4-1.7x (``softenv bench --only sb3``). Wrap it in SB3's ``VecMonitor`` for
episode statistics. Importing this module imports stable-baselines3 (and torch).
"""

from __future__ import annotations

import functools
from typing import Any, Callable, Literal, Sequence

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices, VecEnvStepReturn

from .vector import SoftSphereVectorEnv

SB3_INFO_KEYS = ("is_success",)          # the info keys SB3's own code reads (its logger's success rate)


class SoftSphereSB3VecEnv(VecEnv):
    """``SoftSphereSB3VecEnv(num_envs, env_id="SoftSphere-v0", info_keys=SB3_INFO_KEYS, **scene)``: SB3's
    view of the batched twin (of any SoftSphere id, the haptic ones included).

    ``info_keys``: the info keys each env's dict carries besides the ``terminal_observation`` and
    ``TimeLimit.truncated`` of an ended episode. The default, :data:`SB3_INFO_KEYS`, is what SB3's own
    code reads (``is_success``, for the success rate of its logger and ``EvalCallback``). ``"all"``
    carries every key of the env's info (reward terms, ``normalized_score``, ...), as the single env's
    info has them, for callbacks that log them: building one dict per env per step is most of this
    adapter's cost, and a dict of every key costs as much again as the twin's step (see the module
    docstring), so it is asked for, not the default."""

    def __init__(self, num_envs: int = 8, env_id: str = "SoftSphere-v0",
                 info_keys: Sequence[str] | Literal["all"] = SB3_INFO_KEYS, **kwargs: Any) -> None:
        if isinstance(info_keys, str) and info_keys != "all":
            raise ValueError(f"info_keys={info_keys!r} must be 'all' or a sequence of info keys")
        spec = gym.spec(env_id)
        entry = spec.vector_entry_point
        if not isinstance(entry, str) or not entry.startswith("softenv.envs."):
            raise ValueError(f"env_id={env_id!r} is not a SoftSphere id")
        self.venv = SoftSphereVectorEnv(num_envs, autoreset_mode="same_step",
                                        **{**spec.kwargs, **kwargs})
        self.env_id = env_id
        self.info_keys: tuple[str, ...] | None = None if info_keys == "all" else tuple(info_keys)
        super().__init__(num_envs, self.venv.single_observation_space, self.venv.single_action_space)
        self.render_mode = self.venv.render_mode
        self._actions: np.ndarray | None = None

    def reset(self) -> Any:
        seeds = self._seeds if any(s is not None for s in self._seeds) else None
        options = self._options[0] if self._options and self._options[0] else None
        obs, _ = self.venv.reset(seed=seeds, options=options)
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self) -> VecEnvStepReturn:
        obs, rewards, terminated, truncated, values, final_obs = self.venv.step_values(self._actions)
        dones = terminated | truncated
        if self.info_keys is not None:
            sometimes = self.venv.device.episode_info_keys       # absent on steps where no episode ends
            missing = [key for key in self.info_keys if key not in values and key not in sometimes]
            if missing:
                raise ValueError(f"info_keys {missing} are not info keys of {self.env_id}; available: "
                                 f"{[*values, *(key for key in sometimes if key not in values)]}")
            values = {key: values[key] for key in self.info_keys if key in values}
        infos = _dict_builder(tuple(values))([_column(v) for v in values.values()])
        if final_obs is not None:
            for i in np.flatnonzero(dones).tolist():
                infos[i]["terminal_observation"] = final_obs[i]
                infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
        return obs, rewards.astype(np.float32), dones, infos

    def close(self) -> None:
        self.venv.close()

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        return [getattr(self.venv, attr_name)] * len(self._indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **method_kwargs: Any) -> list[Any]:
        result = getattr(self.venv, method_name)(*method_args, **method_kwargs)
        return [result] * len(self._indices(indices))

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        return [False] * len(self._indices(indices))

    def get_images(self) -> Sequence[np.ndarray | None]:
        frames = self.venv.render()
        return list(frames) if frames is not None else [None] * self.num_envs

    def _indices(self, indices: VecEnvIndices) -> Sequence[int]:
        if indices is None:
            return range(self.num_envs)
        return [indices] if isinstance(indices, int) else list(indices)


def _column(value: np.ndarray) -> list[Any]:
    """One info key's values as a list of Python objects; a constant column (a term whose weight is 0)
    repeats one object instead of making one per env."""
    if value.ndim > 1:
        return list(value)
    if value.dtype == object:                      # nested per-env infos ("clinical": a dict, None where absent)
        return value.tolist()
    bits = value.view(f"u{value.itemsize}")       # bit patterns: -0.0 is not 0.0 here, NaN equals itself
    if len(bits) and (bits == bits[0]).all():
        return value[:1].tolist() * len(value)
    return value.tolist()


@functools.lru_cache(maxsize=16)
def _dict_builder(keys: tuple[str, ...]) -> Callable[[list[list[Any]]], list[dict[str, Any]]]:
    """``columns -> [{keys[0]: columns[0][i], ...} for each env i]``, compiled once per key set (as
    ``collections.namedtuple`` compiles its class): a dict display with constant keys builds in half
    the time of ``dict(zip(keys, row))``, and these dicts are most of the adapter's cost (SB3 wants
    one per env per step)."""
    names = [f"v{i}" for i in range(len(keys))]
    display = ", ".join(f"{key!r}: {name}" for key, name in zip(keys, names))
    return eval(f"lambda columns: [{{{display}}} for {', '.join(names)}, in zip(*columns)]")
