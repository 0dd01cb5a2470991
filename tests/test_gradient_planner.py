"""The gradient-based baseline (baselines.gradient_planner) and the laryngoscope's gradient through the
incisors that it needs."""

import gymnasium as gym
import numpy as np
import pytest
import torch

from softenv.baselines.anchors import scene_config
from softenv.baselines.evaluate import evaluate, scene_kwargs
from softenv.baselines.gradient_planner import EDGE, GradientPlanner
from softenv.baselines.planner import RecordingPolicy
from softenv.baselines.policies import ZeroPolicy, make_baseline
from softenv.envs.world import World

IDEAL = "SoftSphere-v0"
HAPTIC = "SoftSphereHaptic-v0"


def world_of(scene: str) -> World:
    return World(scene_config(scene))


def test_the_planner_improves_on_its_warm_start_and_replays_its_plan():
    """Never worse than the warm start on any episode, much better on average; the plan it keeps is what
    the evaluation then measures; its history never rises; the same settings give the same plan."""
    zero = ZeroPolicy(world_of(IDEAL))
    warm = evaluate(zero, IDEAL, episodes=2).values["error_sum_mm"]
    planner = GradientPlanner(IDEAL, restarts=2, iterations=16, lr=0.3)
    planned = planner.plan(zero, episodes=2)
    assert np.all(planned <= warm) and planned.mean() < 0.5 * warm.mean()
    assert np.all(np.diff(planner.history) <= 0)
    assert len(planner.elapsed) == len(planner.history) == 17      # a wall time for each entry of the history
    measured = evaluate(planner, IDEAL, episodes=2)
    np.testing.assert_allclose(measured.values["error_sum_mm"], planned, rtol=1e-9)
    assert measured.decision_us == planner.decision_us > 0
    again = GradientPlanner(IDEAL, restarts=2, iterations=16, lr=0.3)
    again.plan(zero, episodes=2)
    np.testing.assert_array_equal(again.actions, planner.actions)


def test_the_planner_keeps_the_warm_start_where_it_finds_nothing_better():
    """With no Adam step the only candidates are the warm start (held off the bounds by EDGE) and noisy
    copies of it: where none beats the warm start's own actions, those are the plan, unchanged."""
    expert = make_baseline("expert", world_of(HAPTIC))
    recorder = RecordingPolicy(expert)
    warm = evaluate(recorder, HAPTIC, episodes=1).values["error_sum_mm"]
    planner = GradientPlanner(HAPTIC, restarts=1, iterations=0)
    planned = planner.plan(expert, episodes=1)
    assert planned[0] <= warm[0]
    if planned[0] == warm[0]:
        np.testing.assert_array_equal(planner.actions[0], np.stack(recorder.actions, axis=1)[0])
    else:                                            # the EDGE-held copy of the warm start scored better
        assert np.abs(planner.actions[0]).max() <= EDGE + 1e-6


def test_the_laryngoscope_gradient_through_the_incisors_is_finite():
    """The expert's actions moved by noise lever the blade on the incisors: every action's gradient of the
    summed shape error is finite (Warp's adjoint of the collision's search and of Chipmunk's
    1 / (d + CPFLOAT_MIN) once formed NaN there, docs/gradients.md)."""
    seeds = [1000, 1001, 1002, 1003]
    recorder = RecordingPolicy(make_baseline("expert", world_of(HAPTIC)))
    evaluate(recorder, HAPTIC, len(seeds), seeds)
    base = np.stack(recorder.actions, axis=1).astype(np.float64)
    env_id, kwargs = scene_kwargs(HAPTIC)
    env = gym.make_vec(env_id, num_envs=len(seeds), vectorization_mode="vector_entry_point", backend="torch",
                       differentiable=True, **kwargs)
    noise = 0.5 * np.random.default_rng(0).standard_normal(base.shape)
    z = torch.tensor(np.arctanh(np.clip(base, -EDGE, EDGE)) + noise, requires_grad=True)
    env.reset(seed=seeds)
    loss, incisor = torch.zeros(len(seeds), dtype=torch.float64), np.zeros(len(seeds))
    for t in range(base.shape[1]):
        info = env.step(torch.tanh(z[:, t]))[4]
        loss = loss + info["shape_error_mm"]
        incisor = np.maximum(incisor, info["incisor_force_N"].detach().numpy())
    loss.sum().backward()
    assert (incisor > 0).sum() >= 2                   # the episodes lever on the teeth
    assert torch.isfinite(z.grad).all() and z.grad.abs().max() > 0


def test_the_planner_refuses_bad_settings():
    for kwargs, match in (({"restarts": 0}, "restarts=0"), ({"iterations": 2.5}, "iterations=2.5"),
                          ({"lr": float("nan")}, "lr=nan"), ({"sigma": 0.0}, "sigma=0.0"),
                          ({"restarts": True}, "restarts=True")):
        with pytest.raises(ValueError, match=match):
            GradientPlanner(IDEAL, **kwargs)
    with pytest.raises(ValueError, match="unknown scene 'nowhere'"):
        GradientPlanner("nowhere")


def test_compare_runs_the_gradient_planner_on_request(tmp_path):
    """``softenv compare --policies gradient``: the planner's row beside the others, its step size tuned on
    training targets, scored by the same anchors (above no force, below the exact oracle's 100)."""
    from softenv.baselines.benchmark import Plan, run
    from softenv.cli import main

    plan = Plan(["SoftSphere-v0"], ["zero", "gradient"], [], {"SoftSphere-v0": 1}, episodes=2)
    summaries = run(plan, tmp_path, tmp_path / "runs", "softenv compare --test", echo=lambda s: None)
    scores = {s["policy"]: s["normalized_score"]["mean"] for s in summaries}
    assert set(scores) == {"zero", "gradient"}
    assert scores["zero"] < 1.0 < 50.0 < scores["gradient"] <= 100.0 + 1e-6
    assert main(["compare", "--quick", "--policies", "gradient", "telepathy", "--agents", "--out", "/nonexistent"]) == 2
