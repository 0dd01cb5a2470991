"""What every batched SoftSphere env shares, numpy and torch alike: seeded episodes, reset masks, the
autoreset mode, and infos built as :class:`gymnasium.vector.SyncVectorEnv` builds them (dicts of arrays
with ``_key`` masks)."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode

from .._validation import check_int
from .checks import check_seeds, target_option
from .world import World



def episode_limit(max_episode_steps: Any, horizon: int) -> int:
    """Steps before a batched env truncates: the scene's ``task.horizon``, or fewer where
    ``max_episode_steps`` asks (an outer time limit, as ``gym.make(..., max_episode_steps=m)`` wraps the
    single env in ``TimeLimit(m)``: the task, its schedule and its score keep the horizon)."""
    if max_episode_steps is None:
        return horizon
    return min(horizon, check_int(max_episode_steps, "max_episode_steps", 1))


def autoreset_mode(value: str | AutoresetMode) -> AutoresetMode:
    names = {**{mode.value: mode for mode in AutoresetMode}, **{mode.name.lower(): mode for mode in AutoresetMode}}
    mode = value if isinstance(value, AutoresetMode) else names.get(value) if isinstance(value, str) else None
    if mode is None:
        raise ValueError(f"autoreset_mode={value!r} is not supported; use 'next_step', 'same_step' or 'disabled' "
                         "(or gymnasium.vector.AutoresetMode.NEXT_STEP / SAME_STEP / DISABLED)")
    return mode


def reset_mask_option(options: Any, n: int, mode: AutoresetMode) -> tuple[np.ndarray | None, Any]:
    """``options["reset_mask"]`` (as Gymnasium's vector envs take it): ``None`` when absent, else a bool
    array of ``num_envs`` entries with at least one True, returned with the other options. Only
    ``autoreset_mode="disabled"`` takes it, where it is how ended envs start again."""
    if not isinstance(options, dict) or "reset_mask" not in options:
        return None, options
    if mode != AutoresetMode.DISABLED:
        raise ValueError(f"options['reset_mask'] resets envs under autoreset_mode='disabled'; this env's is "
                         f"{mode.name.lower()!r}, which resets ended envs itself")
    mask = options["reset_mask"]
    if hasattr(mask, "detach"):                     # a torch tensor (the torch twin's users)
        mask = mask.detach().cpu().numpy()
    if not isinstance(mask, np.ndarray) or mask.dtype != np.bool_ or mask.shape != (n,):
        raise ValueError(f"options['reset_mask'] must be a bool array of shape ({n},) (num_envs); got "
                         f"{type(mask).__name__} {getattr(mask, 'dtype', '')} {getattr(mask, 'shape', '')}".rstrip())
    if not mask.any():
        raise ValueError("options['reset_mask'] has no True entry: it must name at least one env to reset")
    rest = {key: value for key, value in options.items() if key != "reset_mask"}
    return mask.copy(), rest or None


def disabled_step_check(ended: Any) -> None:
    """Under ``autoreset_mode="disabled"`` an env whose episode ended must be reset before it steps again."""
    rows = np.flatnonzero(np.asarray(ended))
    if rows.size:
        raise RuntimeError(f"env(s) {rows.tolist()} ended their episodes and autoreset_mode='disabled' does not reset "
                           "them: call reset(options={'reset_mask': mask}) for them before the next step")


def seeded_episodes(world: World, rngs: list[np.random.Generator], seed: int | list[int | None] | None,
                    options: dict[str, Any] | None, mask: np.ndarray | None = None
                    ) -> tuple[list[np.random.Generator], Any]:
    """A batched reset's generators and the episodes of the envs it resets (every env, or the ``mask``ed
    ones; seeds as :func:`check_seeds`, as SyncVectorEnv's reset does, a masked-out env's seed unused).
    Everything is checked before a generator changes."""
    seeds = check_seeds(seed, len(rngs))
    target = target_option(world, options)
    chosen = np.ones(len(rngs), dtype=bool) if mask is None else mask
    fresh = [rng if s is None or not c else gym.utils.seeding.np_random(s)[0] for rng, s, c in zip(rngs, seeds, chosen)]
    idx = np.flatnonzero(chosen)
    return fresh, world.start_episodes([fresh[i] for i in idx], [target] * len(idx))


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


def obs_copy(obs: Any) -> Any:
    return {key: value.copy() for key, value in obs.items()} if isinstance(obs, dict) else obs.copy()


def obs_row(obs: Any, i: int) -> Any:
    if isinstance(obs, dict):
        return {key: value[i].copy() for key, value in obs.items()}
    return obs[i].copy()
