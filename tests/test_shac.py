"""SHAC, the first-order agent (baselines/shac.py): its TD(lambda) targets against the sums written out, its
window's gradient through the differentiable twin against central differences, learning, determinism,
its saved file, bad arguments, and its cell in ``softenv compare``."""

import copy
import json

import gymnasium as gym
import numpy as np
import pytest
import torch

from softenv.baselines import shac
from softenv.baselines.benchmark import Plan, run
from softenv.baselines.evaluate import evaluate, scene_kwargs
from softenv.baselines.policies import ZeroPolicy
from softenv.envs.config import make_config
from softenv.envs.world import World


def test_lambda_returns_are_the_td_lambda_sums():
    """Two envs, three steps, gamma 0.9, lambda 0.5: env 0 runs through the window (bootstrapped from the
    last value), env 1's episode ends at step 0 (no return crosses it)."""
    r = torch.tensor([[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]])
    v = torch.tensor([[10.0, 20.0], [30.0, 40.0], [50.0, 60.0]])
    ends = torch.tensor([[False, True], [False, False], [False, False]])
    g, lam = 0.9, 0.5
    got = shac.lambda_returns(r, v, ends, g, lam)
    # G_t = r_t + g ((1 - lam) V(s_t+1) + lam G_t+1), V(s_t+1) = v[t]; the window's last G_t = r_t + g v[t]
    last0 = 5 + g * 50
    mid0 = 3 + g * ((1 - lam) * 30 + lam * last0)
    first0 = 1 + g * ((1 - lam) * 10 + lam * mid0)
    last1 = 6 + g * 60
    mid1 = 4 + g * ((1 - lam) * 40 + lam * last1)
    first1 = 2 + g * 20                                    # its episode ended: its own value only
    want = torch.tensor([[first0, first1], [mid0, mid1], [last0, last1]])
    assert torch.allclose(got, want, rtol=1e-6)
    one_step = shac.lambda_returns(r, v, ends, g, 0.0)     # lambda 0: one-step TD targets
    assert torch.allclose(one_step, r + g * v)


def test_a_windows_gradient_through_the_simulator_matches_central_differences():
    """The actor loss of a window of 6 steps on 3 envs of SoftSphere-v0 (float64 twin and nets; observations are
    float32, so the differences take a step of 1e-4): its gradient with respect to the actor's output bias,
    back through every step and observation, against central differences of the same window."""
    args = shac.ShacArgs(num_envs=3, horizon=6)
    env_id, kwargs = scene_kwargs("SoftSphere-v0")
    env = gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point", backend="torch",
                       dtype=torch.float64, check_actions=False, autoreset_mode="same_step", differentiable=True,
                       **kwargs)
    torch.manual_seed(0)
    agent = shac.ShacAgent(env.single_observation_space.shape[0], 4, [8, 8]).double()
    with torch.no_grad():
        agent.actor[-1].weight.mul_(5.0)                   # actions away from zero, inside tanh's smooth middle
    target = copy.deepcopy(agent.critic)

    def loss() -> torch.Tensor:
        obs, _ = env.reset(seed=3)
        return shac.window(agent, target, env, obs, args, torch.Generator().manual_seed(1)).loss

    bias = agent.actor[-1].bias
    agent.zero_grad()
    loss().backward()
    grad = bias.grad.clone()
    numeric = torch.zeros(4, dtype=torch.float64)
    for i in range(4):
        with torch.no_grad():
            bias[i] += 1e-4
            up = float(loss())
            bias[i] -= 2e-4
            down = float(loss())
            bias[i] += 1e-4
        numeric[i] = (up - down) / 2e-4
    assert torch.abs(grad).min() > 1e-2                    # the loss depends on every action component
    assert torch.allclose(grad, numeric, rtol=1e-3, atol=1e-4 * float(torch.abs(numeric).max()))


def test_shac_learns_reproducibly_and_saves_what_it_learned(tmp_path):
    """10,240 env steps on SoftSphere-v0 take its test return from its first evaluation's to well above the
    zero policy's; the same seed trains the same weights bit for bit; the file loads back only for its settings."""
    args = shac.ShacArgs(total_timesteps=16 * 32 * 20, evaluations=4, eval_episodes=10)
    agent, run_info = shac.train(args, tmp_path / "run", log=lambda line: None)
    steps, returns = run_info["curve"]
    kwargs = scene_kwargs("SoftSphere-v0")[1]
    kwargs.pop("obs_mode")
    zero = evaluate(ZeroPolicy(World(make_config(**kwargs))), "SoftSphere-v0", 10).values["return"].mean()
    assert list(steps) == [2560, 5120, 7680, 10240] and returns[-1] > returns[0] and returns[-1] > zero + 10
    with np.load(tmp_path / "run" / "eval" / "evaluations.npz") as log:
        assert log["timesteps"].tolist() == list(steps) and np.allclose(log["results"].mean(axis=1), returns)

    again, _ = shac.train(copy.deepcopy(args), None, log=lambda line: None)
    for a, b in zip(agent.state_dict().values(), again.state_dict().values()):
        assert torch.equal(a, b)

    path = tmp_path / "shac.pt"
    shac.save(agent, args, path)
    assert shac.train_seconds(path) is None                 # saved without the record
    shac.save(agent, args, path, train_seconds=12.5)
    loaded = shac.load(path, args)                          # the record is not a setting
    assert shac.train_seconds(path) == 12.5
    obs = torch.randn(5, len(agent.norm.mean))
    assert torch.equal(loaded.deterministic(obs), agent.deterministic(obs))
    with pytest.raises(ValueError, match="was trained with"):
        shac.load(path, shac.ShacArgs(total_timesteps=999_999))
    data = torch.load(path, weights_only=True)
    torch.save({**data, "fingerprint": {**data["fingerprint"], "dynamics": "0" * 64}}, path)
    with pytest.raises(ValueError, match="trained on another simulator or other libraries"):
        shac.load(path, args)


@pytest.mark.parametrize("change, message", [({"scene": "Nope-v0"}, "scene='Nope-v0'"),
                                             ({"horizon": 0}, "horizon=0: give a whole number >= 1"),
                                             ({"gamma": 1.5}, r"gamma=1.5: give a number in \[0, 1\]"),
                                             ({"total_timesteps": 10}, "total_timesteps=10: give at least one window")])
def test_bad_arguments_are_refused_by_name(change, message):
    with pytest.raises(ValueError, match=message):
        shac.train(shac.ShacArgs(**change), log=lambda line: None)


def test_compare_trains_shac_on_request_with_its_learning_curve(tmp_path):
    plan = Plan(["SoftSphere-v0"], ["zero"], ["shac"], {"SoftSphere-v0": 1}, {"shac": 16 * 32 * 2}, episodes=3)
    run(plan, tmp_path, tmp_path / "runs", "test", echo=lambda s: None)
    report = json.loads((tmp_path / "benchmark.json").read_text())
    cell = next(s for s in report["summaries"] if s["policy"] == "shac")
    assert cell["kind"] == "agent (1,024 steps, first-order)" and np.array(cell["episode_scores"]).shape == (1, 3)
    assert report["learning_curves"]["SoftSphere-v0 shac"][0]["env_steps"] == [512, 1024]   # one a window here
    saved = tmp_path / "runs" / "SoftSphere-v0" / "shac-0" / "shac.pt"
    [row] = report["convergence"]
    assert row["train_s_per_seed"] == shac.train_seconds(saved) > 0 and row["train_s_recorded"] == 1
