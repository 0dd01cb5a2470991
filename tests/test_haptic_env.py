"""SoftSphereHaptic envs: conformance, determinism, the batched twin, pickling with live contacts,
rewards and infos, rendering, imports, bad input and the SB3 adapter."""

import copy
import math
import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env, data_equivalence
from gymnasium.vector import AutoresetMode

import softenv  # noqa: F401  (registers the ids)
from softenv.envs import HAPTIC_SCENES

IDS = list(HAPTIC_SCENES)
PRESS = np.array([0.0, 0.9, 0.0, 0.0], np.float32)
TEETH = np.array([0.0, -1.0, 0.0, -1.0], np.float32)        # up and tip-up: into the incisors


def same(a, b) -> bool:
    return data_equivalence(a, b, exact=True)


@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.parametrize("obs_mode", ["vector", "dict"])
def test_gymnasium_and_sb3_checkers_pass_without_warnings(env_id, obs_mode):
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make(env_id, obs_mode=obs_mode, render_mode="rgb_array", render={"size": 64})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped, skip_render_check=False)
        other = gym.make(env_id, obs_mode=obs_mode)
        sb3_check_env(other.unwrapped if obs_mode == "dict" else other, warn=True)


def test_ids_register_with_their_horizons_and_keep_the_device_when_sections_are_passed():
    env = gym.make("softenv:SoftSphereHaptic-v0", device={"coupling_stiffness": 5e3}, task={"tolerance": 0.2})
    u = env.unwrapped
    assert u.world.config["device"]["kind"] == "laryngoscope" and u.device.laryngoscope.params.coupling_stiffness == 5e3
    assert env.spec.max_episode_steps is None and u.world.horizon == 250
    procedure = gym.make("SoftSphereHapticProcedure-v0", task={"tolerance": 0.2}).unwrapped
    assert procedure.world.task_kind == "procedure" and procedure.world.horizon == 500
    ideal = gym.make("SoftSphereHaptic-v0", device={"kind": "ideal"}).unwrapped      # device.kind alone decides
    assert type(ideal.device).__name__ == "IdealDevice" and ideal.world.horizon == 250
    with pytest.raises(ValueError, match=r"device.kind='blade' is not a device kind; allowed: \['ideal', 'laryngoscope'\]"):
        gym.make("SoftSphereHaptic-v0", device={"kind": "blade"})


def test_observation_layout_infos_and_reward_terms():
    env = gym.make("SoftSphereHaptic-v0", reward={"incisor_weight": 2.0, "force_weight": 0.5})
    obs, _ = env.reset(seed=0)
    w = env.unwrapped.world
    assert obs.shape == (2 * w.k + 19,) and env.observation_space.contains(obs)
    assert np.array_equal(obs[2 * w.k:], np.zeros(19, np.float32))            # at rest, at the start pose
    for _ in range(10):
        obs, reward, _, _, info = env.step(PRESS)
    assert info["tongue_force_N"] > 5.0 and info["tongue_force_N"] == pytest.approx(info["force_N"])
    assert info["haptic_force_N"].shape == (3,) and info["blade_pose"].shape == (4,)
    parts = info["reward_shape"] + info["reward_force"] + info["reward_smooth"] + info["reward_incisor"]
    assert reward == pytest.approx(parts)
    env.reset(seed=0)
    for _ in range(30):
        obs, reward, _, _, info = env.step(TEETH)
    assert info["incisor_force_N"] > 0.0
    assert info["reward_incisor"] == pytest.approx(-2.0 * info["incisor_force_N"] / 30.0)
    assert env.observation_space.contains(obs)


def test_no_motion_scores_zero_and_leaves_the_tongue_at_rest():
    env = gym.make("SoftSphereHaptic-v0")
    env.reset(seed=1)
    u = env.unwrapped
    for _ in range(20):
        _, _, _, _, info = env.step(np.zeros(4, np.float32))
    assert np.array_equal(u.b, u.world.b_rest) and info["tongue_force_N"] == 0.0
    assert info["normalized_score"] == pytest.approx(0.0, abs=1e-9)


def test_pressing_toward_the_target_scores_above_zero():
    env = gym.make("SoftSphereHaptic-v0")
    env.reset(seed=1)
    for t in range(60):
        _, _, _, _, info = env.step(PRESS if t < 6 else np.zeros(4, np.float32))
    assert info["normalized_score"] > 10.0


