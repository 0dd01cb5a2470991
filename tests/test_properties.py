"""Property tests (hypothesis): scene configs inside their documented ranges and any actions, on every
id, single env and batched twin: nothing but the documented ``ValueError``, nothing non-finite,
observations inside ``observation_space``, and the twin's env 0 equal to a single env bit for bit.

Profiles (tests/conftest.py): ``ci`` (default: 60 examples a test, 660 in all, about a minute) and ``long`` (1,000 a test,
11,000 in all), run by ``SOFTENV_HYPOTHESIS_PROFILE=long python -m pytest tests/test_properties.py``.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import softenv  # noqa: F401

IDEAL = ["SoftSphere-v0", "SoftSphereViscoelastic-v0", "SoftSphereProcedure-v0"]
HAPTIC = ["SoftSphereHaptic-v0", "SoftSphereHapticProcedure-v0"]
# a small surface and table keep each example's scene build to tens of milliseconds
SMALL = {"mesh": {"resolution": 5}, "shape_model": {"n_contacts": 8, "n_loads": 4, "n_components": 4},
         "response": {"table_nodes": (3, 3, 3, 3)}}


def log_uniform(low: float, high: float) -> st.SearchStrategy[float]:
    """Floats spread over decades, the ends included."""
    return st.one_of(st.sampled_from([low, high]),
                     st.floats(math.log10(low), math.log10(high)).map(lambda e: min(max(10.0 ** e, low), high)))


def unit() -> st.SearchStrategy[float]:
    return st.one_of(st.sampled_from([-1.0, 0.0, 1.0]), st.floats(-1.0, 1.0))


actions = st.lists(st.lists(unit(), min_size=4, max_size=4), min_size=1, max_size=6)


@st.composite
def scenes(draw: st.DrawFn, haptic: bool) -> dict:
    """Scene sections inside the documented ranges (softenv.describe_config())."""
    radius = draw(log_uniform(1e-4, 1.0))
    max_normal = draw(log_uniform(1e-3, 1e6))
    max_sideways = draw(log_uniform(1e-3, 1e6))
    # the laryngoscope pays for stiff tissue in substeps (1e12 Pa: ~1 s a step); its stiffest corners are
    # tested in test_reliability.py, so its examples stop at 1e8 Pa
    tissue = {"law": draw(st.sampled_from(["linear", "stiffening"])), "E": draw(log_uniform(1e-3, 1e8 if haptic else 1e12)),
              "nu": draw(st.floats(0.0, 0.499)), "radius": radius,
              "patch_radius": radius * draw(st.sampled_from([1e-3, 0.5, 1.0]) | st.floats(1e-3, 1.0))}
    dynamics = {"kind": draw(st.sampled_from(["quasi_static", "viscoelastic"])),
                "relaxed_fraction": draw(st.floats(1e-6, 1.0)), "time_constant": draw(st.sampled_from([0.0, 1e6]) |
                                                                                    log_uniform(1e-6, 1e6))}
    if not haptic:       # the laryngoscope's control period is the id's (stiff corners cost substeps, not tests)
        dynamics["dt"] = draw(log_uniform(1e-4, 10.0))
    normal_hi = max_normal * draw(st.floats(0.0, 1.0))
    sideways = sorted(max_sideways * draw(st.floats(-1.0, 1.0)) for _ in range(2))
    task = {"target_normal_force": (0.0, normal_hi), "target_sideways_force": tuple(sideways),
            "terminate_on_success": draw(st.booleans()), "tolerance": draw(st.floats(1e-3, 0.999))}
    reward = {key: draw(st.sampled_from([0.0, 1.0]) | st.floats(0.0, 100.0))
              for key in ("shape_weight", "force_weight", "smoothness_weight", "incisor_weight")}
    reward["safe_force"] = draw(log_uniform(1e-3, 1e6))
    device = {"max_normal_force": max_normal, "max_sideways_force": max_sideways}
    if haptic:
        device.update({"coupling_stiffness": draw(log_uniform(1e-3, 1e5)), "coupling_damping": draw(st.floats(0.0, 1e3)),
                       "blade_mass": draw(log_uniform(0.01, 10.0)), "friction": draw(st.floats(0.0, 5.0)),
                       "max_hand_speed": draw(log_uniform(1e-3, 5.0)), "haptic_preset": draw(st.sampled_from(
                           ["touch", "falcon", "omega"]))})
    return {**SMALL, "tissue": tissue, "dynamics": dynamics, "task": task, "reward": reward, "device": device}


def _documented(exc: ValueError) -> bool:
    """A refusal by the config's cross-checks (named settings), not an accident deeper down."""
    return any(f"{section}." in str(exc) for section in ("tissue", "device", "task", "dynamics", "reward"))


