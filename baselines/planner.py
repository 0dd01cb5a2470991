"""The benchmark's oracle on the laryngoscope scenes: trajectory optimisation through the true model.

On the ideal device one step decides everything, and :class:`~baselines.policies.PlanningOracle`
solves it exactly. Through the laryngoscope the shape error summed over the episode depends on the
whole hand trajectory (the blade must be inserted, pressed and swept, through a coupling, against
the incisors), so the oracle plans the whole episode in the scene's own simulator -- device,
contact, response and creep, the same code the policies are scored on. Every quantity of an episode
(start state, target, target schedule) is known to the oracle from the evaluation seed, and the
simulator is deterministic, so an open-loop action sequence optimised for an episode is also its
best closed-loop behaviour: no feedback can do better than a plan that already knows every outcome.

The optimiser is the cross-entropy method (CEM) on the summed shape error itself (the score's ``E``):

* the plan is ``clip(base + interp(knots))``: a warm start ``base`` (the scripted expert's own
  actions, recorded) plus a correction given at knots every ``knot_every`` control steps and
  linearly interpolated between them, which keeps the search smooth and its dimension small
  (51 knots x 4 for a 250-step episode);
* every iteration samples ``candidates - 1`` corrections per episode around the current mean, rolls
  them all out at once on the batched twin (one row per candidate), and refits mean and spread to the
  ``elites`` best; the best plan so far is always re-entered as a candidate (elitism), so the plan
  never gets worse than the warm start;
* everything is seeded, each episode by its own seed, so the plan (and the score's 100) is reproducible bit
  for bit and an episode's plan is the same whichever episodes are planned beside it;
* the search runs from several starts side by side (version 3): the expert's actions with two sampler
  seeds, and no action at all, a start that owes nothing to the expert; each episode keeps its best
  start's plan. 120 iterations: ``scripts/oracle_budget.py`` measures what a longer search would add.

Why not MPC over a receding horizon: with a model this exact a receding horizon only truncates the
cost (the error still to come after the horizon), and its per-step replanning costs the horizon's
rollouts at every step; whole-episode shooting uses the same rollouts on the true objective.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from .evaluate import evaluate


class ReplayPolicy:
    """Plays fixed action sequences ``(n, H, 4)``: row ``i`` of every batch gets ``actions[i, t]`` at
    the episode's step ``t`` (one batch call per step). A single row (a latency probe) gets row 0's
    last action."""

    def __init__(self, actions: np.ndarray, name: str = "replay") -> None:
        self.actions = np.asarray(actions, dtype=np.float32)
        self.name = name
        self._t = 0

    def reset(self) -> None:
        self._t = 0

    def predict(self, obs: Any) -> np.ndarray:
        rows = obs["observation"] if isinstance(obs, dict) else np.asarray(obs)
        if rows.ndim == 1:
            return self.actions[0, -1]
        if len(rows) != len(self.actions):
            raise ValueError(f"{self.name}: a batch of {len(rows)} rows; the plan has {len(self.actions)} episodes")
        t = min(self._t, self.actions.shape[1] - 1)
        self._t += 1
        return self.actions[:, t]


class RecordingPolicy:
    """Wraps a policy and keeps the actions it gave, step by step (the oracle's warm start)."""

    def __init__(self, policy: Any) -> None:
        self.policy = policy
        self.name = policy.name
        self.actions: list[np.ndarray] = []

    def reset(self) -> None:
        self.policy.reset()
        self.actions = []

    def predict(self, obs: Any) -> np.ndarray:
        action = self.policy.predict(obs)
        if np.ndim(action) == 2:                  # batch calls only (not the single-row latency probe)
            self.actions.append(np.array(action, dtype=np.float32))
        return action


def warm_start_actions(warm_start: Any, scene: str, seeds: list[int], **make: Any) -> tuple[np.ndarray, np.ndarray]:
    """``warm_start`` played on the episodes seeded ``seeds``: each episode's summed shape error and its
    actions ``(n, H, 4)`` (float64), where a planner starts."""
    recorder = RecordingPolicy(warm_start)
    error = evaluate(recorder, scene, len(seeds), seeds, **make).values["error_sum_mm"]
    return error, np.stack(recorder.actions, axis=1).astype(np.float64)


def episode_list(seed: int | list[int], episodes: int) -> list[int]:
    """The seeds of ``episodes`` episodes: ``seed, seed + 1, ...``, or ``seed`` itself when it is a list."""
    return [seed + i for i in range(episodes)] if isinstance(seed, int) else [int(s) for s in seed]


class TrajectoryOracle(ReplayPolicy):
    """The whole-episode CEM planner through the device (see the module docstring); after
    :meth:`plan` it replays its plans as a policy.

    Args:
        scene: the benchmark scene (:data:`baselines.evaluate.SCENES`) it plans on.
        candidates: rollouts per episode, start and iteration (the best so far among them).
        iterations: CEM iterations.
        elites: the best candidates the mean and spread are refitted to.
        knot_every: control steps between the correction's knots.
        sigma: the correction's initial spread, in action units.
        seed: the sampler's seed (a restart from the warm start draws with ``seed + r``).
        restarts: searches from the warm start, each with its own sampler seed.
        from_rest: also search from no action at all (the hand held still), a start that owes nothing to
            the warm start.
    """

    # 2: one generator per episode; 3: restarts and a start from rest, 120 iterations.
    # Bump when the search changes: shipped anchors name it
    VERSION = 3

    def __init__(self, scene: str, candidates: int = 16, iterations: int = 120, elites: int = 4, knot_every: int = 25,
                 sigma: float = 0.15, seed: int = 0, restarts: int = 2, from_rest: bool = True) -> None:
        for name, value, low in (("candidates", candidates, 2), ("iterations", iterations, 0), ("elites", elites, 1),
                                 ("knot_every", knot_every, 1), ("restarts", restarts, 0)):
            if int(value) != value or value < low:
                raise ValueError(f"{name}={value!r}: must be an integer >= {low}")
        if elites >= candidates:
            raise ValueError(f"elites={elites} must be below candidates={candidates}")
        if not np.isfinite(sigma) or sigma <= 0:
            raise ValueError(f"sigma={sigma!r}: must be a positive finite number of action units")
        if not isinstance(from_rest, bool):
            raise ValueError(f"from_rest={from_rest!r}: must be True or False")
        if restarts == 0 and not from_rest:
            raise ValueError("restarts=0 with from_rest=False leaves no search: give restarts >= 1 or from_rest=True")
        super().__init__(np.zeros((1, 1, 4)), "oracle")
        self.scene = scene
        self.candidates, self.iterations, self.elites = candidates, iterations, elites
        self.knot_every, self.sigma, self.seed = knot_every, sigma, seed
        self.restarts, self.from_rest = int(restarts), from_rest
        self.history: list[float] = []        # the mean best error sum after each iteration (mm x steps)
        self.history_by_episode = np.zeros((0, 0))   # (iterations + 1, episodes): each episode's best so far
        self.history_by_start = np.zeros((0, 0, 0))  # (starts, iterations + 1, episodes): each start's own
        self.elapsed: list[float] = []        # wall seconds since plan() began, at each entry of history
        self.decision_us = float("nan")       # planning wall time per decision of the plan

    def plan(self, warm_start: Any, episodes: int, seed: int | list[int] = 1000, **make: Any) -> np.ndarray:
        """Plan the ``episodes`` evaluation episodes seeded ``seed, seed + 1, ...`` (or ``seed[i]``, as
        :func:`~softenv.baselines.evaluate.evaluate` seeds them) from each start: ``warm_start``'s actions
        (``restarts`` searches, sampler seeds ``seed, seed + 1, ...``) and, with ``from_rest``, no action
        (sampler seed ``seed``); returns each episode's best summed shape error over the starts. The
        starts run side by side, one batch; each (start, episode) draws from a generator of its own, seeded
        by the sampler's seed and the episode's, so an episode's plan does not depend on which episodes are
        planned beside it, and the first start's search is version 2's. ``make`` overrides scene sections
        as :func:`~softenv.baselines.evaluate.evaluate`'s does (``task={"split": "train"}``: the training
        targets)."""
        started = time.perf_counter()
        seeds = episode_list(seed, episodes)
        warm_error, warm = warm_start_actions(warm_start, self.scene, seeds, **make)      # warm: (n, H, 4)
        n, horizon = warm.shape[:2]
        samplers = [self.seed + r for r in range(self.restarts)]
        bases, errors = [warm] * self.restarts, [warm_error] * self.restarts
        if self.from_rest:
            rest = np.zeros_like(warm)
            bases.append(rest)
            errors.append(evaluate(ReplayPolicy(rest), self.scene, n, seeds, **make).values["error_sum_mm"])
            samplers.append(self.seed)
        starts = len(bases)
        base = np.concatenate(bases)                                       # rows: (start, episode), (S n, H, 4)
        best_error = np.concatenate(errors)
        rows = n * starts
        knots = np.arange(0, horizon + self.knot_every, self.knot_every)
        weights = _interpolation(horizon, knots)                            # (H, M)
        rngs = [np.random.default_rng([sampler, episode]) for sampler in samplers for episode in seeds]
        mean = np.zeros((rows, len(knots), 4))
        best = mean.copy()
        best_actions = base.astype(np.float32)
        spread = np.full_like(mean, self.sigma)
        rollout_seeds = [episode for _ in range(starts) for episode in seeds for _ in range(self.candidates)]
        by_start = [best_error.copy()]
        self.elapsed = [time.perf_counter() - started]
        for _ in range(self.iterations):
            noise = np.stack([rng.standard_normal((self.candidates - 1, len(knots), 4)) for rng in rngs]) * spread[:, None]
            trial = np.concatenate([best[:, None], mean[:, None] + noise], axis=1)     # (rows, K, M, 4)
            actions = np.clip(base[:, None] + np.einsum("tm,nkmc->nktc", weights, trial), -1.0, 1.0)
            replay = ReplayPolicy(actions.reshape(rows * self.candidates, horizon, 4))
            error = evaluate(replay, self.scene, rows * self.candidates, rollout_seeds, **make).values["error_sum_mm"]
            error = error.reshape(rows, self.candidates)
            order = np.argsort(error, axis=1, kind="stable")
            improved = error[np.arange(rows), order[:, 0]] < best_error
            best[improved] = trial[improved, order[improved, 0]]
            best_actions[improved] = replay.actions.reshape(rows, self.candidates, horizon, 4)[improved, order[improved, 0]]
            best_error = np.where(improved, error[np.arange(rows), order[:, 0]], best_error)
            elite = np.take_along_axis(trial, order[:, :self.elites, None, None], axis=1)
            mean = elite.mean(axis=1)
            spread = np.maximum(elite.std(axis=1), 0.02 * self.sigma)
            by_start.append(best_error.copy())
            self.elapsed.append(time.perf_counter() - started)
        self.history_by_start = np.stack(by_start).reshape(self.iterations + 1, starts, n).transpose(1, 0, 2)
        winner = np.argmin(self.history_by_start[:, -1], axis=0)           # each episode's best start (first on ties)
        self.history_by_episode = self.history_by_start.min(axis=0)
        self.history = [float(v) for v in self.history_by_episode.mean(axis=1)]
        # the very actions whose rollouts scored the best error
        self.actions = best_actions.reshape(starts, n, horizon, 4)[winner, np.arange(n)]
        self.decision_us = (time.perf_counter() - started) / (n * horizon) * 1e6
        return self.history_by_start[winner, -1, np.arange(n)]


def _interpolation(horizon: int, knots: np.ndarray) -> np.ndarray:
    """``(horizon, len(knots))`` weights of piecewise-linear interpolation between knots at those steps."""
    t = np.arange(horizon, dtype=np.float64)
    eye = np.eye(len(knots))
    return np.stack([np.interp(t, knots, eye[j]) for j in range(len(knots))], axis=1)

