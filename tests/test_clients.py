"""The RL clients researchers use, run the way a user runs them: rl-zoo3 with every shipped YAML,
TorchRL, SB3 subprocess workers and evaluation, Gymnasium's async vector env and RecordVideo; and
the executor behind ``softenv compare --jobs / --executor ray``."""

from __future__ import annotations

import importlib.util
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import softenv  # noqa: F401  (registers the ids for the in-process tests)
from softenv.envs.config import UnknownSectionError

ROOT = Path(__file__).resolve().parent.parent
HYPERPARAMS = ROOT / "baselines" / "hyperparams"
TEST_SPLIT = "task:dict(split='test')"


# -- rl-zoo3 -------------------------------------------------------------------------------------

@pytest.mark.parametrize("algo, yaml, extra", [
    ("sac", "sac.yml", []), ("td3", "td3.yml", []), ("ppo", "ppo.yml", []),
    # rl-zoo3 builds its eval env from --eval-env-kwargs alone once they are given, so HER's are repeated
    ("sac", "her.yml", ["obs_mode:'dict'"]),
])
def test_rl_zoo3_trains_and_evaluates_on_test_targets_with_each_shipped_yaml(tmp_path, algo, yaml, extra):
    # not imported here: importing rl_zoo3 replaces Gymnasium's TimeLimit in the whole process
    if importlib.util.find_spec("rl_zoo3") is None:
        pytest.skip("rl_zoo3 is not installed (pip install 'softenv[clients]')")
    logs = tmp_path / "logs"
    cmd = [sys.executable, "-m", "rl_zoo3.train", "--algo", algo, "--env", "SoftSphere-v0", "--gym-packages", "softenv",
           "--conf-file", str(HYPERPARAMS / yaml), "-n", "300", "--eval-freq", "150", "--eval-episodes", "2",
           "--n-eval-envs", "1", "-f", str(logs), "--seed", "0", "--eval-env-kwargs", TEST_SPLIT, *extra]
    out = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    run = logs / algo / "SoftSphere-v0_1"
    assert (run / "SoftSphere-v0.zip").is_file()
    with np.load(run / "evaluations.npz") as data:
        assert data["results"].shape[1] == 2 and np.isfinite(data["results"]).all()
    if yaml == "her.yml":          # the YAML's env_kwargs reached the training env: dict observations
        from stable_baselines3.common.save_util import load_from_zip_file

        data, _, _ = load_from_zip_file(run / "SoftSphere-v0.zip", device="cpu")
        assert isinstance(data["observation_space"], gym.spaces.Dict)
        enjoy = [sys.executable, "-m", "rl_zoo3.enjoy", "--algo", algo, "--env", "SoftSphere-v0", "--gym-packages",
                 "softenv", "-f", str(logs), "-n", "50", "--no-render", "--env-kwargs", TEST_SPLIT, "obs_mode:'dict'"]
        out = subprocess.run(enjoy, capture_output=True, text=True, cwd=tmp_path, timeout=300)
        assert out.returncode == 0, out.stderr[-3000:]


def test_agents_take_the_observation_mode_from_the_yaml_not_the_algorithm():
    pytest.importorskip("stable_baselines3")
    from softenv.baselines.agents import agent_env_kwargs, hyperparams

    assert hyperparams("sac-her", "SoftSphere-v0")["env_kwargs"] == {"obs_mode": "dict"}
    env_id, kwargs = agent_env_kwargs("sac-her", "SoftSphere-v0/stiffening", split="train")
    assert (env_id, kwargs["obs_mode"], kwargs["tissue"], kwargs["task"]) == \
        ("SoftSphere-v0", "dict", {"law": "stiffening"}, {"split": "train"})
    assert agent_env_kwargs("sac", "SoftSphere-v0")[1]["obs_mode"] == "vector"


# -- unknown keywords: Python's TypeError form, as TorchRL expects --------------------------------

@pytest.mark.parametrize("make", [
    lambda: gym.make("SoftSphere-v0", frameskip=4),
    lambda: gym.make_vec("SoftSphere-v0", 2, vectorization_mode="vector_entry_point", frameskip=4),
    lambda: gym.make("SoftSphereHaptic-v0", frameskip=4),
])
def test_an_unknown_keyword_is_a_type_error_of_the_usual_form_that_lists_the_sections(make):
    with pytest.raises(TypeError, match="unexpected keyword argument 'frameskip'") as err:
        make()
    assert isinstance(err.value, ValueError) and isinstance(err.value, UnknownSectionError)
    assert "tissue" in str(err.value) and "reward" in str(err.value)


