"""autoreset_mode="disabled" (Gymnasium 1.x's third mode): an ended env waits for reset(options={"reset_mask":
mask}), in the numpy twin (bit for bit against SyncVectorEnv of single envs in the same mode) and the torch twin
(against the numpy twin); misuse is refused before anything changes."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence
from gymnasium.vector import AutoresetMode

import softenv  # noqa: F401  (registers the ids)

DISABLED = AutoresetMode.DISABLED


def same(a, b) -> bool:
    return data_equivalence(a, b, exact=True)


def masked_seeds(t: int, n: int) -> list[int | None]:
    """Reseed every other env at a masked reset, continue the others' generators (both paths run)."""
    return [100 + t + i if i % 2 else None for i in range(n)]


@pytest.mark.parametrize("env_id, obs_mode, extra", [
    ("SoftSphere-v0", "vector", {}), ("SoftSphereProcedure-v0", "dict", {}),
    ("SoftSphereViscoelastic-v0", "vector", {}),
    ("SoftSphereHaptic-v0", "vector", {"device": {"batch_engine": "warp"}})])
def test_numpy_twin_equals_sync_vector_env_through_masked_resets(env_id, obs_mode, extra):
    n = 3
    kwargs = {"obs_mode": obs_mode, "task": {"terminate_on_success": True, "tolerance": 0.5, "horizon": 30}}
    native = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", autoreset_mode=DISABLED,
                          **kwargs, **extra)
    sync = gym.make_vec(env_id, num_envs=n, vectorization_mode="sync", vector_kwargs={"autoreset_mode": DISABLED},
                        **kwargs)
    assert native.metadata["autoreset_mode"] == DISABLED
    assert same(native.reset(seed=11), sync.reset(seed=11))
    rng = np.random.default_rng(0)
    resets = 0
    for t in range(80):
        actions = rng.uniform(-1, 1, (n, 4)).astype(np.float32)
        x, y = native.step(actions), sync.step(actions)
        assert same(x, y), t
        done = x[2] | x[3]
        if done.any():
            resets += int(done.sum())
            seeds = masked_seeds(t, n)
            assert same(native.reset(seed=seeds, options={"reset_mask": done}),
                        sync.reset(seed=seeds, options={"reset_mask": done.copy()}))
    assert resets >= 6


def test_misuse_is_refused_and_changes_nothing():
    n = 2
    env = gym.make_vec("SoftSphere-v0", num_envs=n, vectorization_mode="vector_entry_point", autoreset_mode="disabled",
                       task={"horizon": 3})
    with pytest.raises(RuntimeError, match="without a reset_mask first"):
        env.reset(options={"reset_mask": np.array([True, False])})
    env.reset(seed=0)
    for mask, match in [([True, False], "bool array of shape"), (np.array([1, 0]), "bool array of shape"),
                        (np.array([True]), r"shape \(2,\)"), (np.zeros(2, bool), "no True entry")]:
        with pytest.raises(ValueError, match=match):
            env.reset(options={"reset_mask": mask})
    a = np.zeros((n, 4), np.float32)
    for _ in range(3):
        obs, *_, truncated, _ = env.step(a)
    assert truncated.all()
    with pytest.raises(RuntimeError, match=r"env\(s\) \[0, 1\] ended"):
        env.step(a)
    # the refusals changed nothing: a masked reset of env 1 then a step equals a fresh env's episode there
    reset_obs, _ = env.reset(seed=[None, 5], options={"reset_mask": np.array([False, True])})
    assert same(reset_obs[0], obs[0])                 # env 0 keeps its last observation
    with pytest.raises(RuntimeError, match=r"env\(s\) \[0\] ended"):
        env.step(a)
    fresh = gym.make_vec("SoftSphere-v0", num_envs=n, vectorization_mode="vector_entry_point", task={"horizon": 3})
    assert same(fresh.reset(seed=4)[0][1], reset_obs[1])         # env 1 seeded 4 + 1, as reset(seed=4) seeds it
    for mode in ("next_step", "same_step"):
        other = gym.make_vec("SoftSphere-v0", num_envs=n, vectorization_mode="vector_entry_point", autoreset_mode=mode)
        other.reset(seed=0)
        with pytest.raises(ValueError, match="reset_mask.*autoreset_mode='disabled'"):
            other.reset(options={"reset_mask": np.array([True, False])})
    with pytest.raises(ValueError, match="'disabled'"):
        gym.make_vec("SoftSphere-v0", num_envs=n, vectorization_mode="vector_entry_point", autoreset_mode="never")


