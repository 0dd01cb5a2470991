"""The device contract (softenv.devices.base): every kind composes into the one env class and the one
vector env class, and a new device plugs in through the config alone (examples/probe_device.py)."""

import pickle
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env, data_equivalence

import softenv  # noqa: F401  (registers the ids)
from softenv.devices.base import Device, DeviceBatch, device_kind
from softenv.envs.single import SoftSphereEnv
from softenv.envs.vector import SoftSphereVectorEnv

PROBE = "probe_device:PROBE"
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


@pytest.fixture
def probe_on_path(monkeypatch):
    monkeypatch.syspath_prepend(str(EXAMPLES))


def same(a, b) -> bool:
    """Equal values, bit for bit up to the sign of zero (NaN equals NaN), whatever the container type."""
    return np.array_equal(np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64), equal_nan=True)


@pytest.mark.parametrize("kind", ["ideal", "laryngoscope", PROBE])
def test_every_kind_builds_both_forms_of_the_contract(kind, probe_on_path):
    single = gym.make("softenv:SoftSphere-v0", device={"kind": kind}).unwrapped
    batch = SoftSphereVectorEnv(2, device={"kind": kind})
    assert type(single) is SoftSphereEnv and isinstance(single.device, Device)
    assert isinstance(batch.device, DeviceBatch)
    names = device_kind(kind).obs_names
    assert single.device.obs_names == batch.device.obs_names == names
    assert single.observation_space.shape == (2 * single.world.k + len(names) + 4,)


def test_the_probe_plugs_in_through_the_config_alone_and_passes_both_checkers(probe_on_path):
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make("softenv:SoftSphereProcedure-v0", device={"kind": PROBE})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped)
        sb3_check_env(gym.make("softenv:SoftSphere-v0", device={"kind": PROBE}), warn=True)
    env.reset(seed=0)
    for _ in range(10):                                  # press in at full speed: the tongue pushes back
        _, _, _, _, info = env.step(np.array([0.0, 0.0, 1.0, 0.0], dtype=np.float32))
    law = env.unwrapped.device.law
    assert info["probe_depth_m"] == pytest.approx(min(10 * law.step, law.max_depth))
    assert 0.0 < info["force_N"] <= env.unwrapped.world.config["device"]["max_normal_force"]


@pytest.mark.parametrize("kind", ["ideal", PROBE, "laryngoscope"])
def test_the_vector_env_equals_single_envs_for_every_kind(kind, probe_on_path):
    """Three envs stepped together against three single envs seeded alike, through autoresets: the same
    observations, rewards, flags and infos, bit for bit (the laryngoscope: env 0 only, see its docs)."""
    n, steps = 3, 30
    scene = {"device": {"kind": kind}, "task": {"horizon": 12}}
    actions = np.random.default_rng(0).uniform(-1, 1, (steps, n, 4)).astype(np.float32)
    vec = SoftSphereVectorEnv(n, autoreset_mode="same_step", **scene)
    obs, _ = vec.reset(seed=7)
    vec_trace = [(obs, None)]
    for a in actions:
        obs, reward, term, trunc, info = vec.step(a)
        vec_trace.append((obs, reward, term, trunc, info))
    for i in range(n if kind != "laryngoscope" else 1):
        env = SoftSphereEnv(**scene)
        obs, _ = env.reset(seed=7 + i)
        assert np.array_equal(obs, vec_trace[0][0][i])
        for t, a in enumerate(actions):
            obs, reward, term, trunc, info = env.step(a[i])
            vobs, vreward, vterm, vtrunc, vinfo = vec_trace[t + 1]
            done = term or trunc
            assert reward == vreward[i] and term == vterm[i] and trunc == vtrunc[i]
            expect_obs = vinfo["final_obs"][i] if done else vobs[i]
            assert np.array_equal(obs, expect_obs)
            values = vinfo["final_info"] if done else vinfo
            for key, value in info.items():
                column = values[key]
                if isinstance(value, dict):                 # the episode's record: a dict of per-env columns
                    assert all(same(v, column[k][i]) for k, v in value.items()), key
                else:
                    assert same(value, column[i]), key
            if done:
                obs, _ = env.reset()
                assert np.array_equal(obs, vobs[i])


@pytest.mark.parametrize("kind", [PROBE, "laryngoscope"])
def test_a_pickled_env_continues_bit_for_bit(kind, probe_on_path):
    env = gym.make("softenv:SoftSphere-v0", device={"kind": kind}).unwrapped
    env.reset(seed=3)
    actions = np.random.default_rng(1).uniform(-1, 1, (20, 4)).astype(np.float32)
    for a in actions[:10]:
        env.step(a)
    copy = pickle.loads(pickle.dumps(env))
    for a in actions[10:]:
        ours, theirs = env.step(a), copy.step(a)
        assert data_equivalence(ours, theirs, exact=True)


def test_a_kind_that_names_no_device_is_refused_at_make(probe_on_path):
    allowed = r"allowed: \['ideal', 'laryngoscope'\] or 'module:attribute'"
    for kind, why in [("probe", "is not a device kind"), ("probe_device:Probe", "names a type, not a DeviceKind"),
                      ("probe_device:NOPE", "cannot be loaded"), ("no_such_module:X", "cannot be loaded")]:
        with pytest.raises(ValueError, match=f"device.kind='{kind}' {why}.*{allowed}"):
            gym.make("softenv:SoftSphereHaptic-v0", device={"kind": kind})
    with pytest.raises(ValueError, match=f"device.kind=None must be a string; {allowed}"):
        gym.make_vec("softenv:SoftSphere-v0", num_envs=2, vectorization_mode="vector_entry_point",
                     device={"kind": None})


def test_the_scene_device_section_reaches_the_torch_backend():
    pytest.importorskip("torch")
    env = gym.make_vec("softenv:SoftSphere-v0", num_envs=2, vectorization_mode="vector_entry_point", backend="torch",
                       device={"max_sideways_force": 12.0})
    assert env.unwrapped.world.config["device"]["max_sideways_force"] == 12.0
    assert str(env.unwrapped.torch_device) == "cpu"


@pytest.mark.parametrize("kind, engine", [("ideal", None), (PROBE, None), ("laryngoscope", "warp"),
                                          ("laryngoscope", "pymunk")])
def test_a_pickled_vector_env_continues_bit_for_bit(kind, engine, probe_on_path, tried):
    """Every device's batch pickles and deep-copies (the laryngoscope's engines are rebuilt from their
    state, pymunk's space too): a copy taken mid-episode continues as the original, through autoresets,
    bit for bit."""
    import copy

    tried["batch pickling and copies"] += 2
    device = {"kind": kind} if engine is None else {"kind": kind, "batch_engine": engine}
    env = SoftSphereVectorEnv(3, device=device, task={"horizon": 12}, autoreset_mode="same_step")
    env.reset(seed=5)
    actions = np.random.default_rng(2).uniform(-1, 1, (30, 3, 4)).astype(np.float32)
    for a in actions[:10]:
        env.step(a)
    copies = [pickle.loads(pickle.dumps(env)), copy.deepcopy(env)]
    for a in actions[10:]:
        ours = env.step(a)
        for other in copies:
            assert data_equivalence(ours, other.step(a), exact=True)