def test_torchrl_gym_env_passes_its_spec_check_and_reads_info_through_numpy_info():
    pytest.importorskip("torchrl")
    import torch
    from torchrl.data import Unbounded
    from torchrl.envs import GymEnv, GymWrapper
    from torchrl.envs.libs.gym import default_info_dict_reader
    from torchrl.envs.utils import check_env_specs

    from softenv.envs import NumpyInfo

    env = GymEnv("softenv:SoftSphere-v0")                 # TorchRL drops frameskip after our TypeError
    check_env_specs(env)
    assert env.rollout(4)["next", "observation"].shape == (4, 64)
    env = GymWrapper(NumpyInfo(gym.make("softenv:SoftSphere-v0")))
    env.set_info_dict_reader(default_info_dict_reader(
        ["is_success", "normalized_score"], spec=[Unbounded((), dtype=torch.bool), Unbounded((), dtype=torch.float64)]))
    check_env_specs(env)
    rollout = env.rollout(4)
    assert rollout["next", "normalized_score"].shape == (4,) and torch.isfinite(rollout["next", "normalized_score"]).all()
    assert rollout["next", "is_success"].dtype == torch.bool


def test_numpy_info_turns_every_info_value_into_an_array_of_the_same_value():
    from softenv.envs import NumpyInfo

    plain, wrapped = gym.make("SoftSphere-v0"), NumpyInfo(gym.make("SoftSphere-v0"))
    plain.reset(seed=3)
    wrapped.reset(seed=3)
    action = np.array([0.2, -0.1, 0.4, 0.3], np.float32)
    info, info_np = plain.step(action)[-1], wrapped.step(action)[-1]
    assert set(info) == set(info_np)
    for key, value in info.items():
        assert isinstance(info_np[key], np.ndarray) and info_np[key].shape == () and info_np[key].item() == value


# -- subprocess workers: the "softenv:" prefix imports softenv in every worker -------------------

def test_sb3_subprocess_workers_with_the_prefixed_id_match_in_process_envs():
    pytest.importorskip("stable_baselines3")
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    actions = np.random.default_rng(0).uniform(-1, 1, (5, 2, 4)).astype(np.float32)
    rollouts = []
    for cls in (SubprocVecEnv, DummyVecEnv):
        venv = make_vec_env("softenv:SoftSphere-v0", n_envs=2, seed=11, vec_env_cls=cls)
        obs = [venv.reset()]
        for a in actions:
            obs.append(venv.step(a)[0])
        venv.close()
        rollouts.append(np.stack(obs))
    np.testing.assert_array_equal(rollouts[0], rollouts[1])


def test_async_vector_env_with_spawn_workers_and_the_prefixed_id():
    envs = gym.make_vec("softenv:SoftSphere-v0", num_envs=2, vectorization_mode="async", vector_kwargs={"context": "spawn"})
    twin = gym.make_vec("SoftSphere-v0", num_envs=2, vectorization_mode="vector_entry_point")
    try:
        obs, _ = envs.reset(seed=5)
        ref, _ = twin.reset(seed=5)
        np.testing.assert_array_equal(obs, ref)
        a = np.full((2, 4), 0.3, np.float32)
        np.testing.assert_array_equal(envs.step(a)[1], twin.step(a)[1])
    finally:
        envs.close()


# -- SB3: the adapter's infos and the held-out split in evaluation -------------------------------

def test_sb3_adapter_infos_equal_the_single_envs_infos_step_by_step():
    pytest.importorskip("stable_baselines3")
    from softenv.envs.sb3 import SoftSphereSB3VecEnv

    # success ends episodes at different steps, so some envs reset while others run
    scene = {"task": {"terminate_on_success": True, "tolerance": 0.6, "horizon": 12}}
    n = 4
    adapter = SoftSphereSB3VecEnv(n, info_keys="all", **scene)
    adapter.seed(20)
    adapter.reset()
    singles = [gym.make("SoftSphere-v0", **scene).unwrapped for _ in range(n)]
    for i, env in enumerate(singles):
        env.reset(seed=20 + i)
    rng = np.random.default_rng(1)
    ended = 0
    for _ in range(30):
        a = rng.uniform(-1, 1, (n, 4)).astype(np.float32)
        obs, rewards, dones, infos = adapter.step(a)
        for i, env in enumerate(singles):
            o, r, term, trunc, info = env.step(a[i])
            assert infos[i].keys() - {"terminal_observation", "TimeLimit.truncated"} == info.keys()
            assert all(infos[i][k] == v and type(infos[i][k]) is type(v) for k, v in info.items())
            assert rewards[i] == np.float32(r) and dones[i] == (term or trunc)
            if term or trunc:
                ended += 1
                np.testing.assert_array_equal(infos[i]["terminal_observation"], o)
                assert infos[i]["TimeLimit.truncated"] == (trunc and not term)
                o, _ = env.reset()
            np.testing.assert_array_equal(obs[i], o)
    assert ended >= n


