"""softenv.stats against hand-worked cases and against the rliable package (Agarwal et al. 2021), its
reference implementation: the same point estimates, and intervals of the same width."""

import numpy as np
import pytest

from softenv import stats

rliable_metrics = pytest.importorskip("rliable.metrics")
rliable_library = pytest.importorskip("rliable.library")


def test_hand_worked_aggregates():
    values = np.arange(100, dtype=float)
    assert stats.iqm(values) == pytest.approx(np.mean(np.arange(25, 75)))
    assert stats.iqm(np.array([1.0, 2.0, 3.0, 100.0, 5.0])) == pytest.approx(np.mean([2.0, 3.0, 5.0]))  # cut 1 each end
    assert stats.optimality_gap(np.array([90.0, 110.0, 100.0, 80.0])) == pytest.approx((10 + 0 + 0 + 20) / 4)
    mean, lo, hi = stats.bootstrap_ci(values)
    assert mean == pytest.approx(49.5) and lo < mean < hi
    assert hi - lo == pytest.approx(2 * 1.96 * values.std() / 10, rel=0.15)       # the normal approximation
    assert stats.probability_of_improvement(np.array([[2.0], [3.0]]), np.array([[1.0], [3.0]])) == pytest.approx(
        (1 + 0 + 1 + 0.5) / 4)         # 2 > 1, 2 < 3, 3 > 1, 3 = 3 (a half)
    profile = stats.performance_profile(np.array([[10.0, 50.0], [60.0, 90.0]]), np.array([0.0, 20.0, 55.0, 95.0]))
    np.testing.assert_allclose(profile, [1.0, (0.5 + 1.0) / 2, (0.5 + 0.5) / 2, 0.0])


def _matrices(seed=0):
    rng = np.random.default_rng(seed)
    return rng.normal(80, 15, (10, 5)), rng.normal(75, 20, (8, 5))


def test_point_estimates_equal_rliable():
    x, y = _matrices()
    assert stats.iqm(x) == pytest.approx(rliable_metrics.aggregate_iqm(x), rel=1e-12)
    assert stats.mean(x) == pytest.approx(rliable_metrics.aggregate_mean(x), rel=1e-12)
    assert stats.median(x) == pytest.approx(rliable_metrics.aggregate_median(x), rel=1e-12)
    assert stats.optimality_gap(x) == pytest.approx(rliable_metrics.aggregate_optimality_gap(x, gamma=100.0), rel=1e-12)
    assert stats.probability_of_improvement(x, y) == pytest.approx(
        rliable_metrics.probability_of_improvement(x, y), rel=1e-12)
    taus = np.linspace(0, 120, 25)
    profile, _ = rliable_library.create_performance_profile({"x": x}, taus)
    np.testing.assert_allclose(stats.performance_profile(x, taus), profile["x"], rtol=1e-12)


def test_stratified_intervals_match_rliable_within_bootstrap_noise():
    """Different generators draw different resamples: the interval ends agree to a few percent of its width."""
    x, y = _matrices(1)
    ours = stats.interval_estimates(x, resamples=4000)

    def fn(scores):
        return np.array([rliable_metrics.aggregate_iqm(scores), rliable_metrics.aggregate_optimality_gap(scores, 100.0)])

    points, cis = rliable_library.get_interval_estimates({"x": x}, fn, reps=4000)
    for i, name in enumerate(("iqm", "optimality_gap")):
        point, lo, hi = ours[name]
        width = float(cis["x"][1, i] - cis["x"][0, i])
        assert point == pytest.approx(points["x"][i], rel=1e-12)
        assert lo == pytest.approx(cis["x"][0, i], abs=0.1 * width)
        assert hi == pytest.approx(cis["x"][1, i], abs=0.1 * width)
    poi_point, poi_lo, poi_hi = stats.improvement_interval(x, y, resamples=2000)
    points, cis = rliable_library.get_interval_estimates(
        {"x,y": (x, y)}, rliable_metrics.probability_of_improvement, reps=2000)
    low, high = np.ravel(cis["x,y"])
    assert poi_point == pytest.approx(float(np.ravel(points["x,y"])[0]), rel=1e-12)
    assert poi_lo == pytest.approx(low, abs=0.15 * (high - low)) and poi_hi == pytest.approx(high, abs=0.15 * (high - low))


def test_nested_interval_covers_the_spread_between_runs():
    """With one run it is the bootstrap over episodes; runs that disagree widen it (the reviewer's point:
    three seeds at 75, 93 and 96 are not one policy at 88 +- 1.4)."""
    rng = np.random.default_rng(2)
    one = rng.normal(88, 5, (1, 100))
    assert stats.nested_interval(one) == stats.bootstrap_ci(one[0])            # the same draws, bit for bit
    seeds = np.stack([rng.normal(m, 5, 100) for m in (74.7, 93.3, 96.1)])
    _, lo, hi = stats.nested_interval(seeds)
    pooled = stats.bootstrap_ci(seeds.ravel())
    assert hi - lo > 5 * (pooled[2] - pooled[1])
    assert lo < 80 and hi > 93


def test_bad_scores_are_refused_by_name():
    with pytest.raises(ValueError, match="non-finite"):
        stats.interval_estimates(np.array([[1.0, np.nan]]))
    with pytest.raises(ValueError, match=r"\(runs, tasks\)"):
        stats.check_scores(np.zeros((2, 2, 2)))
    with pytest.raises(ValueError, match="same tasks"):
        stats.probability_of_improvement(np.zeros((2, 3)), np.zeros((2, 2)))


def test_per_episode_scores_give_a_method_of_one_run_its_episodes_spread():
    """Per task (runs, episodes) scores: the matrix is the run means, the interval resamples runs then
    episodes; one run on one task is the bootstrap of its episodes' mean."""
    rng = np.random.default_rng(5)
    one = rng.normal(90, 4, (1, 100))
    matrix, draws = stats.with_resamples([one, one + 1.0], resamples=3000)
    np.testing.assert_allclose(matrix, [[one.mean(), one.mean() + 1.0]])
    assert draws.shape == (3000, 1, 2)
    point, lo, hi = stats.interval_estimates([one], resamples=3000)["mean"]
    reference = stats.bootstrap_ci(one[0], resamples=3000)
    assert point == pytest.approx(reference[0], rel=1e-12)
    assert lo == pytest.approx(reference[1], abs=0.1 * (reference[2] - reference[1]))
    assert hi == pytest.approx(reference[2], abs=0.1 * (reference[2] - reference[1]))
    with pytest.raises(ValueError, match="same number of runs"):
        stats.with_resamples([np.zeros((2, 3)), np.zeros((1, 3))])
