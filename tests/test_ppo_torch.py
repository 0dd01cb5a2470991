"""baselines/ppo_torch.py: a short CPU run learns, is reproducible, and its weights load back safely."""

import gymnasium as gym
import numpy as np
import pytest

torch = pytest.importorskip("torch")

from softenv.baselines.evaluate import evaluate, scene_kwargs  # noqa: E402
from softenv.baselines.policies import make_baseline  # noqa: E402
from softenv.baselines.ppo_torch import Args, TorchPolicy, load, main, save, train  # noqa: E402
from softenv.envs.config import make_config  # noqa: E402
from softenv.envs.world import World  # noqa: E402

SHORT = {"total_timesteps": 16 * 64 * 12, "num_steps": 64}


@pytest.fixture(scope="module")
def trained():
    torch.set_num_threads(1)
    args = Args(seed=0, **SHORT)
    agent, run = train(args, log=lambda line: None)
    return args, agent, run


def test_a_short_run_on_cpu_tensors_learns_to_press(trained):
    """12 updates (12k env steps) already beat the random policy on the test targets, by far."""
    args, agent, run = trained
    assert run["env_steps"] == 16 * 64 * 12 and run["steps_per_s"] > 0
    _assert_beats_random(agent)


def _assert_beats_random(agent):
    kwargs = scene_kwargs("SoftSphere-v0")[1]
    kwargs.pop("obs_mode")
    random = evaluate(make_baseline("random", World(make_config(**kwargs))), "SoftSphere-v0", episodes=20)
    ppo = evaluate(TorchPolicy(agent), "SoftSphere-v0", episodes=20)
    assert ppo.values["error_sum_mm"].mean() < 0.7 * random.values["error_sum_mm"].mean()


def test_training_on_host_drawn_targets_learns_as_well():
    """The numpy generators' targets (the numpy twin's episodes) instead of the device draw."""
    agent, _ = train(Args(seed=0, target_draw="host", **SHORT), log=lambda line: None)
    _assert_beats_random(agent)


def test_the_same_seed_trains_the_same_weights(trained):
    args, agent, _ = trained
    again, _ = train(Args(seed=0, **SHORT), log=lambda line: None)
    for (name, a), b in zip(agent.state_dict().items(), again.state_dict().values()):
        assert torch.equal(a, b), name


def test_weights_load_back_and_mismatches_are_refused(trained, tmp_path):
    args, agent, _ = trained
    path = tmp_path / "ppo-torch-0.pt"
    save(agent, args, path)
    obs = np.random.default_rng(0).uniform(-1, 1, (5, agent.norm.mean.shape[0])).astype(np.float32)
    np.testing.assert_array_equal(TorchPolicy(load(path, "SoftSphere-v0")).predict(obs), TorchPolicy(agent).predict(obs))
    with pytest.raises(ValueError, match="trained on scene 'SoftSphere-v0', not 'SoftSphereProcedure-v0'"):
        load(path, "SoftSphereProcedure-v0")
    assert load(path, "SoftSphere-v0", args) is not None                 # a run to reuse: same settings and simulator
    with pytest.raises(ValueError, match=r"other settings: gamma=0.95 \(asked 0.9\)"):
        load(path, "SoftSphere-v0", Args(seed=0, gamma=0.9, **SHORT))
    data = torch.load(path, weights_only=True)
    for part, changed in (("dynamics", "0" * 64), ("libraries", {**data["fingerprint"]["libraries"], "torch": "0.1"})):
        torch.save({**data, "fingerprint": {**data["fingerprint"], part: changed}}, path)
        with pytest.raises(ValueError, match="trained on another simulator or other libraries"):
            load(path, "SoftSphere-v0", args)
        load(path, "SoftSphere-v0")                                         # to evaluate, any simulator will do
    data["format_version"] = 99
    torch.save(data, path)
    with pytest.raises(ValueError, match="format_version=99"):
        load(path, "SoftSphere-v0")


