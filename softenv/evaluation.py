"""Score any policy the way the benchmark does: softenv's public evaluation API.

One call, :func:`evaluate_policy`, runs a policy on a benchmark scene's test targets (the protocol's
episodes, all at once on the batched twin), scales each episode's summed shape error by the shipped
anchors into the normalized score (0 = no force, 100 = the planning oracle) and returns the
per-episode metrics with their intervals. A policy is a batched callable from observations to
actions, a stable-baselines3 model, or a policy object with ``predict`` (and ``reset``); a list of
them is one per training seed, and the intervals then cover the seeds too (a two-level bootstrap).
:func:`aggregate` puts several scenes' evaluations of one method together the way ``rliable`` does
(IQM, optimality gap, stratified bootstrap); :mod:`softenv.leaderboard` turns an evaluation into a
result file others can check.

    from softenv.evaluation import evaluate_policy
    result = evaluate_policy(lambda obs: np.zeros((len(obs), 4), np.float32), "SoftSphereHaptic-v0")
    print(result.score)          # (mean, low, high): 0 for no force
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Sequence

import gymnasium as gym
import numpy as np

from . import stats
from .baselines.anchors import Anchors, load_anchors, scene_hash, scene_config
from .baselines.evaluate import (CLINICAL, EPISODES, METRICS, PROTOCOL_VERSION, SCENES, SPLIT, episode_seeds, evaluate,
                                 normalized_scores)
from .baselines.policies import CallablePolicy, SB3Policy

__all__ = ["Evaluation", "SCENES", "aggregate", "as_policy", "evaluate_policy", "score_aggregates"]


def as_policy(policy: Any, name: str | None = None) -> Any:
    """The benchmark's policy interface (``predict(obs)``, ``reset()``, ``name``) around ``policy``: a
    stable-baselines3 model (deterministic actions), an object that already has ``predict`` and
    ``reset``, or a callable ``obs -> actions`` over a batch (numpy or torch; its actions are checked by
    the env, never clipped)."""
    if hasattr(policy, "predict") and hasattr(policy, "observation_space") and hasattr(policy, "policy"):
        wrapped = SB3Policy(policy, name or type(policy).__name__.lower())
        wrapped.obs_mode = "goal" if isinstance(policy.observation_space, gym.spaces.Dict) else "vector"
        return wrapped
    if hasattr(policy, "predict") and hasattr(policy, "reset"):
        return policy                              # its own name; evaluate_policy's name= names the result
    if callable(policy):
        return CallablePolicy(policy, name or str(getattr(policy, "__name__", "policy")))
    raise ValueError(f"policy={policy!r} is neither a callable obs -> actions, a stable-baselines3 model, nor an "
                     "object with predict(obs) and reset()")


def score_aggregates(scores: np.ndarray) -> dict[str, Any]:
    """What an evaluation, and a result file, report of ``(runs, episodes)`` normalized scores: the mean and
    the IQM, each with its two-level bootstrap interval (:func:`softenv.stats.nested_interval`), and each
    run's mean."""
    mean, low, high = stats.nested_interval(scores)
    iqm, iqm_low, iqm_high = stats.nested_interval(scores, stats.iqm)
    return {"mean": mean, "ci_low": low, "ci_high": high, "iqm": iqm, "iqm_low": iqm_low, "iqm_high": iqm_high,
            "per_run": [float(v) for v in scores.mean(axis=1)]}