@pytest.mark.parametrize("env_id", IDS)
def test_same_seed_gives_bitwise_identical_rollouts(env_id):
    actions = np.random.default_rng(1).uniform(-1, 1, (120, 4)).astype(np.float32)

    def rollout(seed):
        env = gym.make(env_id)
        out = [env.reset(seed=seed)]
        out += [env.step(a) for a in actions]
        return out

    assert same(rollout(7), rollout(7))
    assert not same(rollout(7)[0], rollout(8)[0])


@pytest.mark.parametrize("autoreset, obs_mode, engine", [
    (AutoresetMode.NEXT_STEP, "vector", "auto"), (AutoresetMode.SAME_STEP, "vector", "warp"),
    (AutoresetMode.NEXT_STEP, "dict", "warp"), (AutoresetMode.SAME_STEP, "dict", "auto"),
    (AutoresetMode.NEXT_STEP, "vector", "pymunk")])
def test_batched_twin_matches_single_envs(autoreset, obs_mode, engine):
    """Every env of the twin equals a single env bit for bit on the Warp engine (auto, warp); on
    the pymunk engine env 0 does, and envs 1 and 2 sit elsewhere in the shared space (their positions
    carry an offset, so they round differently) and agree to 1e-6."""
    n = 3
    kwargs = {"obs_mode": obs_mode, "task": {"terminate_on_success": True, "tolerance": 0.6}}
    native = gym.make_vec("SoftSphereHaptic-v0", num_envs=n, vectorization_mode="vector_entry_point",
                          autoreset_mode=autoreset, max_episode_steps=40, device={"batch_engine": engine}, **kwargs)
    sync = gym.make_vec("SoftSphereHaptic-v0", num_envs=n, vectorization_mode="sync", max_episode_steps=40,
                        vector_kwargs={"autoreset_mode": autoreset}, **kwargs)
    exact = n if engine != "pymunk" else 1
    rng = np.random.default_rng(3)
    x, y = native.reset(seed=11), sync.reset(seed=11)
    ended = 0
    for _ in range(100):                                       # crosses episode ends (40 steps or success)
        actions = rng.uniform(-1, 1, (n, 4)).astype(np.float32)
        actions[:, 1] = np.abs(actions[:, 1])
        x, y = native.step(actions), sync.step(actions)
        obs_x, obs_y = (x[0], y[0]) if obs_mode == "vector" else (x[0]["observation"], y[0]["observation"])
        assert np.array_equal(obs_x[:exact], obs_y[:exact])
        np.testing.assert_allclose(obs_x, obs_y, rtol=1e-6, atol=1e-6)
        assert np.array_equal(x[1][:exact], y[1][:exact])
        np.testing.assert_allclose(x[1], y[1], rtol=1e-6, atol=1e-6)
        assert np.array_equal(x[2], y[2]) and np.array_equal(x[3], y[3])
        assert set(x[4]) == set(y[4])
        for key in ("incisor_force_N", "tongue_force_N", "normalized_score"):
            if key in x[4]:
                assert np.array_equal(x[4][key][:exact], y[4][key][:exact])
        ended += int(np.sum(x[2] | x[3]))
    assert ended >= 3


@pytest.mark.parametrize("actions", [PRESS, TEETH], ids=["tongue", "incisors"])
def test_pickle_and_deepcopy_continue_identically_with_live_contacts(actions):
    env = gym.make("SoftSphereHaptic-v0")
    env.reset(seed=3)
    for _ in range(25):
        _, _, _, _, info = env.step(actions)
    assert info["tongue_force_N"] > 0 or info["incisor_force_N"] > 0
    clones = [pickle.loads(pickle.dumps(env)), copy.deepcopy(env)]
    moves = np.random.default_rng(0).uniform(-1, 1, (30, 4)).astype(np.float32)
    expected = [env.step(a) for a in moves]
    for clone in clones:
        assert same([clone.step(a) for a in moves], expected)


def test_reset_leaves_no_contact_behind():
    env, fresh = gym.make("SoftSphereHaptic-v0"), gym.make("SoftSphereHaptic-v0")
    env.reset(seed=5)
    for _ in range(30):
        _, _, _, _, info = env.step(TEETH)
    assert info["incisor_force_N"] > 0
    a, b = env.reset(seed=9), fresh.reset(seed=9)
    assert same(a, b)
    for move in np.random.default_rng(2).uniform(-1, 1, (20, 4)).astype(np.float32):
        assert same(env.step(move), fresh.step(move))


@pytest.mark.parametrize("bad", [np.array([np.nan, 0, 0, 0], np.float32), np.array([0, 1.5, 0, 0], np.float32),
                                 np.zeros(3, np.float32), np.array([0, 0, 0, np.inf])])
