"""What every batched SoftSphere env shares, numpy and torch alike, and the single env's action check:
action checks, seeding and reset options, the autoreset mode, and infos built as
:class:`gymnasium.vector.SyncVectorEnv` builds them (dicts of arrays with ``_key`` masks)."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode

from .._validation import check_int, real_array
from .world import World



def check_action_one(action: Any) -> list[float]:
    a = real_array(action, "action", (4,))
    values = a.tolist() if a.dtype.kind == "f" else [float(x) for x in a.tolist()]
    for i, x in enumerate(values):
        if not -1.0 <= x <= 1.0:          # also rejects NaN
            raise ValueError(f"action[{i}] = {x!r}: actions must be finite and within [-1, 1]")
    return values


def check_actions(actions: Any, n: int) -> np.ndarray:
    a = real_array(actions, "actions", (n, 4)).astype(np.float64, copy=False)
    bad = ~((a >= -1.0) & (a <= 1.0))
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise ValueError(f"actions[{i}, {j}] = {float(a[i, j])!r}: actions must be finite and within [-1, 1]")
    return a


def episode_limit(max_episode_steps: Any, horizon: int) -> int:
    """Steps before a batched env truncates: the scene's ``task.horizon``, or fewer where
    ``max_episode_steps`` asks (an outer time limit, as ``gym.make(..., max_episode_steps=m)`` wraps the
    single env in ``TimeLimit(m)``: the task, its schedule and its score keep the horizon)."""
    if max_episode_steps is None:
        return horizon
    return min(horizon, check_int(max_episode_steps, "max_episode_steps", 1))


def autoreset_mode(value: str | AutoresetMode) -> AutoresetMode:
    names = {"next_step": AutoresetMode.NEXT_STEP, "same_step": AutoresetMode.SAME_STEP,
             AutoresetMode.NEXT_STEP.value: AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP.value: AutoresetMode.SAME_STEP}
    mode = value if isinstance(value, AutoresetMode) else names.get(value)
    if mode not in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP):
        raise ValueError(f"autoreset_mode={value!r} is not supported; use 'next_step' or 'same_step' "
                         "(or gymnasium.vector.AutoresetMode.NEXT_STEP / SAME_STEP)")
    return mode


def seeded_episodes(world: World, rngs: list[np.random.Generator], seed: int | list[int | None] | None,
                    options: dict[str, Any] | None) -> tuple[list[np.random.Generator], Any]:
    """A batched reset's generators and episodes: ``seed=s`` seeds env ``i`` with ``s + i``, a list seeds
    each env, ``None`` continues each env's generator (as SyncVectorEnv's reset does). Everything is
    checked before a generator changes."""
    n = len(rngs)
    if seed is None:
        seeds: list[int | None] = [None] * n
    elif isinstance(seed, (int, np.integer)):
        seeds = [int(seed) + i for i in range(n)]
    else:
        seeds = list(seed)
        if len(seeds) != n:
            raise ValueError(f"seed has {len(seeds)} entries; num_envs={n}")
    fresh = [rng if s is None else gym.utils.seeding.np_random(s)[0] for rng, s in zip(rngs, seeds)]
    target = target_option(world, options)
    return fresh, world.start_episodes(fresh, [target] * n)


def target_option(world: World, options: dict[str, Any] | None) -> np.ndarray | None:
    if not options:
        return None
    unknown = set(options) - {"target"}
    if unknown:
        raise ValueError(f"unknown reset options {sorted(unknown)}; valid: ['target'] (target force in action units)")
    return world.target_from_action(options["target"])


def add_masked(infos: dict[str, Any], values: dict[str, np.ndarray], mask: np.ndarray) -> None:
    """Vector-env infos as SyncVectorEnv builds them: zeros where the mask is off, plus ``_key``."""
    if not mask.any():
        return
    everyone = mask.all()
    for key, value in values.items():
        if value.dtype == object:        # per-env nested infos (a dict, None where absent), nested as SyncVectorEnv does
            present = mask & np.array([v is not None for v in value])
            if present.any():
                infos[key], infos[f"_{key}"] = _nested(value, present), present
            continue
        if everyone:
            infos[key] = value.copy()
        else:
            rows = mask.reshape(mask.shape + (1,) * (value.ndim - 1))       # per-env vectors: mask each row
            infos[key] = np.where(rows, value, np.zeros((), dtype=value.dtype))
        infos[f"_{key}"] = mask.copy()


def _nested(value: np.ndarray, present: np.ndarray) -> dict[str, np.ndarray]:
    """The dicts of the ``present`` envs as one dict of per-env arrays (zeros elsewhere) with ``_key`` masks."""
    rows = np.flatnonzero(present)
    out: dict[str, np.ndarray] = {}
    for key, first in value[rows[0]].items():
        column = np.zeros(len(value), dtype=type(first))
        column[rows] = [value[i][key] for i in rows]
        out[key], out[f"_{key}"] = column, present.copy()
    return out


def obs_row(obs: Any, i: int) -> Any:
    if isinstance(obs, dict):
        return {key: value[i].copy() for key, value in obs.items()}
    return obs[i].copy()