@dataclass
class Evaluation:
    """A policy's test episodes on one scene: ``runs`` (training seeds) x ``episodes``.

    ``error_sum`` and ``normalized_score`` are ``(runs, episodes)``; ``metrics`` holds every per-episode
    metric of the benchmark (``final_error_mm``, ``success``, ``steps_to_success``, ``peak_force_N``, and
    the clinical metrics on the laryngoscope scenes), each ``(runs, episodes)``. ``score`` is the mean
    normalized score with its 95 % interval (runs, then episodes within them, resampled), ``iqm`` the
    interquartile mean of every episode's score with its interval, ``per_run`` each run's mean."""

    policy: str
    scene: str
    seeds: list[int]
    error_sum: np.ndarray
    normalized_score: np.ndarray
    metrics: dict[str, np.ndarray]
    anchors: Anchors
    decision_us: float
    scene_hash: str
    protocol: int = PROTOCOL_VERSION
    split: str = SPLIT

    @property
    def score(self) -> tuple[float, float, float]:
        a = score_aggregates(self.normalized_score)
        return a["mean"], a["ci_low"], a["ci_high"]

    @property
    def iqm(self) -> tuple[float, float, float]:
        a = score_aggregates(self.normalized_score)
        return a["iqm"], a["iqm_low"], a["iqm_high"]

    @property
    def per_run(self) -> list[float]:
        return score_aggregates(self.normalized_score)["per_run"]

    def summary(self) -> dict[str, Any]:
        """The evaluation's numbers as a report writes them (every aggregate recomputable from the scores)."""
        return {"policy": self.policy, "scene": self.scene, "runs": len(self.normalized_score),
                "episodes": len(self.seeds), **score_aggregates(self.normalized_score), "decision_us": self.decision_us}

    def __str__(self) -> str:
        s = self.summary()
        return (f"{self.policy} on {self.scene}: normalized score {s['mean']:.1f} [{s['ci_low']:.1f}, {s['ci_high']:.1f}] "
                f"(IQM {s['iqm']:.1f}; {s['runs']} run(s) x {s['episodes']} test episodes; 0 = no force, 100 = the "
                "planning oracle)")


def evaluate_policy(policy: Any, scene: str = "SoftSphere-v0", episodes: int = EPISODES, *, name: str | None = None,
                    echo: Callable[[str], None] | None = None) -> Evaluation:
    """Score ``policy`` under the benchmark's protocol on ``scene`` (a name of :data:`SCENES`): the
    protocol's first ``episodes`` test episodes (100 make a leaderboard result), at once on the batched
    twin, scaled by the scene's anchors (shipped; else computed and cached, ``echo`` saying so in one
    line). ``policy``: see :func:`as_policy`; a list or tuple of them is one per training seed."""
    if scene not in SCENES:
        raise ValueError(f"scene={scene!r} is not a benchmark scene; valid scenes: {list(SCENES)}")
    if isinstance(episodes, bool) or not isinstance(episodes, (int, np.integer)) or not 1 <= episodes <= 100_000:
        raise ValueError(f"episodes={episodes!r} must be an int in [1, 100000]")
    runs = list(policy) if isinstance(policy, (list, tuple)) else [policy]
    if not runs:
        raise ValueError("policy=[]: give at least one policy (one per training seed)")
    seeds = episode_seeds(int(episodes))
    anchors = load_anchors(scene, seeds, echo)
    done = [evaluate(as_policy(p, name), scene, len(seeds), seeds) for p in runs]
    names = {e.policy for e in done}
    keys = [k for k in (*METRICS, *CLINICAL) if k in done[0].values and k != "normalized_score"]
    error_sum = np.stack([e.values["error_sum_mm"] for e in done])
    return Evaluation(policy=name or "/".join(sorted(names)), scene=scene, seeds=seeds, error_sum=error_sum,
                      normalized_score=normalized_scores(error_sum, anchors.zero, anchors.oracle),
                      metrics={k: np.stack([e.values[k] for e in done]) for k in keys}, anchors=anchors,
                      decision_us=float(np.median([e.decision_us for e in done])),
                      scene_hash=scene_hash(scene_config(scene)))


def aggregate(evaluations: Sequence[Evaluation], resamples: int = stats.RESAMPLES,
              seed: int = 0) -> dict[str, tuple[float, float, float]]:
    """One method's evaluations on several scenes as ``rliable`` aggregates them: each run's mean score
    per scene makes a ``(runs, scenes)`` matrix; IQM, mean, median and optimality gap with
    stratified-bootstrap intervals. Every evaluation must have the same number of runs."""
    if not evaluations:
        raise ValueError("evaluations=[]: give at least one")
    counts = {len(e.normalized_score) for e in evaluations}
    if len(counts) != 1:
        raise ValueError(f"every scene needs the same number of runs to aggregate; got {sorted(counts)}")
    matrix = np.stack([e.normalized_score.mean(axis=1) for e in evaluations], axis=1)
    return stats.interval_estimates(matrix, resamples=resamples, seed=seed)
