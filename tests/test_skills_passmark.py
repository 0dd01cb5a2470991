"""Pass marks by the contrasting-groups method, and the demo cohort's learning model."""

import numpy as np
import pytest
from scipy import optimize, stats

from softenv.skills import cohort
from softenv.skills.passmark import PassMark, contrasting_groups, crossing, group_amounts
from softenv.skills.store import Store


def test_the_mark_is_where_the_fitted_normal_densities_cross():
    rng = np.random.default_rng(1)
    expert, novice = rng.normal(90, 3, 40), rng.normal(50, 9, 40)
    mark = crossing(expert, novice)
    fitted = [stats.norm(g.mean(), g.std(ddof=1)) for g in (expert, novice)]
    truth = optimize.brentq(lambda x: fitted[0].pdf(x) - fitted[1].pdf(x), novice.mean(), expert.mean())
    assert mark == pytest.approx(truth, abs=1e-9)
    same = crossing(np.array([80.0, 90.0]), np.array([40.0, 50.0]))      # equal spreads: the midpoint of the means
    assert same == pytest.approx(65.0)


def test_groups_that_do_not_contrast_are_refused():
    with pytest.raises(ValueError, match="not above the novice group's"):
        crossing(np.array([50.0, 52.0]), np.array([60.0, 61.0]))
    with pytest.raises(ValueError, match="novice group needs at least 2 finite scores"):
        crossing(np.array([90.0, 92.0]), np.array([np.nan, 40.0]))


def test_false_pass_and_fail_are_counted_in_the_groups():
    mark = PassMark("s", 60.0, "contrasting groups", 1, {"expert": [55.0, 70.0, 80.0, 90.0], "novice": [40.0, 61.0]})
    assert (mark.false_fail, mark.false_pass) == (0.25, 0.5)
    again = PassMark.from_evidence("s", 60.0, "contrasting groups", 1, mark.evidence())
    assert again == mark


def test_members_vary_around_their_profile_within_what_degrade_takes():
    members = group_amounts({"hesitation": 1.0, "overshoot": 40.0}, 200, seed=3)
    hesitation = np.array([m["hesitation"] for m, _ in members])
    assert 0.5 <= hesitation.min() and hesitation.max() <= 1.6 and abs(hesitation.mean() - 1.05) < 0.05
    assert max(m["overshoot"] for m, _ in members) == 50.0          # 40 x 1.5 capped at degrade's 50 mm
    assert all(0 <= m["tremor"] <= 0.2 for m, _ in members)         # the tremor every member shows


def test_the_scene_mark_separates_the_expert_and_novice_profiles():
    mark = contrasting_groups("SoftSphereHaptic-v0", None, per_group=4, seed=0)
    expert, novice = np.array(mark.groups["expert"]), np.array(mark.groups["novice"])
    assert novice.max() < mark.mark < expert.min()
    assert (mark.false_pass, mark.false_fail) == (0.0, 0.0) and mark.method == "contrasting groups"


def test_the_cohort_learns_by_the_power_law_of_practice():
    rows = cohort.plan(trainees=4, sessions=8, seed=2)
    assert rows == cohort.plan(trainees=4, sessions=8, seed=2)                 # seeded
    assert [r[1] for r in rows[::8]] == list(cohort.STARTING_PROFILES)
    hesitation = np.array([r[4]["hesitation"] for r in rows]).reshape(4, 8)
    # errors shrink over sessions: the last session's are well below the first's for every trainee
    assert np.all(hesitation[:, -1] < 0.7 * hesitation[:, 0] + 0.1)
    assert all((b[3] - a[3]).days == 7 for a, b in zip(rows[:7], rows[1:8]))    # a week apart


def test_a_small_demo_cohort_is_kept_with_its_pass_mark(tmp_path):
    stages = []
    with Store(tmp_path / "demo.sqlite") as store:
        cohort.build(store, trainees=2, sessions=2, per_group=3, progress=lambda s, d, t: stages.append((s, d, t)))
        rows = store.sessions()
        assert sorted((r.trainee, r.source) for r in rows) == [("T-01", "demo")] * 2 + [("T-02", "demo")] * 2
        assert set(store.pass_marks()) == {"SoftSphereHaptic-v0"}
        assert {t.status for t in store.trainees()} <= {"pass", "not yet"}
    assert ("sessions", 4, 4) in stages and ("pass mark", 6, 6) in stages


def test_the_cached_demo_cohort_is_rebuilt_when_the_code_changes(tmp_path, monkeypatch):
    """The cohort's sessions are played by the simulator: a cache keyed on softenv's version alone served
    a cohort of older code (found remaking results/skills_lab)."""
    monkeypatch.setattr(cohort, "cache_dir", lambda: tmp_path)
    built = []
    monkeypatch.setattr(cohort, "build", lambda store, *a, **k: built.append(store))
    monkeypatch.setattr(cohort, "code_digest", lambda: "one")
    first = cohort.demo_store(trainees=1, sessions=1)
    assert cohort.demo_store(trainees=1, sessions=1) == first and len(built) == 1      # read from the cache
    monkeypatch.setattr(cohort, "code_digest", lambda: "another")
    assert cohort.demo_store(trainees=1, sessions=1) != first and len(built) == 2
