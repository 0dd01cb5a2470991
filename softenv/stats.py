"""Statistics a benchmark reports: robust aggregates, their interval estimates, and comparisons.

Agarwal et al. 2021 ("Deep RL at the edge of the statistical precipice", the ``rliable`` package)
set how RL results are reported: scores as a ``(runs, tasks)`` matrix (a run is one training seed,
a task one scene; an entry the run's mean normalized score on the task), aggregated by the
interquartile mean (IQM) and the optimality gap, each with a 95 % interval from a *stratified*
bootstrap (runs resampled with replacement within each task, so every task keeps its weight);
performance profiles (the share of runs and tasks above each score ``tau``); and the probability
that one method improves on another (the Mann-Whitney statistic, averaged over tasks). ``rliable``
is archived (October 2025), so softenv owns this code; the tests hold it to the package's numbers.

Everything here is numpy only. Point estimates equal ``rliable``'s definitions: IQM is
``scipy.stats.trim_mean(scores, 0.25)`` over all entries, the median is that of the tasks' means, the
optimality gap is
``gamma - mean(min(scores, gamma))`` (``gamma`` = 100, the planning oracle), the performance profile
counts scores strictly above ``tau``.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

ORACLE_SCORE = 100.0            # the normalized score of the planning oracle: the optimality gap's threshold
CONFIDENCE = 0.95
RESAMPLES = 2000

Aggregate = Callable[[np.ndarray], float]


def iqm(values: np.ndarray) -> float:
    """Interquartile mean: the mean of the middle 50 % of all entries (``floor(n / 4)`` cut from each end,
    as ``scipy.stats.trim_mean(values, 0.25)``)."""
    v = np.sort(np.asarray(values, dtype=np.float64), axis=None)
    if v.size == 0:
        return float("nan")
    cut = int(0.25 * v.size)
    return float(v[cut:v.size - cut].mean())


def mean(values: np.ndarray) -> float:
    v = np.asarray(values, dtype=np.float64)
    return float(v.mean()) if v.size else float("nan")


def median(values: np.ndarray) -> float:
    """The median over tasks of each task's mean over runs (``rliable``'s), of a ``(runs, tasks)`` matrix."""
    v = np.asarray(values, dtype=np.float64)
    return float(np.median(v.reshape(len(v), -1).mean(axis=0))) if v.size else float("nan")


def optimality_gap(values: np.ndarray, gamma: float = ORACLE_SCORE) -> float:
    """How far scores fall short of ``gamma`` on average, scores above it counting as ``gamma``."""
    v = np.asarray(values, dtype=np.float64)
    return float(gamma - np.minimum(v, gamma).mean()) if v.size else float("nan")


AGGREGATES: dict[str, Aggregate] = {"iqm": iqm, "mean": mean, "median": median, "optimality_gap": optimality_gap}


def check_scores(scores: np.ndarray, name: str = "scores") -> np.ndarray:
    """A ``(runs, tasks)`` float matrix of finite scores (a 1-D array is one task's runs)."""
    m = np.asarray(scores, dtype=np.float64)
    if m.ndim == 1:
        m = m[:, None]
    if m.ndim != 2 or m.shape[0] < 1 or m.shape[1] < 1:
        raise ValueError(f"{name} must be a (runs, tasks) matrix with at least one entry; got shape {m.shape}")
    if not np.isfinite(m).all():
        raise ValueError(f"{name} holds {int((~np.isfinite(m)).sum())} non-finite entries; every score must be finite")
    return m


def stratified_resamples(scores: np.ndarray, resamples: int = RESAMPLES, seed: int = 0) -> np.ndarray:
    """``(resamples, runs, tasks)``: each task's runs drawn with replacement, independently of the other tasks."""
    m = check_scores(scores)
    runs, tasks = m.shape
    rng = np.random.default_rng(seed)
    rows = rng.integers(0, runs, size=(resamples, runs, tasks))
    return np.take_along_axis(m[None], rows, axis=1)


def interval(point: float, draws: np.ndarray, confidence: float = CONFIDENCE) -> tuple[float, float, float]:
    """``(point, low, high)``: the percentile interval of the bootstrap ``draws`` around ``point``."""
    tail = 100 * (1 - confidence) / 2
    return point, float(np.percentile(draws, tail)), float(np.percentile(draws, 100 - tail))


def with_resamples(scores: np.ndarray | list[np.ndarray], resamples: int = RESAMPLES,
                   seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The ``(runs, tasks)`` matrix of run means and its stratified bootstrap draws ``(resamples, runs, tasks)``.
    ``scores`` is that matrix (runs resampled within each task), or per task a ``(runs, episodes)`` array of
    per-episode scores, the same number of runs on each (runs resampled within each task, then episodes
    within each drawn run: the interval then holds the spread between episodes too, which a method with
    one run, a deterministic baseline, has and a matrix of its one run mean cannot show)."""
    if not isinstance(scores, list):
        m = check_scores(scores)
        return m, stratified_resamples(m, resamples, seed)
    tasks = [check_scores(t, f"scores[{i}]") for i, t in enumerate(scores)]
    if not tasks or len({len(t) for t in tasks}) != 1:
        raise ValueError(f"scores must give every task the same number of runs; got {[len(t) for t in tasks]}")
    rng = np.random.default_rng(seed)
    draws = np.stack([nested_draws(t, resamples, rng).mean(axis=-1) for t in tasks], axis=-1)
    return np.stack([t.mean(axis=1) for t in tasks], axis=1), draws


def nested_draws(scores: np.ndarray, resamples: int, rng: np.random.Generator) -> np.ndarray:
    """``(resamples, runs, episodes)``: a ``(runs, episodes)`` array's runs drawn with replacement, then
    episodes with replacement within each drawn run (one run: the episodes drawn as :func:`bootstrap_ci`
    draws them, from the same stream, so the two intervals are one)."""
    runs, episodes = scores.shape
    picked = rng.integers(0, runs, size=(resamples, runs, 1)) if runs > 1 else np.zeros((resamples, 1, 1), int)
    return scores[picked, rng.integers(0, episodes, size=(resamples, runs, episodes))]


def interval_estimates(scores: np.ndarray | list[np.ndarray], aggregates: dict[str, Aggregate] | None = None,
                       resamples: int = RESAMPLES, confidence: float = CONFIDENCE,
                       seed: int = 0) -> dict[str, tuple[float, float, float]]:
    """Each aggregate of a ``(runs, tasks)`` matrix (or of per-task ``(runs, episodes)`` scores: see
    :func:`with_resamples`) with its stratified-bootstrap interval: ``{"iqm": (point, low, high), ...}``
    (default: IQM, mean, median, optimality gap)."""
    m, draws = with_resamples(scores, resamples, seed)
    aggregates = AGGREGATES if aggregates is None else aggregates
    return {name: interval(fn(m), np.array([fn(d) for d in draws]), confidence) for name, fn in aggregates.items()}


def bootstrap_ci(values: np.ndarray, resamples: int = RESAMPLES, seed: int = 0,
                 confidence: float = CONFIDENCE) -> tuple[float, float, float]:
    """Mean of one sample and its percentile-bootstrap interval (NaNs if the sample is empty)."""
    v = np.asarray(values, dtype=np.float64)
    if v.size == 0:
        return float("nan"), float("nan"), float("nan")
    rng = np.random.default_rng(seed)
    means = v[rng.integers(0, v.size, (resamples, v.size))].mean(axis=1)
    return interval(float(v.mean()), means, confidence)


def nested_interval(scores: np.ndarray, aggregate: Aggregate = mean, resamples: int = RESAMPLES,
                    confidence: float = CONFIDENCE, seed: int = 0) -> tuple[float, float, float]:
    """One scene's ``(runs, episodes)`` scores aggregated over every entry, with the interval of a
    two-level bootstrap: runs (training seeds) drawn with replacement, then episodes within each drawn
    run, so the interval holds both the spread between seeds and the spread between episodes (with one
    run it is the bootstrap over episodes)."""
    m = check_scores(scores)
    draws = nested_draws(m, resamples, np.random.default_rng(seed))
    values = draws.reshape(resamples, -1).mean(axis=1) if aggregate is mean else np.array([aggregate(d) for d in draws])
    return interval(aggregate(m), values, confidence)


def performance_profile(scores: np.ndarray, taus: np.ndarray) -> np.ndarray:
    """The share of runs scoring above each ``tau``, averaged over tasks: ``(len(taus),)``."""
    m = check_scores(scores)
    return (m[None] > np.asarray(taus, dtype=np.float64)[:, None, None]).mean(axis=1).mean(axis=1)


def profile_intervals(scores: np.ndarray | list[np.ndarray], taus: np.ndarray, resamples: int = RESAMPLES,
                      confidence: float = CONFIDENCE, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The performance profile and its pointwise stratified-bootstrap interval: ``(profile, low, high)``
    (``scores`` as :func:`with_resamples` takes them)."""
    m, resampled = with_resamples(scores, resamples, seed)
    draws = np.array([performance_profile(d, taus) for d in resampled])
    tail = 100 * (1 - confidence) / 2
    return performance_profile(m, taus), np.percentile(draws, tail, axis=0), np.percentile(draws, 100 - tail, axis=0)


def probability_of_improvement(x: np.ndarray, y: np.ndarray) -> float:
    """P(X > Y) + P(X = Y) / 2 for a run of method X against a run of method Y on the same task,
    averaged over tasks (both ``(runs, tasks)``, runs may differ in number)."""
    mx, my = check_scores(x, "x"), check_scores(y, "y")
    if mx.shape[1] != my.shape[1]:
        raise ValueError(f"x and y must score the same tasks: x has {mx.shape[1]}, y has {my.shape[1]}")
    greater = (mx[:, None, :] > my[None, :, :]).mean(axis=(0, 1))
    ties = (mx[:, None, :] == my[None, :, :]).mean(axis=(0, 1))
    return float((greater + 0.5 * ties).mean())


def improvement_interval(x: np.ndarray | list[np.ndarray], y: np.ndarray | list[np.ndarray],
                         resamples: int = RESAMPLES, confidence: float = CONFIDENCE,
                         seed: int = 0) -> tuple[float, float, float]:
    """:func:`probability_of_improvement` with its interval, each method resampled within each task
    (``x`` and ``y`` as :func:`with_resamples` takes them)."""
    mx, draws_x = with_resamples(x, resamples, seed)
    my, draws_y = with_resamples(y, resamples, seed + 1)
    point = probability_of_improvement(mx, my)
    return interval(point, np.array([probability_of_improvement(a, b) for a, b in zip(draws_x, draws_y)]), confidence)