torch = pytest.importorskip("torch")


@pytest.mark.parametrize("env_id, obs_mode", [("SoftSphere-v0", "vector"), ("SoftSphereProcedure-v0", "dict"),
                                              ("SoftSphereHaptic-v0", "vector")])
def test_torch_twin_equals_the_numpy_twin_through_masked_resets(env_id, obs_mode):
    """float64 on CPU, targets drawn on the host: observations to float32 rounding, rewards within 1e-12 (1e-6 on
    the laryngoscope, whose tensor engine agrees with the numpy engines to rounding), the same flags, and the
    masked resets' observations (a torch mask) likewise."""
    n = 3
    kwargs = {"obs_mode": obs_mode, "task": {"terminate_on_success": True, "tolerance": 0.5, "horizon": 30}}
    ref = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", autoreset_mode=DISABLED, **kwargs)
    env = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", autoreset_mode=DISABLED,
                       backend="torch", dtype=torch.float64, **kwargs)
    assert env.metadata["autoreset_mode"] == DISABLED

    def close(a, b):
        for x, y in ((a, b),) if not isinstance(a, dict) else ((a[k], b[k]) for k in a):
            np.testing.assert_allclose(y.double().numpy(), np.asarray(x, np.float64), rtol=1e-5, atol=1e-5)

    tolerance = 1e-6 if "Haptic" in env_id else 1e-12
    close(ref.reset(seed=3)[0], env.reset(seed=3)[0])
    rng = np.random.default_rng(1)
    resets = 0
    for t in range(70):
        a = rng.uniform(-1, 1, (n, 4)).astype(np.float32)
        x, y = ref.step(a), env.step(torch.as_tensor(a))
        close(x[0], y[0])
        np.testing.assert_allclose(y[1].numpy(), x[1], rtol=tolerance, atol=tolerance)
        assert np.array_equal(x[2], y[2].numpy()) and np.array_equal(x[3], y[3].numpy())
        done = x[2] | x[3]
        if done.any():
            resets += int(done.sum())
            seeds = masked_seeds(t, n)
            close(ref.reset(seed=seeds, options={"reset_mask": done})[0],
                  env.reset(seed=seeds, options={"reset_mask": torch.as_tensor(done)})[0])
    assert resets >= 4
    env.step(torch.zeros((n, 4), dtype=torch.float64))
    with pytest.raises(ValueError, match="no True entry"):
        env.reset(options={"reset_mask": torch.zeros(n, dtype=torch.bool)})


def test_torch_device_draw_masked_reset_starts_the_seeded_episode():
    """Targets drawn on the device: a masked reset seeding env 1 with s starts the episode a full reset gives
    that env with the same seed; env 0, not masked, keeps its state."""
    kwargs = {"backend": "torch", "dtype": torch.float64, "target_draw": "device", "autoreset_mode": DISABLED}
    env = gym.make_vec("SoftSphereProcedure-v0", num_envs=2, vectorization_mode="vector_entry_point", **kwargs)
    twin = gym.make_vec("SoftSphereProcedure-v0", num_envs=2, vectorization_mode="vector_entry_point", **kwargs)
    env.reset(seed=0)
    a = torch.full((2, 4), 0.3, dtype=torch.float64)
    before, *_ = env.step(a)
    obs, _ = env.reset(seed=[None, 41], options={"reset_mask": np.array([False, True])})
    assert torch.equal(obs[0], before[0])
    fresh, _ = twin.reset(seed=40)                    # env 1 seeded 41
    assert torch.equal(obs[1], fresh[1])
    assert torch.equal(env.step(a)[0][1], twin.step(a)[0][1])
