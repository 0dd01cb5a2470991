"""The laryngoscope scenes' oracle: whole-episode CEM through the device (baselines.planner)."""

import gymnasium as gym
import numpy as np
import pytest

from softenv.baselines.evaluate import evaluate, scene_kwargs
from softenv.baselines.planner import RecordingPolicy, ReplayPolicy, TrajectoryOracle
from softenv.baselines.policies import make_baseline
from softenv.envs.config import make_config
from softenv.envs.world import World

SCENE = "SoftSphereHaptic-v0"


@pytest.fixture(scope="module")
def expert():
    kwargs = scene_kwargs(SCENE)[1]
    kwargs.pop("obs_mode")
    return make_baseline("expert", World(make_config(**kwargs)))


def test_replaying_a_closed_loop_rollout_open_loop_gives_the_same_episodes(expert):
    """The oracle's premise: the scene is deterministic, so the actions a feedback policy gave, played
    back blind on the same seeds, give the same errors (to rounding: rows sit elsewhere in the space)."""
    recorder = RecordingPolicy(expert)
    closed = evaluate(recorder, SCENE, episodes=3).values["error_sum_mm"]
    actions = np.stack(recorder.actions, axis=1)
    assert actions.shape == (3, 250, 4)
    replayed = evaluate(ReplayPolicy(actions), SCENE, episodes=3).values["error_sum_mm"]
    np.testing.assert_allclose(replayed, closed, rtol=1e-9)
    # the same actions on other seeds (other targets) are another matter
    other = evaluate(ReplayPolicy(actions), SCENE, episodes=3, seed=[1001, 1002, 1000]).values["error_sum_mm"]
    assert not np.allclose(other, closed, rtol=1e-3)


def test_the_oracle_improves_on_its_warm_start_and_replays_its_plan(expert):
    """Elitist CEM: never worse than the expert on any episode, better on average; the plan it returns
    is what the evaluation then measures; and the same seed gives the same plan bit for bit."""
    warm = evaluate(expert, SCENE, episodes=3).values["error_sum_mm"]
    oracle = TrajectoryOracle(SCENE, candidates=6, iterations=4, elites=2, restarts=1, from_rest=False)
    planned = oracle.plan(expert, episodes=3)
    assert np.all(planned <= warm * (1 + 1e-9)) and planned.mean() < 0.97 * warm.mean()
    assert oracle.history[0] == pytest.approx(warm.mean()) and np.all(np.diff(oracle.history) <= 1e-9)
    assert len(oracle.elapsed) == len(oracle.history) == 5        # a wall time for each entry of the history
    by_episode = oracle.history_by_episode                        # each episode's own budget curve
    assert by_episode.shape == (5, 3) and np.all(np.diff(by_episode, axis=0) <= 0)
    np.testing.assert_array_equal(by_episode[0], warm)
    np.testing.assert_array_equal(by_episode[-1], planned)
    np.testing.assert_allclose(by_episode.mean(axis=1), oracle.history, rtol=1e-12)
    measured = evaluate(oracle, SCENE, episodes=3)
    np.testing.assert_allclose(measured.values["error_sum_mm"], planned, rtol=1e-9)
    assert measured.decision_us == oracle.decision_us > 0       # the planner's own figure is carried, not re-timed
    again = TrajectoryOracle(SCENE, candidates=6, iterations=4, elites=2, restarts=1, from_rest=False)
    again.plan(expert, episodes=3)
    np.testing.assert_array_equal(again.actions, oracle.actions)


def test_the_oracle_keeps_each_episodes_best_start(expert):
    """Two restarts from the expert and one from rest, side by side: each start's search is the one it
    would run alone (its own generators: the first is the single search above bit for bit), the rest
    start begins at the no-force error, each episode keeps its best start's plan, and that plan replays
    to its error."""
    settings = {"candidates": 6, "iterations": 3, "elites": 2}
    oracle = TrajectoryOracle(SCENE, **settings)                   # restarts=2, from_rest=True
    planned = oracle.plan(expert, episodes=2)
    assert oracle.history_by_start.shape == (3, 4, 2)
    alone = TrajectoryOracle(SCENE, **settings, restarts=1, from_rest=False)
    alone.plan(expert, episodes=2)
    np.testing.assert_array_equal(oracle.history_by_start[0], alone.history_by_episode)
    other = TrajectoryOracle(SCENE, **settings, seed=1, restarts=1, from_rest=False)
    other.plan(expert, episodes=2)
    np.testing.assert_array_equal(oracle.history_by_start[1], other.history_by_episode)
    rest = evaluate(ReplayPolicy(np.zeros((2, 250, 4))), SCENE, episodes=2).values["error_sum_mm"]
    np.testing.assert_array_equal(oracle.history_by_start[2, 0], rest)
    np.testing.assert_array_equal(oracle.history_by_episode, oracle.history_by_start.min(axis=0))
    np.testing.assert_array_equal(planned, oracle.history_by_start[:, -1].min(axis=0))
    assert np.all(planned <= alone.history_by_episode[-1])
    np.testing.assert_allclose(evaluate(oracle, SCENE, episodes=2).values["error_sum_mm"], planned, rtol=1e-9)


def test_the_oracle_plans_the_targets_its_scene_overrides_name(expert):
    """plan(..., task={"split": "train"}) searches the training targets (the offline datasets' episodes):
    its errors are what the plan scores there, and the expert's training-target errors its warm start."""
    train = {"task": {"split": "train"}}
    oracle = TrajectoryOracle(SCENE, candidates=4, iterations=2, elites=1)
    planned = oracle.plan(expert, 2, [0, 1], **train)
    assert oracle.history[0] == pytest.approx(evaluate(expert, SCENE, 2, [0, 1], **train).values["error_sum_mm"].mean())
    np.testing.assert_allclose(evaluate(ReplayPolicy(oracle.actions), SCENE, 2, [0, 1], **train).values["error_sum_mm"],
                               planned, rtol=1e-9)
    on_test = evaluate(ReplayPolicy(oracle.actions), SCENE, 2, [0, 1]).values["error_sum_mm"]
    assert not np.allclose(on_test, planned, rtol=1e-3)


def test_evaluate_sums_each_episodes_reward(expert):
    """values["return"] is the episode's summed reward: summed again here over a single env's steps."""
    recorder = RecordingPolicy(expert)
    returns = evaluate(recorder, SCENE, 2).values["return"]
    env_id, kwargs = scene_kwargs(SCENE)
    env = gym.make(env_id, **kwargs)
    for i, seed in enumerate((1000, 1001)):
        env.reset(seed=seed)
        total = sum(float(env.step(step[i])[1]) for step in recorder.actions)
        assert total == pytest.approx(returns[i], rel=1e-9)


def test_the_oracle_refuses_bad_settings():
    for kwargs, match in (({"candidates": 1}, "candidates=1"), ({"elites": 16}, "elites=16 must be below candidates=16"),
                          ({"sigma": float("nan")}, "sigma=nan"), ({"knot_every": 0}, "knot_every=0"),
                          ({"iterations": 2.5}, "iterations=2.5"), ({"restarts": -1}, "restarts=-1"),
                          ({"from_rest": 1}, "from_rest=1: must be True or False"),
                          ({"restarts": 0, "from_rest": False}, "leaves no search")):
        with pytest.raises(ValueError, match=match):
            TrajectoryOracle(SCENE, **kwargs)


def test_replay_refuses_a_batch_of_another_size():
    with pytest.raises(ValueError, match="a batch of 2 rows; the plan has 3 episodes"):
        ReplayPolicy(np.zeros((3, 5, 4))).predict(np.zeros((2, 7)))
