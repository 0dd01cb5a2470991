"""SoftSphere envs: conformance, determinism, single/batched agreement, physics of a step, bad input."""

import copy
import math
import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.utils.env_match import check_environments_match
from gymnasium.vector import AutoresetMode

import softenv
from softenv.envs import ENV_SCENES
from softenv.envs.world import World
from softenv.envs.config import make_config

IDS = list(ENV_SCENES)
MODES = ["vector", "dict", "vertices"]


def rollout(env, seed, actions):
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for a in actions:
        obs, r, term, trunc, info = env.step(a)
        out.append((obs, r, term, trunc, info))
        if term or trunc:
            obs, _ = env.reset()
            out.append(obs)
    return out


def same(a, b) -> bool:
    return gym.utils.env_checker.data_equivalence(a, b, exact=True)


@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.parametrize("obs_mode", MODES)
def test_gymnasium_check_env_passes_without_warnings(env_id, obs_mode):
    env = gym.make(env_id, obs_mode=obs_mode, render_mode="rgb_array")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped, skip_render_check=False)


@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.parametrize("obs_mode", MODES)
def test_sb3_check_env_passes_without_warnings(env_id, obs_mode):
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make(env_id, obs_mode=obs_mode)
    if obs_mode == "dict":      # SB3 calls env.compute_reward, which Gymnasium 1.x wrappers do not forward
        env = env.unwrapped
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sb3_check_env(env, warn=True)


def test_ideal_scenes_import_neither_pymunk_matplotlib_nor_torch(heavy_modules_after):
    code = "import gymnasium as gym\n"
    for env_id in IDS:                                  # make without importing softenv first
        code += (f"env = gym.make('softenv:{env_id}')\n"
                 "env.reset(seed=0)\n"
                 "for _ in range(20): env.step(env.action_space.sample())\n"
                 f"venv = gym.make_vec('softenv:{env_id}', num_envs=2, vectorization_mode='vector_entry_point')\n"
                 "venv.reset(seed=0); venv.step(venv.action_space.sample())\n")
    assert heavy_modules_after(code) == []


def test_registration_is_idempotent_and_kwargs_override_the_scene():
    softenv.register_envs()
    softenv.register_envs()
    env = gym.make("SoftSphere-v0", tissue={"law": "stiffening"}, task={"tolerance": 0.2})
    assert env.unwrapped.world.config["tissue"]["law"] == "stiffening"
    assert env.unwrapped.world.tolerance == 0.2
    assert env.spec.max_episode_steps is None and env.unwrapped.world.horizon == 100     # the env truncates itself
    assert gym.make("SoftSphereViscoelastic-v0").unwrapped.world.dynamics.stateful


@pytest.mark.parametrize("env_id", IDS)
def test_same_seed_gives_bitwise_identical_rollouts(env_id):
    actions = [np.random.default_rng(1).uniform(-1, 1, 4).astype(np.float32) for _ in range(150)]
    a = rollout(gym.make(env_id), 7, actions)
    b = rollout(gym.make(env_id), 7, actions)
    c = rollout(gym.make(env_id), 8, actions)
    assert same(a, b)
    assert not same(a[0], c[0])


@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.parametrize("autoreset", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
@pytest.mark.parametrize("obs_mode", ["vector", "dict"])
def test_batched_twin_equals_sync_vector_env_of_single_envs(env_id, autoreset, obs_mode):
    n, steps = 3, 230                        # crosses two episode ends (100 steps each)
    kwargs = {"obs_mode": obs_mode, "task": {"terminate_on_success": True, "tolerance": 0.5}}
    native = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point",
                          autoreset_mode=autoreset, **kwargs)
    sync = gym.make_vec(env_id, num_envs=n, vectorization_mode="sync", vector_kwargs={"autoreset_mode": autoreset},
                        **kwargs)
    assert native.metadata["autoreset_mode"] == autoreset
    rng = np.random.default_rng(3)
    assert same(native.reset(seed=11), sync.reset(seed=11))
    ended = 0
    for _ in range(steps):
        actions = rng.uniform(-1, 1, (n, 4)).astype(np.float32)
        actions[0] = native.unwrapped.world.force_box.normalised(native.unwrapped._episode.target_features[0, -1])
        x, y = native.step(actions), sync.step(actions)
        assert same(x, y), (x, y)
        ended += int(np.sum(x[2] | x[3]))
    assert ended >= 3


