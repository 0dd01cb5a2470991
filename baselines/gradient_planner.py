"""A gradient-based baseline: whole-episode trajectory optimisation by Adam through the differentiable
torch twin (``make_vec(..., backend="torch", differentiable=True)``; docs/gradients.md).

It plans what :class:`~.planner.TrajectoryOracle` plans, the same way: every episode of the evaluation
protocol is known from its seed and the simulator is deterministic, so an open-loop action sequence
optimised for an episode is its best behaviour. Where the oracle's cross-entropy search samples, this
planner follows the gradient of the same objective, the episode's summed shape error (the score's
``E``), taken through every step of the scene's own simulator (device, contact, response, creep):

* the plan is ``tanh(z)`` with ``z`` one free vector per step and action component, started at the
  warm start's actions (``atanh`` of them, held off the bounds by :data:`EDGE`), so every action stays
  in [-1, 1] and keeps a gradient;
* ``restarts`` plans per episode are optimised at once (one env of the torch twin each): the warm start
  itself, and ``restarts - 1`` warm starts moved by noise of spread ``sigma`` in ``z`` (each episode's
  noise drawn from a generator of its own, so a plan does not depend on the episodes beside it);
* each iteration rolls every plan out once with the graph recorded, back-propagates the summed error
  and takes one Adam step; each plan's best iterate is kept;
* at the end every restart's best plan is rolled out again on the numpy twin (the protocol's
  evaluation) beside the warm start, and the best of them is the plan: it is never worse than the warm
  start, and its error sum is the one evaluation measures.

Through contact the gradient is a subgradient (the branch each substep took, docs/gradients.md), so
where an episode's error hinges on making or breaking contact the planner may stall where the sampling
oracle does not; ``scripts/gradient_planner.py`` measures where.
"""

from __future__ import annotations

import time
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from softenv.envs.world import World

from .evaluate import evaluate, scene_kwargs
from .planner import ReplayPolicy, episode_list, warm_start_actions
from .policies import ZeroPolicy, make_baseline

EDGE = 0.999          # the warm start's actions held within +-EDGE before atanh (tanh reaches +-1 only at infinity)
STEP_SIZES = (0.03, 0.1, 0.3)      # Adam's step sizes tune_lr() tries
TRAIN = {"task": {"split": "train"}}