def test_compare_runs_ppo_torch_on_the_ideal_scenes_and_says_where(tmp_path):
    from softenv.baselines.benchmark import Plan, run

    plan = Plan(["SoftSphere-v0"], ["zero"], ["ppo-torch"], {"SoftSphere-v0": 1}, {"ppo-torch": 16 * 128 * 2}, episodes=5)
    lines = []
    summaries = run(plan, tmp_path, tmp_path / "runs", "softenv compare --test", echo=lines.append)
    row = next(s for s in summaries if s["policy"] == "ppo-torch")
    device = "cuda" if torch.cuda.is_available() else "cpu"
    assert row["kind"] == f"agent (4,096 steps, torch on {device})" and row["episodes"] == 5
    assert (tmp_path / "runs" / "SoftSphere-v0" / "ppo-torch-0" / "ppo-torch.pt").exists()
    assert torch.cuda.is_available() or any("no GPU in this process" in line for line in lines)


@pytest.mark.parametrize("scene", ["SoftSphereHaptic-v0", "SoftSphereHapticProcedure-v0"])
def test_ppo_torch_trains_on_the_laryngoscope_scenes(scene, tmp_path):
    """The torch twin steps the laryngoscope, so the torch PPO trains on both haptic ids (two updates
    here), sees the device's observation, and its weights load back for that scene only."""
    args = Args(scene=scene, seed=0, num_envs=8, num_steps=32, total_timesteps=8 * 32 * 2)
    agent, run = train(args, log=lambda line: None)
    assert run["env_steps"] == 8 * 32 * 2
    assert agent.norm.mean.shape[0] == gym.make(f"softenv:{scene}").observation_space.shape[0]
    save(agent, args, tmp_path / "a.pt")
    result = evaluate(TorchPolicy(load(tmp_path / "a.pt", scene)), scene, episodes=2)
    assert np.isfinite(result.values["error_sum_mm"]).all()
    with pytest.raises(ValueError, match=f"trained on scene '{scene}'"):
        load(tmp_path / "a.pt", "SoftSphere-v0")


def test_the_command_line_sets_the_batch_shape_and_reports_it(tmp_path):
    report = tmp_path / "ppo.md"
    main(["--seeds", "0", "--num-envs", "8", "--num-steps", "16", "--minibatch-size", "64", "--update-epochs", "1",
          "--total-timesteps", "384", "--episodes", "3", "--report", str(report)])
    text = report.read_text()
    assert "--num-envs 8 --num-steps 16 --minibatch-size 64" in text       # the command, as typed
    assert "| 0 | " in text and "| 384 |" in text                           # 3 rollouts of 8 envs x 16 steps
    from softenv.bench.timing import code_revision
    assert f"--report {report}` at {code_revision()} (" in text              # and the code that made it


@pytest.mark.parametrize("field,value", [("num_envs", 0), ("num_steps", -1), ("minibatch_size", 0),
                                         ("update_epochs", 0), ("total_timesteps", 100)])
def test_a_batch_shape_that_cannot_train_is_refused_by_name(field, value):
    with pytest.raises(ValueError, match=f"{field}={value}"):
        train(Args(**{field: value}), log=lambda line: None)


@pytest.mark.parametrize("compile_env", [False, True])
def test_a_device_this_process_cannot_use_is_refused_by_name(compile_env):
    """With ``--compile-env`` the device picks the compile mode before the env is made; it is checked there too."""
    with pytest.raises(ValueError, match="torch_device='gpu' is not a torch device usable here"):
        train(Args(device="gpu", compile_env=compile_env), log=lambda line: None)


@pytest.mark.parametrize("device", ["cpu"] + (["cuda"] if torch.cuda.is_available() else []))
def test_a_compiled_env_step_trains_as_the_eager_one(trained, device):
    """``--compile-env``: the same run with the env's step compiled (``compile_options``; on a GPU also
    recorded as the env's CUDA graphs). Inductor rounds some float32 sums in another order, so the weights
    drift by rounding only (5e-7 after 12 rollouts on CPU), where a wrong compiled step (stale state, a lost
    autoreset, an output overwritten too soon) would change them by orders of magnitude more."""
    args, agent, _ = trained
    if device != "cpu":
        agent, _ = train(Args(seed=0, device=device, **SHORT), log=lambda line: None)
    compiled, _ = train(Args(seed=0, device=device, compile_env=True, **SHORT), log=lambda line: None)
    eager, other = agent.state_dict(), compiled.state_dict()
    assert max(float((eager[k] - other[k]).abs().max()) for k in eager) < 1e-4