def test_check_environments_match_at_one_env():
    native = gym.make_vec("SoftSphere-v0", num_envs=1, vectorization_mode="vector_entry_point")
    sync = gym.make_vec("SoftSphere-v0", num_envs=1, vectorization_mode="sync")
    check_environments_match(native, sync, num_steps=120, seed=5, skip_render=True)


def test_async_vector_env_matches_sync():
    asynced = gym.make_vec("SoftSphere-v0", num_envs=2, vectorization_mode="async")
    sync = gym.make_vec("SoftSphere-v0", num_envs=2, vectorization_mode="sync")
    actions = np.random.default_rng(0).uniform(-1, 1, (10, 2, 4)).astype(np.float32)
    assert same(asynced.reset(seed=2), sync.reset(seed=2))
    for a in actions:
        assert same(asynced.step(a), sync.step(a))
    asynced.close()


def test_pickle_and_deepcopy_continue_the_same_episode():
    env = gym.make("SoftSphereViscoelastic-v0")
    env.reset(seed=3)
    for _ in range(5):
        env.step(env.action_space.sample())
    clones = [pickle.loads(pickle.dumps(env)), copy.deepcopy(env)]
    action = np.array([0.2, -0.1, 0.5, 0.3], np.float32)
    expected = env.step(action)
    for clone in clones:
        assert same(clone.step(action), expected)


def test_exact_oracle_scores_100_and_zero_force_scores_0():
    env = gym.make("SoftSphere-v0")
    target = np.array([0.3, -0.05, 0.6, 0.5], np.float32)
    env.reset(seed=0, options={"target": target})
    for _ in range(3):
        obs, reward, _, _, info = env.step(target)
        assert reward == 0.0 and info["is_success"] and info["normalized_score"] == pytest.approx(100.0)
    env.reset(seed=0, options={"target": target})
    rest = env.unwrapped.world.force_box.rest_action
    for _ in range(3):
        obs, reward, _, _, info = env.step(rest)
        assert reward < -0.5 and not info["is_success"] and info["normalized_score"] == pytest.approx(0.0, abs=1e-9)


def test_success_error_mm_is_the_shape_error_where_success_begins():
    """Actions blended from rest to the target force cross the success line once: the steps on each side of it
    say is_success exactly when their shape error is under ``success_error_mm``."""
    env = gym.make("SoftSphere-v0")
    target = np.array([0.3, -0.05, 0.6, 0.5], np.float32)
    env.reset(seed=0, options={"target": target})
    with pytest.raises(RuntimeError, match="reset"):
        float(gym.make("SoftSphere-v0").unwrapped.success_error_mm)
    rest = env.unwrapped.world.force_box.rest_action
    line = env.unwrapped.success_error_mm
    seen = set()
    for s in np.linspace(0.0, 1.0, 60):
        _, _, _, _, info = env.step((rest + s * (target - rest)).astype(np.float32))
        assert info["is_success"] == (info["shape_error_mm"] < line * (1 - 1e-12)) or \
            abs(info["shape_error_mm"] - line) < 1e-9 * line
        seen.add(info["is_success"])
    assert seen == {True, False}


