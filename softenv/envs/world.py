"""One scene's parts composed into the rules of an episode, shared by the single and batched envs.

:class:`World` holds the immutable :class:`~softenv.envs.scene.Scene` (tissue, shape model,
response), the device's kind, the dynamics, the target family, the reward weights and the observation
layout. Everything that happens at reset (sampling targets, their shapes, the zero-force and oracle
reference returns for the normalised score) runs here on arrays with a leading batch axis, so the
single env (a batch of one) and the batched twin share the code and agree bit for bit. Per-step work
lives in the envs themselves: the single env's scalar fast path and the batched twin's array path
perform the same IEEE operations in the same order.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces

from .._validation import real_array
from ..airway import target_ranges
from ..response import TabulatedResponse
from ..response.exact import TableWork
from ..devices.base import DeviceKind, device_kind
from ..devices.force_box import ForceBox
from .task import Dynamics, TargetFamily, procedure_schedule
from .scene import Scene, build_scene, degrees_to_features
from ..sections import SceneConfig

OBS_MODES = ("vector", "dict", "vertices")
# the shape-error floor: a target displacement below this share of the family centre's counts as it ...
REFERENCE_FLOOR = 0.1
# ... and never below this share of the device's design press (a family of vanishing forces keeps finite ratios)
DESIGN_FLOOR = 1e-6


@dataclass
class Episodes:
    """Per-episode arrays for ``n`` envs (leading axis), made at reset and read every step."""

    target_features: np.ndarray   # (n, T, 4) force features of the target at each step (T = 1 for reach)
    target_b: np.ndarray          # (n, T, k) target shape parameters
    sq_ref: np.ndarray            # (n, T) squared reference distance max(||b* - b_rest||, floor)^2
    zero_cum: np.ndarray          # (n, H) cumulative error ratio of the zero-force policy
    oracle_cum: np.ndarray        # (n, H) cumulative error ratio of the exact oracle


TASK_TERMS = ("reward_shape", "reward_force", "reward_smooth")   # the device's terms are its other reward_* keys


def other_reward_terms(info: dict[str, Any]) -> Any:
    """A step's reward without its shape term, from its ``info``: ``force + smooth + device``, where
    ``device`` sums the device's ``reward_*`` keys in the order it wrote them (as its ``report`` returns)."""
    device = [value for key, value in info.items() if key.startswith("reward_") and key not in TASK_TERMS]
    extra = device[0] if device else 0.0
    for value in device[1:]:
        extra = extra + value
    return info.get("reward_force", 0.0) + info.get("reward_smooth", 0.0) + extra


