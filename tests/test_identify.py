"""Tissue identification from a device log (softenv.training.identify): sessions of known tongue and coupling
stiffness, with sensor noise and tremor, recovered within their error bars when the blade's height is measured
beside the tongue's force; the force alone confounds the two stiffnesses (they act in series); bad input refused
by name."""

import numpy as np
import pytest

from softenv.envs.config import scene_material
from softenv.training.hand import haptic_config, reach_env, relative_hand_pose, sensor_readings
from softenv.training.identify import identify, identify_log, log_actions, simulate_sessions
from softenv.training.logs import HAND_LOG, SENSOR_COLUMNS, read_readings, save_log
from softenv.training.trainee import degrade, expert_hand_log

TRUTH = {"tissue_stiffness": np.array([1.25, 0.85]), "coupling_stiffness": np.array([0.85, 1.2])}
NOISE = {"tongue_force_N": 0.3, "blade_z_mm": 0.1}


@pytest.fixture(scope="module")
def sessions():
    config = haptic_config(None)
    log = expert_hand_log(config, duration_s=1.6, force_rate=None)    # the whole press within the short log
    actions = np.stack([log_actions(degrade(log, config, tremor=0.5, seed=s), config) for s in range(2)], axis=1)
    return config, actions


def _fit(sessions, channels, iterations):
    config, actions = sessions
    noise = [NOISE[c] for c in channels]
    measured = simulate_sessions(actions, TRUTH, config, channels=channels, noise=noise, seed=3)
    return identify(actions, measured, noise, config, names=tuple(TRUTH), channels=channels, iterations=iterations,
                    lr=0.05)


def test_known_stiffnesses_are_recovered_within_their_intervals_from_force_and_blade_height(sessions):
    fit = _fit(sessions, ("tongue_force_N", "blade_z_mm"), 20)     # Adam near, then Newton's steps converge
    for name, truth in TRUTH.items():
        assert np.all(fit.low[name] <= truth) and np.all(truth <= fit.high[name]), (name, fit.low[name], fit.high[name])
        assert np.all(np.abs(fit.values[name] / truth - 1.0) < 0.02), (name, fit.values[name])
    assert fit.losses[-1] < 0.01 * fit.losses[0]
    assert np.all(fit.normalised_rms < 1.3)               # the residuals are the sensors' noise, no more
    assert fit.confounded() == []


def test_the_force_alone_confounds_the_tongue_and_the_coupling(sessions):
    fit = _fit(sessions, ("tongue_force_N",), 10)
    (a, b, rho), = fit.confounded()
    assert (a, b) == ("tissue_stiffness", "coupling_stiffness") and rho < -0.95


def test_bad_input_is_refused_by_name(sessions):
    config, actions = sessions
    good = np.zeros((actions.shape[0], 2, 1))
    with pytest.raises(ValueError, match="channels=\\['pressure'\\]: choose one or more of"):
        identify(actions, good, [0.3], config, channels=("pressure",))
    with pytest.raises(ValueError, match="measured has shape \\(3, 2, 1\\); it must be \\(steps, sessions, channels\\)"):
        identify(actions, good[:3], [0.3], config, channels=("tongue_force_N",))
    with pytest.raises(ValueError, match="noise=\\[0.0\\]: one standard deviation > 0 per channel"):
        identify(actions, good, [0.0], config, channels=("tongue_force_N",))
    with pytest.raises(ValueError, match="names=\\['tongue'\\]: choose one or more of"):
        identify(actions, good, [0.3], config, names=("tongue",), channels=("tongue_force_N",))
    with pytest.raises(ValueError, match="iterations"):
        identify(actions, good, [0.3], config, channels=("tongue_force_N",), iterations=0)


def test_a_log_with_sensor_columns_is_identified_end_to_end(tmp_path):
    """A session recorded on the numpy twin of a tongue 1.25 times as stiff (the scene's tissue.E), poses and
    sensor readings written a control period a row as ``softenv play`` writes them, is fitted on the torch
    twin of the scene the log names (the normal tongue): the factor comes back."""
    base = haptic_config(None)
    stiff = haptic_config({"tissue": {"E": 1.25 * scene_material(base)[0]}})
    actions = log_actions(expert_hand_log(base, duration_s=1.2), stiff)
    env = reach_env(stiff, len(actions))
    env.reset(seed=0)
    poses, readings = [relative_hand_pose(env)], [sensor_readings(env)]
    for a in actions:
        env.step(a)
        poses.append(relative_hand_pose(env))
        readings.append(sensor_readings(env))
    dt = base["dynamics"]["dt"]
    path = tmp_path / "session.csv"
    save_log(np.column_stack([np.arange(len(poses)) * dt, poses]), path, HAND_LOG,
             readings={c: np.array([r[c] for r in readings]) for c in SENSOR_COLUMNS})
    assert max(r["tongue_force_N"] for r in readings) > 5.0                # the blade pressed the tongue
    np.testing.assert_allclose(read_readings(path)["blade_z_mm"], [r["blade_z_mm"] for r in readings], rtol=1e-8)
    fit = identify_log(path, NOISE, names=("tissue_stiffness",), iterations=10)
    assert abs(fit.values["tissue_stiffness"][0] / 1.25 - 1.0) < 0.02, fit.values
    with pytest.raises(ValueError, match="give the standard deviation of every channel the log carries"):
        identify_log(path, {"tongue_force_N": 0.3})
    save_log(np.column_stack([np.arange(len(poses)) * dt, poses]), tmp_path / "bare.csv", HAND_LOG)
    assert read_readings(tmp_path / "bare.csv") == {}
    with pytest.raises(ValueError, match="carries no sensor readings"):
        identify_log(tmp_path / "bare.csv", NOISE)
    with pytest.raises(ValueError, match="row 1, column 'tongue_force_N' = -1.0: a force must be finite and >= 0"):
        save_log(np.column_stack([np.arange(len(poses)) * dt, poses]), tmp_path / "bad.csv", HAND_LOG,
                 readings={"tongue_force_N": np.r_[-1.0, np.zeros(len(poses) - 1)]})
