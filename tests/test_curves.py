"""The learning curves' convergence rule and the comparison at equal env steps (baselines/curves.py),
against sums done by hand on made-up curves."""

import numpy as np
import pytest

from softenv.baselines import curves
from softenv.baselines.curves import at_equal_steps, convergence, convergence_report, value_at
from softenv.stats import bootstrap_ci

STEPS = np.arange(1, 11) * 1000.0


def test_value_at_reads_the_last_evaluation_at_or_before():
    curve = (STEPS, -np.arange(10.0, 0.0, -1.0))
    assert value_at(curve, 8000) == (-3.0, 8000)
    assert value_at(curve, 8999) == (-3.0, 8000)
    with pytest.raises(ValueError, match=r"steps=500: .* first evaluation is at 1000"):
        value_at(curve, 500)


def test_a_flat_tail_converges_and_a_rising_one_does_not():
    """Three seeds level at -10, -12, -14 from 5,000 steps: their lines over the last half are flat, so no
    further gain, converged. Three seeds still climbing 5 each 1,000 steps: a further 2,000 steps add 10,
    against a tolerance of 5 % of the 45 gained (-60 to -15), so not converged, every seed still rising."""
    flat = [(STEPS, np.r_[np.linspace(-100, level, 5), [level] * 5]) for level in (-10.0, -12.0, -14.0)]
    c = convergence(flat)
    assert c["ahead"] == pytest.approx(0.0, abs=1e-9) and c["final"] == pytest.approx(-12.0)
    assert c["tolerance"] == pytest.approx(0.05 * 88.0) and c["still_rising"] == 0 and c["converged"] is True
    mean, low, high = bootstrap_ci(np.array([-10.0, -12.0, -14.0]))
    assert (c["final_low"], c["final_high"]) == (low, high)

    rising = [(STEPS, -60 + 5 * np.arange(10) + offset) for offset in (0.0, 0.5, 1.0)]
    r = convergence(rising)
    assert r["ahead"] == pytest.approx(10.0) and r["tolerance"] == pytest.approx(0.05 * 45.0)
    assert r["still_rising"] == 3 and r["converged"] is False
    assert r["budget"] == 10_000 and r["seeds"] == 3


def test_seeds_levelled_far_apart_do_not_loosen_the_rule():
    """The old rule's flaw: two seeds stuck at -200 and two at -60 give a final interval some 70 wide, which
    hid a third pair still climbing 4 each 1,000 steps. Paired by seed, their further gains (0, 0, 8, 8)
    have an upper end of 8, above 5 % of the mean gain so far, so not converged; two seeds still rising."""
    stuck = [(STEPS, np.r_[np.linspace(-250, level, 5), [level] * 5]) for level in (-200.0, -60.0)]
    climbing = [(STEPS, -120 + 4 * np.arange(10.0) + offset) for offset in (0.0, 1.0)]
    r = convergence(stuck + climbing)
    assert r["ahead"] == pytest.approx(4.0) and r["ahead_high"] == pytest.approx(8.0)
    assert r["still_rising"] == 2 and r["converged"] is False
    assert r["final_high"] - r["final_low"] > 50                     # the spread the old rule took as tolerance


def test_one_seed_or_too_few_evaluations_have_no_verdict_and_bad_input_is_refused():
    assert convergence([(STEPS, STEPS / 1000)])["converged"] is None
    sparse = [(np.array([1000.0, 10_000.0]), np.array([-50.0, v])) for v in (-10.0, -12.0)]
    assert convergence(sparse)["converged"] is None                  # one evaluation in the last half
    with pytest.raises(ValueError, match=r"runs=\[\]"):
        convergence([])


def test_agents_are_read_at_the_smallest_budget():
    """SAC's budget is 4,000 steps, PPO's 10,000: both are read at 4,000, PPO at its evaluation there."""
    ppo = [(STEPS, STEPS / 100), (STEPS, STEPS / 100 + 2)]
    sac = [(STEPS[:4], np.array([1.0, 2.0, 3.0, 4.0]))]
    steps, at = at_equal_steps({"ppo": ppo, "sac": sac})
    assert steps == 4000
    assert at["ppo"][0] == pytest.approx(41.0) and at["sac"][0] == pytest.approx(4.0)
    with pytest.raises(ValueError, match="at least one curve"):
        at_equal_steps({"ppo": ppo, "sac": []})

    table, rows = convergence_report({("S", "ppo"): ppo, ("S", "sac"): sac}, {("S", "ppo"): [30.0, None]})
    assert [r["agent"] for r in rows] == ["ppo", "sac"] and rows[0]["train_s_per_seed"] == 30.0
    assert rows[0]["train_s_recorded"] == 1 and rows[1]["train_s_recorded"] == 0
    assert np.isnan(rows[1]["train_s_per_seed"]) and rows[0]["equal_steps"] == 4000
    assert "| S | ppo | 2 | 10,000 |" in table and "41.0" in table
    # the minutes column: the mean of the seeds that recorded theirs, and how many did
    assert "| 0.5 (1 of 2 seeds) |" in table and table.endswith("at 4,000 | - |")
    both = convergence_report({("S", "ppo"): ppo}, {("S", "ppo"): [30.0, 90.0]})[0]
    assert both.endswith("at 10,000 | 1.0 |")


def test_the_rule_is_written_from_its_constants(monkeypatch):
    """The rule's words follow its numbers: one place says them (the table's headers too)."""
    assert (curves.TREND, curves.AHEAD, curves.TOLERANCE) == (0.5, 0.2, 0.05)
    assert "last 50 % of the budget" in curves.RULE and "further 20 %" in curves.RULE
    assert "less than 5 %" in curves.RULE and "above 5 %" in curves.RISING
    monkeypatch.setattr(curves, "TOLERANCE", 0.1)
    monkeypatch.setattr(curves, "AHEAD", 0.25)
    table = curves.convergence_report({("S", "ppo"): [(STEPS, STEPS / 100)] * 2}, {})[0]
    assert "gain a further 25 % would add" in table and "tolerance (10 % of the gain so far)" in table


def test_the_learning_curves_name_the_agents_still_rising():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from softenv.baselines.benchmark import Plan, _learning_curves

    rising = [(STEPS, -60 + 5 * np.arange(10) + offset) for offset in (0.0, 0.5, 1.0)]
    flat = [(STEPS, np.r_[np.linspace(-100, level, 5), [level] * 5]) for level in (-10.0, -12.0, -14.0)]
    plan = Plan(["SoftSphere-v0"], [], ["ppo", "sac"], {"SoftSphere-v0": 3}, {"ppo": 10_000, "sac": 10_000})
    fig = _learning_curves(plan, {("SoftSphere-v0", "ppo"): rising, ("SoftSphere-v0", "sac"): flat}, "test", plt)
    texts = [t.get_text() for t in fig.axes[0].texts]
    assert any(t.endswith("not converged (rule in the report): ppo") for t in texts)
    plt.close(fig)
