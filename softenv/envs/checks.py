"""The checks at an env's boundary of what a user passes, single and batched envs alike: actions, seeds
and reset options, each refused with the argument, the value and what is allowed."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validation import real_array
from .world import World


def check_action_one(action: Any) -> list[float]:
    """The single env's action as 4 Python floats (any real dtype, cast to float64 at the boundary: a
    ``longdouble`` or integer action leaves no other type in the env's state or its reward)."""
    a = real_array(action, "action", (4,))
    values = a.tolist() if a.dtype.kind == "f" and a.dtype.itemsize <= 8 else a.astype(np.float64).tolist()
    for i, x in enumerate(values):
        if not -1.0 <= x <= 1.0:          # also rejects NaN
            raise ValueError(f"action[{i}] = {x!r}: actions must be finite and within [-1, 1]")
    return values


def check_actions(actions: Any, n: int) -> np.ndarray:
    """A batch's actions as a float64 ``(n, 4)`` array, each in [-1, 1]."""
    a = real_array(actions, "actions", (n, 4)).astype(np.float64, copy=False)
    bad = ~((a >= -1.0) & (a <= 1.0))
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise ValueError(f"actions[{i}, {j}] = {float(a[i, j])!r}: actions must be finite and within [-1, 1]")
    return a


SEED_RULE = "an int in [0, 2**64) or None"


def _one_seed(value: Any, name: str) -> int | None:
    if value is None:
        return None
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or not 0 <= value < 1 << 64:
        raise ValueError(f"{name}={value!r} must be {SEED_RULE}")
    return int(value)


def check_seed(seed: Any) -> int | None:
    """A single env's ``reset(seed=...)``, checked before anything changes."""
    return _one_seed(seed, "seed")


def check_seeds(seed: Any, n: int) -> list[int | None]:
    """A batched reset's seed per env: ``seed=s`` seeds env ``i`` with ``s + i``, a list or array seeds each
    env (``None`` entries continue their generator), ``None`` continues every env's generator."""
    if seed is None or isinstance(seed, (int, np.integer, bool, np.bool_)):
        first = _one_seed(seed, "seed")
        if first is not None and first + n > 1 << 64:
            raise ValueError(f"seed={seed!r}: env i is seeded seed + i, so seed must be below 2**64 - {n}")
        return [None if first is None else first + i for i in range(n)]
    if not isinstance(seed, (list, tuple, np.ndarray)):
        raise ValueError(f"seed={seed!r} must be {SEED_RULE}, or a list of {n} of them (one per env)")
    if len(seed) != n:
        raise ValueError(f"seed has {len(seed)} entries; num_envs={n} (one per env)")
    values = seed.tolist() if isinstance(seed, np.ndarray) else list(seed)
    return [_one_seed(s, f"seed[{i}]") for i, s in enumerate(values)]


def target_option(world: World, options: Any) -> np.ndarray | None:
    """``reset(options=...)``: ``None``, or a dict whose one key is ``"target"`` (force in action units)."""
    if options is None:
        return None
    if not isinstance(options, dict):
        raise ValueError(f"options={options!r} must be a dict or None; valid key: 'target' (target force in "
                         "action units)")
    if not options:
        return None
    unknown = set(options) - {"target"}
    if unknown:
        raise ValueError(f"unknown reset options {sorted(unknown)}; valid: ['target'] (target force in action units)")
    return world.target_from_action(options["target"])