def _check_rollout(env_id: str, sections: dict, steps: list[list[float]], seed: int) -> None:
    try:
        single = gym.make(env_id, **sections)
    except ValueError as exc:
        assert _documented(exc), exc
        with pytest.raises(ValueError):
            gym.make_vec(env_id, 2, vectorization_mode="vector_entry_point", **sections)
        return
    batched = gym.make_vec(env_id, 2, vectorization_mode="vector_entry_point", **sections)
    obs, _ = single.reset(seed=seed)
    obs_b, _ = batched.reset(seed=seed)
    space = single.observation_space
    np.testing.assert_array_equal(obs, obs_b[0])
    for a in steps:
        a = np.asarray(a)
        obs, reward, terminated, truncated, info = single.step(a)
        obs_b, rewards, terminated_b, _, info_b = batched.step(np.stack([a, -a]))
        assert space.contains(obs), (obs, space)
        assert all(space.contains(row) for row in obs_b)
        assert math.isfinite(reward) and np.isfinite(rewards).all()
        assert all(np.isfinite(v).all() for k, v in info.items() if k != "clinical")
        if "clinical" in info:               # smoothness is NaN (undefined) only for a still hand or 1 step
            m = info["clinical"]
            assert all(math.isfinite(v) for k, v in m.items() if k not in ("sparc", "ldlj"))
            defined = m["hand_path_m"] > 0.0 and m["duration_s"] > 1.5 * single.unwrapped.world.config["dynamics"]["dt"]
            assert all(math.isfinite(m[k]) == defined for k in ("sparc", "ldlj")), m
        np.testing.assert_array_equal(obs_b[0], obs)
        assert rewards[0] == reward and terminated_b[0] == terminated
        if terminated or truncated:
            break


@pytest.mark.parametrize("env_id", IDEAL + HAPTIC)
@given(steps=actions, seed=st.integers(0, 2**31 - 1))
def test_any_actions_on_every_id_stay_finite_inside_the_space_and_single_equals_batched(env_id, steps, seed):
    _check_rollout(env_id, SMALL, steps, seed)


@pytest.mark.parametrize("env_id", IDEAL)
@given(data=st.data())
def test_ideal_scene_configs_inside_their_ranges_step_finite_and_agree(env_id, data):
    _check_rollout(env_id, data.draw(scenes(haptic=False)), data.draw(actions), data.draw(st.integers(0, 2**31 - 1)))


@pytest.mark.parametrize("env_id", HAPTIC)
@given(data=st.data())
def test_laryngoscope_scene_configs_inside_their_ranges_step_finite_and_agree(env_id, data):
    _check_rollout(env_id, data.draw(scenes(haptic=True)), data.draw(actions), data.draw(st.integers(0, 2**31 - 1)))


bad_actions = st.one_of(
    st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=0, max_size=6).filter(
        lambda xs: len(xs) != 4 or not all(-1.0 <= x <= 1.0 for x in xs)),
    st.lists(st.floats(-1e6, 1e6).filter(lambda x: abs(x) > 1.0), min_size=4, max_size=4),
    st.lists(st.text(max_size=3), min_size=4, max_size=4),
    st.lists(st.complex_numbers(max_magnitude=1.0), min_size=4, max_size=4),
    st.lists(st.booleans(), min_size=4, max_size=4),
)


@given(bad=bad_actions)
def test_bad_actions_raise_value_error_and_change_nothing(bad):
    for env in (_BAD_SINGLE, _BAD_BATCHED):
        before = env.unwrapped._b.copy()
        batch = bad if env is _BAD_SINGLE else [bad, bad]
        with pytest.raises(ValueError):
            env.step(batch)
        np.testing.assert_array_equal(env.unwrapped._b, before)


_BAD_SINGLE = gym.make("SoftSphere-v0", **SMALL)
_BAD_SINGLE.reset(seed=0)
_BAD_BATCHED = gym.make_vec("SoftSphere-v0", 2, vectorization_mode="vector_entry_point", **SMALL)
_BAD_BATCHED.reset(seed=0)
