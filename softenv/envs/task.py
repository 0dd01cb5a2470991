"""The task an environment poses besides its device (``softenv.devices``): targets, dynamics, reward.

Each part works on arrays with any leading batch shape, so the single environment (state of shape
``(k,)``) and its batched twin (``(N, k)``) call the same code. Float versions exist only where the
single environment would otherwise pay numpy's per-call overhead on four numbers; they perform the
same IEEE operations in the same order, so both environments agree bit for bit.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._ops import ArrayOps, Ops
from ..sections import RewardSection


class Dynamics:
    """Shape parameters relax toward the equilibrium ``g`` of the applied force.

    ``quasi_static``: ``b = g``. ``viscoelastic``: a standard linear solid in b-space,
    ``z <- z + (g - z)(1 - exp(-dt / tau))``, ``b = r g + (1 - r) z``: exact for a force held over
    the step, stable for every ``dt / tau`` (the factor lies in (0, 1]), and ``tau = 0`` gives the
    instant response with no division. ``1 - exp(-x)`` is computed as ``-expm1(-x)`` so tiny
    ``dt / tau`` keep their precision.
    """

    def __init__(self, kind: str, dt: float, relaxed_fraction: float, time_constant: float) -> None:
        self.kind = kind
        self.dt = dt
        self.r = relaxed_fraction
        self.one_minus_r = 1.0 - relaxed_fraction
        self.move = 1.0 if time_constant == 0.0 else -math.expm1(-dt / time_constant)

    @property
    def stateful(self) -> bool:
        return self.kind == "viscoelastic"

    def step(self, z: Any, g: Any) -> Any:
        """Advance the creep state ``z`` (a numpy array or torch tensor) in place toward ``g``; return the
        new shape ``b``."""
        if self.kind == "quasi_static":
            return g
        z += (g - z) * self.move
        return self.r * g + self.one_minus_r * z


class TargetFamily:
    """Laryngoscopy-like target forces: a box in force-feature space, split into train and test cells.

    The box is divided into ``cells`` equal parts per axis; a cell belongs to the test set when the
    sum of its indices is odd (a checkerboard), so train and test targets never share a cell and
    both cover the whole family. A target force is drawn by picking a cell of the split uniformly,
    then a point uniformly inside it.
    """

    def __init__(self, low: np.ndarray, high: np.ndarray, split: str, cells: int = 3) -> None:
        self.low, self.high = np.asarray(low, dtype=float), np.asarray(high, dtype=float)
        grid = np.stack(np.meshgrid(*[np.arange(cells)] * self.low.size, indexing="ij"), axis=-1).reshape(-1, self.low.size)
        parity = grid.sum(axis=1) % 2
        self.cells = grid[parity == (1 if split == "test" else 0)]
        self.n_cells = cells
        self.split = split

    @property
    def centre(self) -> np.ndarray:
        """The family's central force (trainee scoring's target)."""
        return (self.low + self.high) / 2

    def sample_many(self, rngs: list[np.random.Generator]) -> np.ndarray:
        """One target per generator, ``(len(rngs), d)``: each generator draws its cell, then its point."""
        draws = [(rng.integers(len(self.cells)), rng.random(self.low.size)) for rng in rngs]
        cell = self.cells[[i for i, _ in draws]]
        unit = (cell + np.array([u for _, u in draws]).reshape(len(rngs), self.low.size)) / self.n_cells
        return self.low + unit * (self.high - self.low)

    def cell_of(self, features: np.ndarray) -> np.ndarray:
        """Cell indices of force features (for checking the split)."""
        unit = (np.asarray(features) - self.low) / (self.high - self.low)
        return np.minimum((unit * self.n_cells).astype(int), self.n_cells - 1)


def procedure_schedule(targets: np.ndarray, start_insertion: float, horizon: int) -> np.ndarray:
    """The procedure task's target force features at every step, ``(n, horizon, 4)`` for targets
    ``(n, 4)``: the laryngoscopy sequence in three equal phases -- *insert* (the blade slides from the
    front of the range to the target depth with a light touch of 10 % of the target's pressing force),
    *press* (the pressing force rises to the target's), *sweep* (the sideways force rises to the
    target's); see :func:`procedure_features`. (A reach task holds its target throughout.)
    """
    t = (np.arange(horizon) + 1) / horizon
    return procedure_features(targets[:, None, :], t, start_insertion, ArrayOps)


def procedure_features(target: Any, t: Any, start_insertion: float, ops: Ops) -> Any:
    """The procedure's target features at episode fraction ``t = (step + 1) / horizon``: targets
    ``(..., 4)``, fractions ``(...)`` (numpy arrays with :class:`~softenv._ops.ArrayOps`, tensors with
    the torch twin's ops: the same operations, so the same values)."""
    insert, press, sweep = (ops.clip(3.0 * t - j, 0.0, 1.0) for j in range(3))    # progress in each phase
    return ops.stack([start_insertion + (target[..., 0] - start_insertion) * insert, target[..., 1] * insert,
                      target[..., 2] * (0.1 + 0.9 * press), target[..., 3] * sweep])


def action_change(a: Any, prev: Any) -> Any:
    """``||a - prev||^2`` from the actions' components, one item each (a row's floats, or a batch's columns:
    ``a.T``), summed in order: the same bits on floats, arrays and tensors."""
    terms = [(x - y) * (x - y) for x, y in zip(a, prev)]
    total = terms[0]
    for term in terms[1:]:
        total = total + term
    return total


def normalized_score(zero_cum: Any, oracle_cum: Any, agent_cum: Any, ops: Ops) -> Any:
    """The normalised score of the episode so far from the cumulative shape-error ratios of the
    zero-force policy, the oracle and the agent: 0 for the zero-force policy, 100 for the oracle."""
    return 100.0 * (zero_cum - agent_cum) / ops.clip(zero_cum - oracle_cum, 1e-12, math.inf)


def reward_terms(sq_dist: Any, sq_ref: Any, normal: Any, sideways: Any, sq_action_change: Any,
                 weights: RewardSection, ops: Ops) -> tuple[Any, Any, Any, Any, Any, Any]:
    """Reward and its terms from squared b-space distances (scalars or arrays alike).

    Returns ``(reward, shape_term, force_term, smooth_term, error_ratio, force)``:
    ``error_ratio = ||b - b*|| / max(||b* - b_rest||, floor)`` -- the RMS surface error over the
    target's RMS displacement from rest; ``force = sqrt(normal^2 + sideways^2)``.
    """
    ratio = ops.sqrt(sq_dist / sq_ref)
    force = ops.sqrt(normal * normal + sideways * sideways)
    shape_term = -weights["shape_weight"] * ratio
    force_term = -weights["force_weight"] * (ops.positive(force - weights["safe_force"]) / weights["safe_force"])
    smooth_term = -weights["smoothness_weight"] * (sq_action_change / 4.0)
    return shape_term + force_term + smooth_term, shape_term, force_term, smooth_term, ratio, force