def test_eval_callback_scores_the_test_targets_when_asked_to():
    pytest.importorskip("stable_baselines3")
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import EvalCallback
    from stable_baselines3.common.env_util import make_vec_env

    eval_env = make_vec_env("softenv:SoftSphere-v0", n_envs=1, env_kwargs={"task": {"split": "test"}})
    world = eval_env.envs[0].unwrapped.world
    model = PPO("MlpPolicy", make_vec_env("softenv:SoftSphere-v0", n_envs=1), n_steps=64, batch_size=64, n_epochs=1,
                seed=0, device="cpu")
    model.learn(128, callback=EvalCallback(eval_env, n_eval_episodes=2, eval_freq=64, verbose=0))
    test_cells = {tuple(c) for c in world.family.cells}
    features = eval_env.envs[0].unwrapped.target_features
    assert world.family.split == "test"
    assert all(tuple(c) in test_cells for c in world.family.cell_of(features[:1]))


# -- Gymnasium's RecordVideo --------------------------------------------------------------------

def test_record_video_writes_an_episode(tmp_path):
    pytest.importorskip("moviepy")
    pytest.importorskip("matplotlib")
    env = gym.wrappers.RecordVideo(gym.make("softenv:SoftSphere-v0", render_mode="rgb_array", task={"horizon": 8}),
                                   str(tmp_path / "videos"), episode_trigger=lambda episode: True, disable_logger=True)
    env.reset(seed=0)
    done = False
    while not done:
        *_, terminated, truncated, _ = env.step(env.action_space.sample())
        done = terminated or truncated
    env.close()
    videos = list((tmp_path / "videos").glob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 1000


# -- the executor --------------------------------------------------------------------------------

def _square(x: int) -> int:
    return x * x


def _fail_once(marker: str, value: int) -> int:
    """Fails on its first call (the marker file does not exist yet), succeeds on the retry."""
    path = Path(marker)
    if not path.exists():
        path.write_text("tried")
        raise RuntimeError("transient failure")
    return value


def _die_once(marker: str, value: int) -> int:
    """Kills its own worker process on its first call (as a lost machine would); returns on the retry."""
    path = Path(marker)
    if not path.exists():
        path.write_text("killed")
        os.kill(os.getpid(), signal.SIGKILL)
    return value


def _always_fail(value: int) -> int:
    raise ValueError(f"bad job {value}")


def _jobs(tmp_path: Path, tag: str) -> list:
    from softenv.parallel import Job

    return [Job("a", _square, (3,)), Job("flaky", _fail_once, (str(tmp_path / f"marker-{tag}"), 7)),
            Job("broken", _always_fail, (5,)), Job("b", _square, (4,))]


@pytest.mark.parametrize("executor, n_jobs", [("local", 1), ("local", 2)])
def test_executor_retries_reports_failures_and_keeps_the_order(tmp_path, executor, n_jobs):
    from softenv.parallel import run_jobs

    lines: list[str] = []
    results = run_jobs(_jobs(tmp_path, f"{executor}{n_jobs}"), executor, n_jobs, retries=2, echo=lines.append)
    assert [r.key for r in results] == ["a", "flaky", "broken", "b"]
    assert [r.value for r in results if r.ok] == [9, 7, 16]
    assert results[1].attempts == 2 and results[1].ok
    assert not results[2].ok and results[2].attempts == 3 and results[2].error == "ValueError: bad job 5"
    assert len(lines) == 4 and lines[-1].startswith("[4/4 jobs")
    assert sum("FAILED" in line for line in lines) == 1


def test_executor_rejects_bad_arguments():
    from softenv.parallel import Job, run_jobs

    with pytest.raises(ValueError, match="executor='dask'"):
        run_jobs([], "dask")
    with pytest.raises(ValueError, match=r"jobs=0 must be an int in \[1, 4096\]"):
        run_jobs([], "local", 0)
    with pytest.raises(ValueError, match="repeated: a"):
        run_jobs([Job("a", _square, (1,)), Job("a", _square, (2,))])


def _tiny_plan():
    from softenv.baselines.benchmark import Plan

    return Plan(["SoftSphere-v0"], ["zero", "direct-poly3"], ["sac"], {"SoftSphere-v0": 2}, {"sac": 1100}, episodes=8)


def _cells(summaries: list[dict]) -> str:
    """Every number but the measured decision times, as text (NaN equals NaN there, bit for bit otherwise)."""
    return json.dumps([{k: v for k, v in s.items() if k != "decision_us"} for s in summaries], sort_keys=True)


@pytest.fixture(scope="module")
def local_grid(tmp_path_factory):
    pytest.importorskip("stable_baselines3")
    from softenv.baselines.benchmark import run

    runs = tmp_path_factory.mktemp("runs-local")
    return run(_tiny_plan(), runs, runs, "test", echo=lambda s: None, write=False)


def test_compare_over_two_local_workers_equals_one_process(tmp_path, local_grid):
    from softenv.baselines.benchmark import run

    parallel = run(_tiny_plan(), tmp_path, tmp_path / "runs", "test", echo=lambda s: None, write=False, n_jobs=2)
    assert _cells(parallel) == _cells(local_grid)
    assert [s["policy"] for s in parallel] == ["zero", "direct-poly3", "sac"]


def test_compare_on_a_local_ray_instance_equals_the_local_executor(tmp_path, local_grid):
    ray = pytest.importorskip("ray")
    from softenv.baselines.benchmark import run

    os.environ.pop("RAY_ADDRESS", None)
    with_ray = run(_tiny_plan(), tmp_path, tmp_path / "runs", "test", echo=lambda s: None, write=False,
                   executor="ray", n_jobs=2)
    assert not ray.is_initialized()                        # the run shut down the instance it started
    assert _cells(with_ray) == _cells(local_grid)


def test_ray_executor_retries_and_reports_failures(tmp_path):
    ray = pytest.importorskip("ray")
    from softenv.parallel import run_jobs

    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])     # Ray workers cannot import a test file

    results = run_jobs(_jobs(tmp_path, "ray"), "ray", 2, retries=1, echo=None)
    assert [r.value for r in results if r.ok] == [9, 7, 16]
    assert results[1].attempts == 2 and not results[2].ok and results[2].attempts == 2