def test_shape_error_and_reward_agree_with_rebuilt_vertices():
    """b-space distances against an independent computation on decoded surfaces."""
    env = gym.make("SoftSphere-v0", obs_mode="vertices")
    world: World = env.unwrapped.world
    obs, _ = env.reset(seed=4)
    target_b = env.unwrapped.target_b[0]
    sm = world.scene.shape_model
    n = world.n_vertices
    for a in np.random.default_rng(0).uniform(-1, 1, (5, 4)).astype(np.float32):
        obs, reward, _, _, info = env.step(a)
        points = obs[2 * world.k + 8:].reshape(n, 3).astype(np.float64) * world.scene.tissue.radius
        truth = sm.decode(env.unwrapped.b).reshape(n, 3)
        np.testing.assert_allclose(points, truth, atol=1e-8)            # float32 vertices over R
        target = sm.decode(target_b).reshape(n, 3)
        rest = sm.decode(world.b_rest).reshape(n, 3)
        rms = np.sqrt(np.mean(np.sum((truth - target) ** 2, axis=1)))
        ref = np.sqrt(np.mean(np.sum((target - rest) ** 2, axis=1)))
        assert info["shape_error_mm"] == pytest.approx(rms * 1e3, rel=1e-9)
        assert reward == pytest.approx(-rms / max(ref, math.sqrt(world.floor_sq / n)), rel=1e-9)
        f = world.force_box.features(a.astype(np.float64))
        assert info["force_N"] == pytest.approx(math.hypot(f[2], f[3]))


def test_tabulated_exact_response_is_close_to_the_direct_computation():
    scene = gym.make("SoftSphere-v0").unwrapped.world.scene
    err = scene.response_error(n=200)
    mean_disp = np.sqrt(np.mean(np.sum(scene.data.shapes.reshape(len(scene.data.shapes), -1, 3)
                                       - scene.mesh.vertices.reshape(1, -1, 3), axis=2) ** 2)) * 1e3
    assert err["max_mm"] < 0.05 * max(mean_disp, 1.0)
    assert err["median_mm"] < 0.02


@pytest.mark.parametrize("tau, dt", [(5.8, 0.05), (1e-12, 0.05), (1e6, 10.0), (0.0, 0.05)])
def test_viscoelastic_creep_matches_the_closed_form_and_is_stable(tau, dt):
    env = gym.make("SoftSphere-v0", dynamics={"kind": "viscoelastic", "time_constant": tau, "dt": dt,
                                              "relaxed_fraction": 0.7})
    env.reset(seed=0)
    u = env.unwrapped
    a = np.array([0.1, 0.2, 0.9, -0.4], np.float32)
    g = u.world.response_one(u.world.force_box.features_one(a.tolist()))
    b0 = u.world.b_rest
    for n in range(1, 40):
        env.step(a)
        decay = 1.0 if tau == 0.0 else math.exp(-n * dt / tau)
        expected = 0.7 * g + 0.3 * (g + (b0 - g) * (0.0 if tau == 0.0 else decay))
        np.testing.assert_allclose(u.b, expected, rtol=1e-9, atol=1e-12)
        assert np.isfinite(u.b).all()


def test_procedure_target_moves_insert_press_sweep():
    env = gym.make("SoftSphereProcedure-v0")
    env.reset(seed=1)
    f = env.unwrapped.target_features
    third = len(f) // 3
    assert f[0, 2] < 0.2 * f[-1, 2] and f[0, 3] == pytest.approx(0.0, abs=0.1)       # light touch, no sweep
    assert np.all(np.diff(f[:third, 0]) * np.sign(f[-1, 0] - f[0, 0]) >= 0)         # insertion moves in
    assert f[2 * third - 1, 2] == pytest.approx(f[-1, 2], rel=0.05)                   # pressed before the sweep
    assert abs(f[2 * third - 1, 3]) < abs(f[-1, 3])                                    # sweep comes last


def test_train_and_test_targets_never_share_a_cell():
    family_train = World(make_config(task={"split": "train"})).family
    family_test = World(make_config(task={"split": "test"})).family
    rng = np.random.default_rng(0)
    train = {tuple(cell) for cell in family_train.cell_of(family_train.sample_many([rng] * 400))}
    test = {tuple(cell) for cell in family_test.cell_of(family_test.sample_many([rng] * 400))}
    assert train and test and not train & test
    assert len(train | test) == 3 ** 4