class World:
    """The composed environment rules for one validated scene config (see the module docstring)."""

    def __init__(self, config: SceneConfig, obs_mode: str = "vector") -> None:
        if obs_mode not in OBS_MODES:
            raise ValueError(f"obs_mode={obs_mode!r} is not one of {list(OBS_MODES)}")
        self.config = config
        self.obs_mode = obs_mode
        self.scene: Scene = build_scene(config)
        scene = self.scene
        self.force_box = ForceBox(scene.workspace)          # action units <-> force features (targets, ideal device)
        self.device_kind: DeviceKind = device_kind(config["device"]["kind"])
        self.device_obs_size = len(self.device_kind.obs_names)
        self.k = scene.n_components
        self.obs_size = 2 * self.k + self.device_obs_size + 4     # shapes, device state, previous action
        self._device_end = 2 * self.k + self.device_obs_size
        self.dynamics = Dynamics(**config["dynamics"])
        task = config["task"]
        ranges = list(target_ranges(task, config["airway"]).values())
        low, high = (degrees_to_features([r[i] for r in ranges], config["tissue"]["radius"]) for i in (0, 1))
        self.family = TargetFamily(low, high, task["split"])
        self.task_kind = task["kind"]
        self.horizon = task["horizon"]
        self.tolerance = task["tolerance"]
        self.terminate_on_success = task["terminate_on_success"]
        self.weights = config["reward"].copy()
        self.n_vertices = scene.mesh.n_vertices
        self.sqrt_variance = scene.sqrt_variance
        self.inv_sqrt = 1.0 / self.sqrt_variance
        self.b_rest = scene.response.predict_rowwise(scene.rest_features[None])[0]
        centre = scene.response.predict_rowwise(self.family.centre[None])[0]
        press = (scene.workspace.low + np.asarray(scene.workspace.high)) / 2
        press[2] = scene.workspace.high[2]                        # the largest pressing force, mid-workspace
        design = scene.response.predict_rowwise(press[None])[0]
        self.floor_sq = max(REFERENCE_FLOOR * float(np.sqrt(np.sum((centre - self.b_rest) ** 2))),
                            DESIGN_FLOOR * float(np.sqrt(np.sum((design - self.b_rest) ** 2)))) ** 2
        self.start_insertion = float(scene.workspace.low[0])
        self._table = scene.response if isinstance(scene.response, TabulatedResponse) else None
        self.action_space = spaces.Box(-1.0, 1.0, (4,), np.float32)
        self.observation_space = self._observation_space()

    # -- response -------------------------------------------------------------------------------

    def response(self, features: np.ndarray, work: TableWork | None = None) -> np.ndarray:
        """Equilibrium ``b`` of ``(n, 4)`` force features, each row independent of the others (``work``:
        a table's scratch arrays from :meth:`response_work`)."""
        if work is not None and self._table is not None:
            return self._table.lookup(features, work)
        return self.scene.response.predict_rowwise(features)

    def response_work(self, n: int) -> TableWork | None:
        """Reusable arrays for :meth:`response` on batches of ``n`` (``None`` unless the response is a table)."""
        return None if self._table is None else self._table.workspace(n)

    def response_one(self, features: list[float]) -> np.ndarray:
        """:meth:`response` of one force given as Python floats (bitwise equal to its row of a batch)."""
        if self._table is not None:
            return self._table.lookup_one(features)
        return self.scene.response.predict_rowwise(np.array([features]))[0]

    # -- observations ---------------------------------------------------------------------------


    def _observation_space(self) -> spaces.Space:
        b_low, b_high = self.scene.b_bounds
        margin = 1e-6 * (b_high - b_low) + 1e-12           # float rounding of convex combinations
        lo = (b_low - margin) * self.inv_sqrt
        hi = (b_high + margin) * self.inv_sqrt
        ones = np.ones(self.device_obs_size + 4)
        low = np.concatenate([lo, lo, -ones]).astype(np.float32)
        high = np.concatenate([hi, hi, ones]).astype(np.float32)
        if self.obs_mode == "dict":
            goal = spaces.Box(low[:self.k], high[:self.k], dtype=np.float32)
            return spaces.Dict({"observation": spaces.Box(-1.0, 1.0, (self.device_obs_size + 4,), np.float32),
                                "achieved_goal": goal, "desired_goal": goal})
        if self.obs_mode == "vertices":
            # vertices are linear in b, and b stays in its box: bound each coordinate over the box
            sm, R = self.scene.shape_model, self.scene.tissue.radius
            phi = sm.components_[:self.k]
            ends = np.stack([phi * b_low[:, None], phi * b_high[:, None]])
            v_low = (sm.mean_ + ends.min(axis=0).sum(axis=0)) / R
            v_high = (sm.mean_ + ends.max(axis=0).sum(axis=0)) / R
            pad = 1e-6 * (v_high - v_low) + 1e-9
            low = np.concatenate([low, (v_low - pad).astype(np.float32)])
            high = np.concatenate([high, (v_high + pad).astype(np.float32)])
        return spaces.Box(low, high, dtype=np.float32)

    def observe(self, b: np.ndarray, target_b: np.ndarray, device_state: Any, prev_action: Any) -> Any:
        """The observation of one env (``(k,)`` inputs) or a batch (``(n, k)``)."""
        k, d = self.k, self._device_end
        obs = np.empty(b.shape[:-1] + (self.obs_size,), np.float32)   # float64 values rounded on assignment
        if isinstance(device_state, list):                              # the single env's fast path
            obs[:k] = b * self.inv_sqrt
            obs[k:2 * k] = target_b * self.inv_sqrt
            obs[2 * k:] = device_state + prev_action
        else:       # a batch: the products go straight into their float32 slots (rounded as assigned)
            np.multiply(b, self.inv_sqrt, out=obs[..., :k], casting="same_kind")
            np.multiply(target_b, self.inv_sqrt, out=obs[..., k:2 * k], casting="same_kind")
            obs[..., 2 * k:d] = device_state
            obs[..., d:] = prev_action
        if self.obs_mode == "dict":
            return {"observation": obs[..., 2 * k:].copy(), "achieved_goal": obs[..., :k].copy(),
                    "desired_goal": obs[..., k:2 * k].copy()}
        if self.obs_mode == "vertices":
            return np.concatenate([obs, self.vertices(b).astype(np.float32)], axis=-1)
        return obs

    def vertices(self, b: np.ndarray) -> np.ndarray:
        """Surface points over the radius, flattened: ``(3 n,)`` or ``(N, 3 n)`` (row by row, so a
        batch equals its rows decoded alone)."""
        R = self.scene.tissue.radius
        if b.ndim == 1:
            return self.scene.shape_model.decode(b) / R
        return np.stack([self.scene.shape_model.decode(row) / R for row in b])

    def goal_shape_term(self, achieved_goal: np.ndarray, desired_goal: np.ndarray) -> Any:
        """The shape reward term from ``b / sqrt(lambda)`` goals (any leading axes)."""
        b = np.asarray(achieved_goal, dtype=np.float64) * self.sqrt_variance
        target = np.asarray(desired_goal, dtype=np.float64) * self.sqrt_variance
        d = b - target
        r = target - self.b_rest
        sq_ref = np.maximum(np.sum(r * r, axis=-1), self.floor_sq)
        return -self.weights["shape_weight"] * np.sqrt(np.sum(d * d, axis=-1) / sq_ref)

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> Any:
        """Reward from goals (dict observations; vectorised over leading axes, for HER): the step's reward
        with the shape term recomputed from the float32 goals (:meth:`goal_shape_term`) and every other
        term read from ``info`` (a dict, or an array or list of dicts, one per goal): ``reward_force``,
        ``reward_smooth`` and the device's ``reward_*`` keys (the laryngoscope's ``reward_incisor``),
        summed in the step's order, so that for the step's own goals it equals the step's reward bit
        for bit.
        """
        shape = self.goal_shape_term(achieved_goal, desired_goal)
        if isinstance(info, dict):
            return shape + other_reward_terms(info)
        extra = np.array([other_reward_terms(i) for i in np.ravel(info)])
        return shape + extra.reshape(np.shape(info))

    # -- episodes -------------------------------------------------------------------------------

    def start_episodes(self, rngs: list[np.random.Generator], targets: list[np.ndarray | None] | None = None) -> Episodes:
        """Draw one target per generator (or take the given force features) and precompute the episode."""
        n = len(rngs)
        given = targets or [None] * n
        drawn = [i for i, t in enumerate(given) if t is None]
        target = np.empty((n, 4))
        target[drawn] = self.family.sample_many([rngs[i] for i in drawn])
        for i, t in enumerate(given):
            if t is not None:
                target[i] = t
        if self.task_kind == "reach":
            features = target[:, None, :]
        else:
            features = procedure_schedule(target, self.start_insertion, self.horizon)
        T = features.shape[1]
        target_b = self.response(features.reshape(n * T, 4)).reshape(n, T, self.k)
        r = target_b - self.b_rest
        sq_rest = np.sum(r * r, axis=-1)                      # the zero-force policy's squared error: b stays at rest
        sq_ref = np.maximum(sq_rest, self.floor_sq)
        zero_ratio = np.sqrt(sq_rest / sq_ref)
        steps = np.minimum(np.arange(self.horizon), T - 1)
        # take, not zero_ratio[:, steps]: fancy indexing returns Fortran order, where cumsum runs 3x slower
        zero_cum = np.cumsum(zero_ratio.take(steps, axis=1), axis=1)
        if self.dynamics.stateful:
            oracle_cum = np.cumsum(self._oracle_ratio(target_b, sq_ref, steps), axis=1)
        else:
            oracle_cum = np.zeros((n, self.horizon))                 # the shape is the target at once
        return Episodes(features, target_b, sq_ref, zero_cum, oracle_cum)

    def _oracle_ratio(self, target_b: np.ndarray, sq_ref: np.ndarray, steps: np.ndarray) -> np.ndarray:
        """Error ratio at each step of the oracle (stateful dynamics), which holds the target force
        from the start."""
        n = target_b.shape[0]
        if target_b.shape[1] == 1:
            # constant target: b_t - g = (1 - r) (1 - move)^t (b_rest - g), in closed form
            decay = (1.0 - self.dynamics.move) ** (np.arange(self.horizon) + 1.0)
            r = target_b[:, 0] - self.b_rest
            start = np.sqrt(np.sum(r * r, axis=-1) / sq_ref[:, 0])
            return self.dynamics.one_minus_r * start[:, None] * decay[None, :]
        oracle = np.empty((n, self.horizon))
        z = np.repeat(self.b_rest[None], n, axis=0)
        for t in range(self.horizon):                               # moving target: simulate
            g = target_b[:, steps[t]]
            d = self.dynamics.step(z, g) - g
            oracle[:, t] = np.sqrt(np.sum(d * d, axis=-1) / sq_ref[:, steps[t]])
        return oracle

    def target_from_action(self, value: Any, name: str = "options['target']") -> np.ndarray:
        """Force features of a target given in action units (checked to lie in the target family)."""
        a = real_array(value, name, (4,)).astype(np.float64)
        if not np.isfinite(a).all():
            raise ValueError(f"{name} must be 4 finite numbers in action units [-1, 1], got {value!r}")
        f = self.force_box.features(a)
        tol = 1e-9 * (self.family.high - self.family.low + 1e-12)
        if ((f < self.family.low - tol) | (f > self.family.high + tol)).any():
            raise ValueError(f"{name}={a.tolist()} maps to force features {f.tolist()}, outside the target family "
                             f"[{self.family.low.tolist()}, {self.family.high.tolist()}]")
        return np.clip(f, self.family.low, self.family.high)