def test_a_ray_worker_killed_mid_job_is_run_again_by_ray(tmp_path):
    ray = pytest.importorskip("ray")
    from softenv.parallel import Job, run_jobs

    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
    os.environ.pop("RAY_ADDRESS", None)
    jobs = [Job("a", _square, (3,)), Job("killed", _die_once, (str(tmp_path / "marker"), 7)), Job("b", _square, (4,)),
            Job("niceness", os.nice, (0,))]
    results = run_jobs(jobs, "ray", 2, retries=1, echo=None)
    assert (tmp_path / "marker").read_text() == "killed"          # its first worker did die
    # the last: a local instance's workers run at this process's priority (Ray's default niceness is 15)
    assert [r.value for r in results] == [9, 7, 16, os.nice(0)] and all(r.ok for r in results)


def test_softenv_data_over_two_workers_writes_the_same_data_sets(tmp_path, capsys):
    from softenv.cli import main
    from softenv.datasets import ForceShapeData

    args = ["data", "--points", "441", "--laws", "linear", "stiffening", "--magnitudes", "3"]
    assert main([*args, "--out", str(tmp_path / "one")]) == 0
    assert main([*args, "--jobs", "2", "--out", str(tmp_path / "two")]) == 0
    assert "[2/2 jobs" in capsys.readouterr().err
    for name in ("paper-441pts-10def-linear.npz", "paper-441pts-10def-stiffening.npz"):
        one, two = ForceShapeData.load(tmp_path / "one" / name), ForceShapeData.load(tmp_path / "two" / name)
        np.testing.assert_array_equal(one.shapes, two.shapes)
        np.testing.assert_array_equal(one.forces, two.forces)


def test_sb3_adapter_info_keys_keep_what_is_asked_and_refuse_unknown_keys():
    pytest.importorskip("stable_baselines3")
    from softenv.envs.sb3 import SoftSphereSB3VecEnv

    scene = {"task": {"horizon": 2}}
    full, slim = SoftSphereSB3VecEnv(2, info_keys="all", **scene), SoftSphereSB3VecEnv(2, **scene)   # default: SB3's
    for venv in (full, slim):
        venv.seed(3)
        venv.reset()
    a = np.full((2, 4), 0.5, np.float32)
    (_, _, _, infos_full), (_, _, _, infos) = full.step(a), slim.step(a)
    assert [set(i) for i in infos] == [{"is_success"}] * 2
    assert [i["is_success"] for i in infos] == [i["is_success"] for i in infos_full]
    _, _, dones, infos = slim.step(a)                  # horizon 2: the episode ends, SB3's keys come along
    assert dones.all() and all({"is_success", "terminal_observation", "TimeLimit.truncated"} == set(i) for i in infos)
    unknown = SoftSphereSB3VecEnv(2, info_keys=("score",))
    unknown.reset()
    with pytest.raises(ValueError, match=r"info_keys \['score'\] are not info keys"):
        unknown.step(a)
    with pytest.raises(ValueError, match=r"info_keys='every' must be 'all' or a sequence"):
        SoftSphereSB3VecEnv(2, info_keys="every")
    two = SoftSphereSB3VecEnv(2, info_keys=("normalized_score", "force_N"), **scene)
    two.seed(3)
    two.reset()
    assert [set(i) for i in two.step(a)[3]] == [{"normalized_score", "force_N"}] * 2