def test_bad_action_raises_and_leaves_the_state_unchanged(bad):
    env, twin = gym.make("SoftSphereHaptic-v0").unwrapped, gym.make("SoftSphereHaptic-v0").unwrapped
    env.reset(seed=2)
    twin.reset(seed=2)
    for _ in range(5):
        env.step(PRESS)
        twin.step(PRESS)
    with pytest.raises(ValueError, match="action"):
        env.step(bad)
    assert same(env.step(PRESS), twin.step(PRESS))         # (the batched twin: tests/test_env.py)


@pytest.mark.parametrize("device, match", [
    ({"coupling_stiffness": 0.0}, "device.coupling_stiffness"),
    ({"coupling_stiffness": 1e8}, "device.coupling_stiffness"),
    ({"blade_mass": 0.001}, "device.blade_mass"),
    ({"coupling_damping": float("nan")}, "device.coupling_damping"),
    ({"max_substep": 0.01}, "device.max_substep"),
    ({"haptic_preset": "phantom"}, "device.haptic_preset"),
    ({"batch_engine": "mujoco"}, "device.batch_engine"),
    ({"batch_engine": "compiled"}, r"device.batch_engine='compiled' is retired: it was the numba kernel"),
    ({"batch_engine": "numpy"}, r"device.batch_engine='numpy' is retired"),
    ({"stiffness": 1.0}, "valid keys"),
])
def test_bad_device_parameters_name_the_key_and_range(device, match):
    with pytest.raises(ValueError, match=match):
        gym.make("SoftSphereHaptic-v0", device=device)


def test_the_numpy_twin_refuses_the_torch_twins_engine_by_name():
    with pytest.raises(ValueError, match=r"device.batch_engine='triton' has no numpy engine: 'triton' steps only"):
        gym.make_vec("SoftSphereHaptic-v0", num_envs=2, vectorization_mode="vector_entry_point",
                     device={"batch_engine": "triton"})


@pytest.mark.parametrize("sections", [
    {"device": {"coupling_stiffness": 1e6, "blade_mass": 0.01, "handle_mass": 0.0}},
    {"tissue": {"E": 1e3}},
    {"tissue": {"E": 1e7}},
], ids=["stiff-coupling-10g", "soft-tongue", "stiff-tongue"])
def test_extreme_scenes_stay_finite_and_within_bounds(sections):
    env = gym.make("SoftSphereHaptic-v0", **sections)
    obs, _ = env.reset(seed=0)
    moves = np.concatenate([np.tile([1, 1, 1, 1], (4, 1)), np.tile([0, -1, 0, -1], (4, 1)),
                            np.random.default_rng(0).uniform(-1, 1, (4, 4))]).astype(np.float32)
    for a in moves:
        obs, reward, _, _, info = env.step(a)
        assert np.isfinite(obs).all() and math.isfinite(reward) and env.observation_space.contains(obs)
        assert np.isfinite(info["haptic_force_N"]).all() and math.isfinite(info["incisor_force_N"])


def test_rgb_array_shows_the_blade_beside_the_sphere_and_human_mode_draws_headless():
    env = gym.make("SoftSphereHaptic-v0", render_mode="rgb_array", render={"size": 96})
    env.reset(seed=0)
    first = env.render()
    assert first.shape == (96, 192, 3) and first.dtype == np.uint8
    for _ in range(10):
        env.step(PRESS)
    second = env.render()
    assert np.abs(second[:, 96:].astype(int) - first[:, 96:].astype(int)).sum() > 1000   # the side view moved
    env.close()
    jawed = gym.make("SoftSphereHaptic-v0", render_mode="rgb_array", render={"size": 96}, airway={"interincisal_gap": 30.0})
    jawed.reset(seed=0)
    lower = jawed.render()                                 # the same start, with lower incisors drawn under the blade
    assert np.array_equal(lower[:, :96], first[:, :96]) and np.abs(lower[:, 96:].astype(int) - first[:, 96:]).sum() > 1000
    jawed.close()
    human = gym.make("SoftSphereHaptic-v0", render_mode="human")
    human.reset(seed=0)
    human.step(PRESS)
    assert human.render() is None
    human.close()