@pytest.mark.parametrize("bad", [np.array([np.nan, 0, 0, 0], np.float32), np.array([0, 0, 1.5, 0], np.float32),
                                 np.zeros(3, np.float32), np.array([np.inf, 0, 0, 0])])
def test_bad_action_raises_and_leaves_the_state_unchanged(bad):
    env = gym.make("SoftSphereViscoelastic-v0").unwrapped
    twin = gym.make("SoftSphereViscoelastic-v0").unwrapped
    env.reset(seed=2)
    twin.reset(seed=2)
    a = np.array([0.1, 0.1, 0.5, 0.1], np.float32)
    env.step(a)
    twin.step(a)
    with pytest.raises(ValueError, match="action"):
        env.step(bad)
    assert same(env.step(a), twin.step(a))


@pytest.mark.parametrize("env_id", ["SoftSphere-v0", "SoftSphereHaptic-v0"])
def test_bad_batched_action_names_the_env(env_id):
    venv = gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point")
    venv.reset(seed=0)
    actions = np.zeros((3, 4), np.float32)
    actions[2, 1] = np.nan
    with pytest.raises(ValueError, match=r"actions\[2, 1\] = nan:"):
        venv.step(actions)
    with pytest.raises(ValueError, match="shape"):
        venv.step(np.zeros((2, 4), np.float32))


@pytest.mark.parametrize("overrides, match", [
    ({"tissue": {"youngs": 1.0}}, "valid keys: model .*law"),
    ({"tisue": {}}, "valid sections"),
    ({"tissue": {"nu": 0.5}}, r"tissue.nu"),
    ({"dynamics": {"dt": -1.0}}, r"dynamics.dt"),
    ({"task": {"target_normal_force": (10.0, 90.0)}}, "device range"),
    ({"response": {"model": "gpt"}}, "poly1"),
])
def test_bad_scene_config_lists_valid_keys_and_ranges(overrides, match):
    with pytest.raises(ValueError, match=match):
        gym.make("SoftSphere-v0", **overrides)


def test_bad_reset_options_and_obs_mode():
    env = gym.make("SoftSphere-v0")
    with pytest.raises(ValueError, match="target"):
        env.reset(options={"target": [2.0, 0, 0, 0]})
    with pytest.raises(ValueError, match="unknown reset options"):
        env.reset(options={"goal": 1})
    with pytest.raises(ValueError, match="obs_mode"):
        gym.make("SoftSphere-v0", obs_mode="pixels")


@pytest.mark.parametrize("overrides", [
    {"tissue": {"E": 1e9}},                                            # very stiff tissue
    {"device": {"max_normal_force": 1e6, "max_sideways_force": 1e6},   # huge forces
     "task": {"target_normal_force": (1e5, 1e6), "target_sideways_force": (1e4, 1e5)}},
    {"tissue": {"law": "stiffening"}},
])
def test_extreme_scenes_stay_finite_and_within_bounds(overrides):
    env = gym.make("SoftSphere-v0", obs_mode="vertices", **overrides)
    obs, _ = env.reset(seed=0)
    for a in np.random.default_rng(0).uniform(-1, 1, (30, 4)).astype(np.float32):
        obs, reward, _, _, _ = env.step(a)
        assert np.isfinite(obs).all() and math.isfinite(reward)
        assert env.observation_space.contains(obs)
        radii = np.linalg.norm(obs[2 * env.unwrapped.world.k + 8:].reshape(-1, 3), axis=1)
        assert radii.min() > 0.2 and radii.max() <= 1.05