class GradientPlanner(ReplayPolicy):
    """Adam on each episode's action sequence through the differentiable torch twin (see the module
    docstring); after :meth:`plan` it replays its plans as a policy.

    Args:
        scene: the benchmark scene (:data:`~.evaluate.SCENES`) it plans on.
        restarts: plans optimised per episode (the first from the warm start itself).
        iterations: Adam steps.
        lr: Adam's step size, in ``z`` (the plan is ``tanh(z)``).
        sigma: the restarts' noise in ``z``.
        seed: the restarts' seed.
    """

    def __init__(self, scene: str, restarts: int = 4, iterations: int = 40, lr: float = 0.05, sigma: float = 0.5,
                 seed: int = 0) -> None:
        for name, count, low in (("restarts", restarts, 1), ("iterations", iterations, 0)):
            if isinstance(count, bool) or int(count) != count or count < low:
                raise ValueError(f"{name}={count!r}: must be an integer >= {low}")
        for name, size in (("lr", lr), ("sigma", sigma)):
            if not np.isfinite(size) or size <= 0:
                raise ValueError(f"{name}={size!r}: must be a positive finite number")
        scene_kwargs(scene)                   # refuses an unknown scene by name
        super().__init__(np.zeros((1, 1, 4)), "gradient")
        self.scene = scene
        self.restarts, self.iterations, self.lr, self.sigma, self.seed = int(restarts), int(iterations), lr, sigma, seed
        self.history: list[float] = []        # the mean best error sum (mm x steps) before and after each iteration
        self.elapsed: list[float] = []        # wall seconds since plan() began, at each entry of history
        self.decision_us = float("nan")       # planning wall time per decision of the plan

    def plan(self, warm_start: Any, episodes: int, seed: int | list[int] = 1000, **make: Any) -> np.ndarray:
        """Plan the ``episodes`` evaluation episodes seeded ``seed, seed + 1, ...`` (or ``seed[i]``) from
        ``warm_start``'s actions; returns each episode's summed shape error under its plan, as
        :func:`~.evaluate.evaluate` measures it. ``make`` overrides scene sections as evaluate's does."""
        started = time.perf_counter()
        seeds = episode_list(seed, episodes)
        n, k = len(seeds), self.restarts
        warm_error, base = warm_start_actions(warm_start, self.scene, seeds, **make)       # base: (n, H, 4)
        horizon = base.shape[1]
        start = np.arctanh(np.clip(base, -EDGE, EDGE))
        noise = np.stack([np.random.default_rng([self.seed, s]).standard_normal((k, horizon, 4)) for s in seeds])
        noise[:, 0] = 0.0                                                                  # restart 0: the warm start
        z = torch.tensor((start[:, None] + self.sigma * noise).reshape(n * k, horizon, 4), requires_grad=True)
        optimizer = torch.optim.Adam([z], lr=self.lr)
        env = self._env(n * k, horizon, make)
        rollout_seeds = [s for s in seeds for _ in range(k)]
        best_z, best_loss = z.detach().clone(), torch.full((n * k,), torch.inf, dtype=torch.float64)
        self.history, self.elapsed = [], []
        for iteration in range(self.iterations + 1):
            env.reset(seed=rollout_seeds)
            loss = torch.zeros(n * k, dtype=torch.float64)
            for t in range(horizon):
                loss = loss + env.step(torch.tanh(z[:, t]))[4]["shape_error_mm"]
            better = loss.detach() < best_loss
            best_z[better], best_loss[better] = z.detach()[better], loss.detach()[better]
            self.history.append(float(best_loss.view(n, k).min(dim=1).values.mean()))
            self.elapsed.append(time.perf_counter() - started)
            if iteration == self.iterations:              # the last rollout only scores the last step's plans
                break
            optimizer.zero_grad()
            loss.sum().backward()
            finite = torch.isfinite(torch.as_tensor(z.grad))
            if not finite.all():                          # a gradient the simulator should not form: say where
                row, step = (int(v) for v in torch.nonzero(~finite)[0, :2])
                raise FloatingPointError(f"{self.scene}: the gradient of episode seed {rollout_seeds[row]} (restart "
                                         f"{row % k}) is not finite at step {step} (iteration {iteration})")
            optimizer.step()
        env.close()
        plans = torch.tanh(best_z).numpy().astype(np.float32).reshape(n, k, horizon, 4)
        replay = ReplayPolicy(plans.reshape(n * k, horizon, 4))
        error = evaluate(replay, self.scene, n * k, rollout_seeds, **make).values["error_sum_mm"].reshape(n, k)
        pick = np.argmin(error, axis=1)
        improved = error[np.arange(n), pick] < warm_error
        self.actions = np.where(improved[:, None, None], plans[np.arange(n), pick], base.astype(np.float32))
        self.decision_us = (time.perf_counter() - started) / (n * horizon) * 1e6
        return np.where(improved, error[np.arange(n), pick], warm_error)

    def _env(self, num_envs: int, horizon: int, make: dict[str, Any]) -> Any:
        """The scene's differentiable torch twin on its test targets, episodes of ``horizon`` steps."""
        env_id, kwargs = scene_kwargs(self.scene, make=make)
        kwargs["task"] = {**kwargs["task"], "horizon": horizon}
        return gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", backend="torch",
                            differentiable=True, **kwargs)


def tune_lr(scene: str, warm_start: Any, lrs: tuple[float, ...] = STEP_SIZES, iterations: int = 10,
            seeds: tuple[int, ...] = (0, 1)) -> tuple[float, dict[str, float]]:
    """Adam's step size for ``scene``: of ``lrs``, the one whose plans (2 restarts, ``iterations`` steps) of the
    *training*-target episodes ``seeds`` end with the least mean summed shape error, never a test episode (ties,
    where none improves on the warm start, go to the first); returns it and each step size's error."""
    tried = {}
    for lr in lrs:
        planner = GradientPlanner(scene, restarts=2, iterations=iterations, lr=lr)
        tried[f"{lr:g}"] = float(planner.plan(warm_start, len(seeds), list(seeds), **TRAIN).mean())
    return float(min(tried, key=lambda key: tried[key])), tried


def planner_warm_start(world: World) -> Any:
    """The warm start the benchmark plans from: the scripted expert on the laryngoscope, no force on the
    ideal device."""
    return make_baseline("expert", world) if world.device_kind.name == "laryngoscope" else ZeroPolicy(world)