def test_haptic_scene_imports_pymunk_but_neither_matplotlib_nor_torch(heavy_modules_after):
    """The single env loads pymunk alone; its batched twin Warp too (its engine), and on the pymunk
    engine not Warp."""
    single = ("import gymnasium as gym\n"
              "env = gym.make('softenv:SoftSphereHaptic-v0')\n"
              "env.reset(seed=0)\n"
              "for _ in range(5): env.step(env.action_space.sample())\n")
    assert heavy_modules_after(single) == ["pymunk"]
    batch = single + ("venv = gym.make_vec('softenv:SoftSphereHaptic-v0', num_envs=2, vectorization_mode='vector_entry_point')\n"
                      "venv.reset(seed=0); venv.step(venv.action_space.sample())\n")
    assert heavy_modules_after(batch) == ["pymunk", "warp"]
    assert heavy_modules_after(batch.replace("vectorization_mode='vector_entry_point'",
                                             "vectorization_mode='vector_entry_point', device={'batch_engine': 'pymunk'}")) \
        == ["pymunk"]


def test_sb3_adapter_serves_the_haptic_twin():
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecMonitor

    from softenv.envs.sb3 import SoftSphereSB3VecEnv

    venv = VecMonitor(SoftSphereSB3VecEnv(num_envs=4, env_id="SoftSphereHaptic-v0", task={"horizon": 50}))
    model = PPO("MlpPolicy", venv, n_steps=64, batch_size=128, n_epochs=1, seed=0, device="cpu")
    model.learn(512)
    assert model.num_timesteps >= 512 and len(model.ep_info_buffer) >= 4
    obs = venv.reset()
    assert obs.shape == (4, venv.observation_space.shape[0])


def test_sb3_adapter_gives_the_clinical_metrics_when_asked():
    from softenv.envs.sb3 import SoftSphereSB3VecEnv

    n, horizon = 2, 30
    venv = SoftSphereSB3VecEnv(n, env_id="SoftSphereHaptic-v0", info_keys=("is_success", "clinical"),
                               task={"horizon": horizon})
    twin = gym.make_vec("softenv:SoftSphereHaptic-v0", num_envs=n, vectorization_mode="vector_entry_point",
                        autoreset_mode="same_step", task={"horizon": horizon})
    venv.seed(4)
    venv.reset()
    twin.reset(seed=4)
    actions = np.random.default_rng(4).uniform(-1, 1, (horizon, n, 4)).astype(np.float32)
    for t, a in enumerate(actions):
        _, _, dones, infos = venv.step(a)
        expected = twin.step(a)[4]
        assert dones.all() == (t == horizon - 1)
        assert all(("clinical" in info) == dones.all() for info in infos)    # only where an episode ends
    summary = expected["final_info"]["clinical"]
    for i, info in enumerate(infos):
        assert set(info["clinical"]) == {key for key in summary if not key.startswith("_")}
        assert all(value == summary[key][i] or math.isnan(summary[key][i]) for key, value in info["clinical"].items())
    typo = SoftSphereSB3VecEnv(n, env_id="SoftSphereHaptic-v0", info_keys=("clinic",), task={"horizon": horizon})
    typo.reset()
    with pytest.raises(ValueError, match=r"info_keys \['clinic'\] are not info keys.*'clinical'"):
        typo.step(a)


@pytest.mark.parametrize("env_id", IDS)
def test_her_compute_reward_equals_the_step_reward_with_the_incisor_term(env_id, tried):
    """HER relabels with compute_reward: for the step's own goals it must give the step's reward bit for bit,
    the incisor term included (a blade levering on the teeth is punished in relabelled transitions too)."""
    env = gym.make(env_id, obs_mode="dict", reward={"force_weight": 0.5, "smoothness_weight": 0.1}).unwrapped
    venv = gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point", obs_mode="dict",
                        reward={"force_weight": 0.5, "smoothness_weight": 0.1})
    env.reset(seed=3)
    venv.reset(seed=3)
    rewards, relabelled, infos, incisor = [], [], [], []
    for t in range(60):
        action = TEETH if t % 3 else PRESS
        obs, reward, _, _, info = env.step(action)
        vobs, vreward, _, _, vinfo = venv.step(np.stack([action, PRESS]))
        assert env.compute_reward(obs["achieved_goal"], obs["desired_goal"], info) == reward
        assert np.array_equal(venv.compute_reward(vobs["achieved_goal"], vobs["desired_goal"], vinfo), vreward)
        tried["goal reward (HER's compute_reward)"] += 3          # the single env's step, the vector env's two
        rewards.append(reward)
        infos.append(info)
        relabelled.append(obs)
        incisor.append(info["reward_incisor"])
    assert min(incisor) < -0.05              # the blade did lever on the teeth
    batch = env.compute_reward(np.stack([o["achieved_goal"] for o in relabelled]),
                               np.stack([o["desired_goal"] for o in relabelled]), np.array(infos))
    assert np.array_equal(batch, np.array(rewards))          # HER's call: arrays of goals, an array of infos