def test_regressor_scene_steps_with_a_trained_poly3():
    env = gym.make("SoftSphere-v0", response={"model": "poly3"}, mesh={"resolution": 11},
                   shape_model={"n_contacts": 16, "n_loads": 8, "n_components": 6})
    venv = gym.make_vec("SoftSphere-v0", num_envs=2, vectorization_mode="vector_entry_point", response={"model": "poly3"},
                        mesh={"resolution": 11}, shape_model={"n_contacts": 16, "n_loads": 8, "n_components": 6})
    obs, _ = env.reset(seed=0)
    vobs, _ = venv.reset(seed=0)
    assert same(obs, vobs[0])
    a = np.array([0.3, 0.1, 0.5, 0.2], np.float32)
    assert same(env.step(a)[0], venv.step(np.stack([a, a]))[0][0])


def test_rgb_array_frames_show_the_deformation():
    env = gym.make("SoftSphere-v0", render_mode="rgb_array", render={"size": 96, "fps": 15})
    assert env.metadata["render_fps"] == 15
    env.reset(seed=0)
    first = env.render()
    assert first.shape == (96, 96, 3) and first.dtype == np.uint8
    env.step(np.array([0.0, 0.0, 1.0, 1.0], np.float32))
    second = env.render()
    assert np.abs(second.astype(int) - first.astype(int)).sum() > 1000
    env.close()


def test_sb3_adapter_trains_ppo_for_2000_steps():
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecMonitor

    from softenv.envs.sb3 import SoftSphereSB3VecEnv

    venv = VecMonitor(SoftSphereSB3VecEnv(num_envs=4))
    model = PPO("MlpPolicy", venv, n_steps=128, batch_size=128, n_epochs=2, seed=0, device="cpu")
    model.learn(2000)
    assert model.num_timesteps >= 2000
    assert len(model.ep_info_buffer) >= 4                # episodes ended and were reported
    obs = venv.reset()
    action, _ = model.predict(obs, deterministic=True)
    assert action.shape == (4, 4)


def test_sb3_adapter_reports_terminal_observations():
    from softenv.envs.sb3 import SoftSphereSB3VecEnv

    venv = SoftSphereSB3VecEnv(num_envs=2, info_keys="all")
    venv.seed(0)
    venv.reset()
    for _ in range(100):
        obs, rewards, dones, infos = venv.step(np.zeros((2, 4), np.float32))
    assert dones.all()
    assert all(info["TimeLimit.truncated"] and info["terminal_observation"].shape == obs.shape[1:] for info in infos)
    assert all("normalized_score" in info for info in infos)


def test_human_mode_draws_without_a_display_and_returns_none():
    env = gym.make("SoftSphere-v0", render_mode="human")
    env.reset(seed=0)
    env.step(np.zeros(4, np.float32))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert env.render() is None
    assert env.unwrapped._renderer._figure is not None
    env.close()
    assert env.unwrapped._renderer is None


def test_mlp_scene_builds_and_steps():
    env = gym.make("SoftSphere-v0", response={"model": "mlp"}, mesh={"resolution": 11},
                   shape_model={"n_contacts": 16, "n_loads": 8, "n_components": 6})
    assert env.unwrapped.world.scene.response.trainer == "lbfgs"
    env.reset(seed=0)
    obs, reward, *_ = env.step(np.array([0.3, 0.1, 0.5, 0.2], np.float32))
    assert np.isfinite(obs).all() and env.observation_space.contains(obs)


def test_describe_config_is_a_valid_markdown_table_with_every_setting():
    """Six cells a row, a "|" inside a cell escaped (choices are written "a | b"), every schema key once."""
    import re

    from softenv.envs.config import SCHEMA

    rows = softenv.describe_config().splitlines()
    cells = [re.split(r"(?<!\\)\|", row)[1:-1] for row in rows]
    assert all(len(c) == 6 for c in cells), [r for r, c in zip(rows, cells) if len(c) != 6][:2]
    keys = [(c[0].strip(), c[1].strip()) for c in cells[2:]]
    assert keys == [(s, k) for s, fields in SCHEMA.items() for k in fields]
    assert any("\\|" in row for row in rows)             # the choices' bars, escaped
