"""Clinical metrics against closed forms: LDLJ of a minimum-jerk movement, SPARC of a Gaussian speed
profile, the glottic view past a sphere and a flattened sphere; and the haptic env's episode
summary against its own per-step infos."""

from __future__ import annotations

import math
import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import softenv  # noqa: F401  (registers the ids)
from softenv.devices.laryngoscope import clinical
from softenv.devices.laryngoscope.params import INCISOR_RADIUS, SHAPE_FRICTION
from softenv.geometry import make_mesh
from softenv.training.hand import action_toward, haptic_config, reach_env


def min_jerk_speed(n: int) -> np.ndarray:
    t = np.linspace(0.0, 1.0, n)
    return 30.0 * t ** 2 * (1.0 - t) ** 2                    # A = 1 m in T = 1 s


def test_ldlj_of_a_minimum_jerk_movement_is_the_closed_form():
    # d2v/dt2 = 60 (1 - 6t + 6t^2): integral of its square 720, v_peak = 1.875 -> DLJ = 720 / 1.875^2
    assert clinical.ldlj(min_jerk_speed(2001), 2000.0) == pytest.approx(-math.log(720 / 1.875 ** 2), rel=2e-3)
    # dimensionless: the same shape slower, larger or sampled differently scores the same
    slow = 0.3 * min_jerk_speed(4001)
    assert clinical.ldlj(slow, 2000.0) == pytest.approx(-math.log(720 / 1.875 ** 2), rel=2e-3)


def test_sparc_of_a_gaussian_speed_profile_is_the_arc_length_of_its_spectrum():
    sigma, fs = 0.1, 1000.0
    t = np.arange(-1.0, 1.0, 1.0 / fs)
    speed = np.exp(-t ** 2 / (2 * sigma ** 2))
    # |V(f)| / |V(0)| = exp(-2 pi^2 sigma^2 f^2), which falls to the 0.05 threshold at f_c (< 10 Hz)
    f_c = math.sqrt(math.log(20.0) / (2 * math.pi ** 2 * sigma ** 2))
    f = np.linspace(0.0, f_c, 200001)
    slope = -4 * math.pi ** 2 * sigma ** 2 * f * np.exp(-2 * math.pi ** 2 * sigma ** 2 * f ** 2)
    integrand = np.sqrt((1.0 / f_c) ** 2 + slope ** 2)
    analytic = -float(np.sum((integrand[1:] + integrand[:-1]) / 2 * np.diff(f)))
    assert clinical.sparc(speed, fs) == pytest.approx(analytic, rel=1e-2)


def test_tremor_and_hesitation_lower_both_smoothness_measures():
    fs = 50.0
    smooth = min_jerk_speed(251)
    t = np.arange(251) / fs
    tremor = smooth * (1.0 + 0.2 * np.sin(2 * np.pi * 6.0 * t))
    hesitant = np.concatenate([min_jerk_speed(126), min_jerk_speed(126)[1:]])   # two submovements
    for rough in (tremor, hesitant):
        assert clinical.sparc(rough, fs) < clinical.sparc(smooth, fs) - 0.1
        assert clinical.ldlj(rough, fs) < clinical.ldlj(smooth, fs) - 0.5
    assert math.isnan(clinical.sparc(np.zeros(10), fs)) and math.isnan(clinical.ldlj(np.zeros(10), fs))


def flattened_view(h: float) -> float:
    """The view past a unit circle whose top is cut flat at z = h (h < 1), in closed form: the
    shadow is cast by the back corner of the flat or by the tangent to the arc below it."""
    ex, ez = clinical.EYE
    gx = clinical.GLOTTIS_X
    corner = (-math.sqrt(1 - h * h), h)
    shadows = [ez + (corner[1] - ez) * (gx - ex) / (corner[0] - ex)]
    d2 = ex * ex + ez * ez
    root = math.sqrt(d2 - 1.0)
    for tx, tz in (((ex - ez * root) / d2, (ez + ex * root) / d2), ((ex + ez * root) / d2, (ez - ex * root) / d2)):
        if tz <= h and gx < tx < ex:
            shadows.append(ez + (tz - ez) * (gx - ex) / (tx - ex))
    low, high = clinical.GLOTTIS_Z
    return 100.0 * min(max((high - max(shadows)) / (high - low), 0.0), 1.0)


def test_glottic_view_past_a_sphere_and_a_flattened_sphere():
    mesh = make_mesh("latlong", 121, 0.03)
    rest = clinical.glottic_view(clinical.sagittal_profile(mesh.vertices, mesh.triangles), 0.03)
    assert rest == pytest.approx(clinical.rest_view_analytic(), abs=0.5)
    assert 10.0 < rest < 30.0                                # the rest tongue hides most of the opening
    views = []
    for h in (0.9, 0.8, 0.7):
        v = mesh.vertices.copy()
        v[:, 2] = np.minimum(v[:, 2], h * 0.03)
        views.append(clinical.glottic_view(clinical.sagittal_profile(v, mesh.triangles), 0.03))
        assert views[-1] == pytest.approx(flattened_view(h), abs=0.5)
    assert rest < views[0] < views[1] < views[2]
    gone = mesh.vertices * [1.0, 1.0, 0.0] - [0.0, 0.0, 0.03]      # nothing left above the line of sight
    assert clinical.glottic_view(clinical.sagittal_profile(gone, mesh.triangles), 0.03) == 100.0


def test_sagittal_profile_lies_in_the_plane_and_on_the_sphere():
    mesh = make_mesh("latlong", 31, 1.0)
    p = clinical.sagittal_profile(mesh.vertices, mesh.triangles)
    r = np.hypot(p[:, 0], p[:, 1])
    assert len(p) > 40 and np.all(r <= 1.0 + 1e-12) and np.all(r > 0.99)
    assert p[:, 0].min() < -0.99 and p[:, 0].max() > 0.99      # the whole cut, front to back


def test_episode_metrics_of_a_known_log():
    dt = 0.02
    log = np.zeros((5, len(clinical.COLUMNS)))
    log[1:, 0] = [1.0, 3.0, 2.0, 0.0]                          # tongue force
    log[1:, 1] = [0.0, 5.0, 0.0, 1.0]                          # incisor force
    log[1:, 2] = [0.01, 0.02, 0.02, 0.02]                      # the hand 1 cm forward twice
    log[1:, 4] = [0.0, 0.0, 0.03, 0.03]                        # then 3 cm aside
    log[1:, 5] = [1.0, -1.0, 0.0, 0.0]                         # wrist moment
    log[1:, 6] = [2.0, 2.0, 2.0, 0.0]                          # lift moment
    log[1:, 7] = [0.0, 4.0, 7.0, 6.0]                          # the jaw's push
    m = clinical.episode_metrics(log, dt, 50.0)
    assert m["duration_s"] == pytest.approx(0.08)
    assert m["peak_tongue_force_N"] == 3.0 and m["mean_tongue_force_N"] == pytest.approx(1.5)
    assert m["tongue_force_time_Ns"] == pytest.approx(6.0 * dt)
    assert m["peak_incisor_force_N"] == 5.0 and m["incisor_contact_s"] == pytest.approx(2 * dt)
    assert m["peak_jaw_force_N"] == 7.0
    # the hand's moment about the incisal edge |wrist + lift| = 3, 1, 2, 0: of its 6 N m, 1 while on the teeth
    assert m["lever_share"] == pytest.approx(1.0 / 6.0)
    assert m["hand_path_m"] == pytest.approx(0.05)
    assert m["glottic_view_pct"] == 50.0


def run_episode(env: gym.Env, actions: np.ndarray) -> tuple[list[dict], dict]:
    infos = []
    for a in actions:
        _, _, terminated, truncated, info = env.step(a)
        infos.append(info)
        if terminated or truncated:
            return infos, info["clinical"]
    raise AssertionError("the episode did not end")


def test_haptic_env_reports_the_episode_at_its_last_step():
    env = gym.make("softenv:SoftSphereHaptic-v0")
    dt = env.unwrapped.world.config["dynamics"]["dt"]
    env.reset(seed=3)
    rng = np.random.default_rng(3)
    actions = rng.uniform(-1, 1, (400, 4)).astype(np.float32)
    actions[:, 1] = np.abs(actions[:, 1])
    infos, summary = run_episode(env, actions)
    assert all("clinical" not in info for info in infos[:-1])
    tongue = np.array([i["tongue_force_N"] for i in infos])
    incisor = np.array([i["incisor_force_N"] for i in infos])
    assert summary["duration_s"] == pytest.approx(len(infos) * dt)
    assert summary["peak_tongue_force_N"] == tongue.max() > 0
    assert summary["tongue_force_time_Ns"] == pytest.approx(tongue.sum() * dt)
    assert summary["peak_incisor_force_N"] == incisor.max()
    assert summary["incisor_contact_s"] == pytest.approx(np.count_nonzero(incisor > 0) * dt)
    assert 0.0 <= summary["lever_share"] <= 1.0 and summary["hand_path_m"] > 0.0
    assert summary["sparc"] < 0 and summary["ldlj"] < 0
    assert summary["glottic_view_pct"] > clinical.rest_view_analytic() - 5      # pressed: not less than at rest

    still = gym.make("softenv:SoftSphereHaptic-v0")
    still.reset(seed=3)
    _, quiet = run_episode(still, np.zeros((400, 4), np.float32))
    assert quiet["hand_path_m"] == 0.0 and quiet["peak_tongue_force_N"] == 0.0 and math.isnan(quiet["sparc"])
    # the rest tongue on the scene's own mesh: the analytic view of a sphere
    assert quiet["glottic_view_pct"] == pytest.approx(clinical.rest_view_analytic(), abs=1.5)


def test_clinical_log_survives_pickle():
    env = gym.make("softenv:SoftSphereHaptic-v0")
    env.reset(seed=5)
    actions = np.random.default_rng(5).uniform(-1, 1, (400, 4)).astype(np.float32)
    for a in actions[:100]:
        env.step(a)
    copy = pickle.loads(pickle.dumps(env))
    _, a_summary = run_episode(env, actions[100:])
    _, b_summary = run_episode(copy, actions[100:])
    assert a_summary == b_summary or all(
        (math.isnan(a_summary[k]) and math.isnan(b_summary[k])) or a_summary[k] == b_summary[k] for k in a_summary)


@pytest.mark.parametrize("mode", [AutoresetMode.SAME_STEP, AutoresetMode.NEXT_STEP])
def test_batched_twin_reports_what_single_envs_report(mode):
    """The twin's env 0 equals a single env bit for bit, so its clinical summary does too, in the
    layout SyncVectorEnv gives a nested info (per-key arrays with masks)."""
    n = 2
    native = gym.make_vec("softenv:SoftSphereHaptic-v0", num_envs=n, vectorization_mode="vector_entry_point",
                          autoreset_mode=mode, task={"horizon": 30})
    sync = gym.make_vec("softenv:SoftSphereHaptic-v0", num_envs=n, vectorization_mode="sync", task={"horizon": 30},
                        vector_kwargs={"autoreset_mode": mode})
    native.reset(seed=4)
    sync.reset(seed=4)
    actions = np.random.default_rng(4).uniform(-1, 1, (30, n, 4)).astype(np.float32)
    for t, a in enumerate(actions):
        x, y = native.step(a)[4], sync.step(a)[4]
        if mode == AutoresetMode.SAME_STEP and "final_info" in y:
            x, y = x["final_info"], y["final_info"]
        assert ("clinical" in x) == ("clinical" in y) == (t == len(actions) - 1)
    assert set(x["clinical"]) == set(y["clinical"])
    assert np.array_equal(x["_clinical"], y["_clinical"])
    for key in clinical.episode_metrics(np.zeros((2, len(clinical.COLUMNS))), 0.02, 0.0):
        assert x["clinical"][key][0] == y["clinical"][key][0] or (
            math.isnan(x["clinical"][key][0]) and math.isnan(y["clinical"][key][0]))
        np.testing.assert_allclose(x["clinical"][key], y["clinical"][key], rtol=1e-6, atol=1e-9)


def test_the_jaws_peak_is_recorded_alike_by_single_envs_and_the_batched_twin():
    """Grade 3's lower incisors under a blade pressed straight down: the clinical record's jaw peak is the
    device's own reading at its highest, and the twin's env 0 records what a single env does, bit for bit."""
    kwargs = {"airway": {"grade": 3}, "task": {"horizon": 40}}
    single = gym.make("softenv:SoftSphereAirway-v0", **kwargs)
    native = gym.make_vec("softenv:SoftSphereAirway-v0", num_envs=2, vectorization_mode="vector_entry_point", **kwargs)
    single.reset(seed=3)
    native.reset(seed=3)
    press = np.array([0.0, 1.0, 0.0, 0.0], np.float32)
    readings = []
    for _ in range(40):
        info = single.step(press)[4]
        batch_info = native.step(np.stack([press, press]))[4]
        readings.append(float(single.unwrapped.device.laryngoscope.jaw_force))
    assert max(readings) > 10.0 and info["clinical"]["peak_jaw_force_N"] == max(readings)
    assert batch_info["clinical"]["peak_jaw_force_N"][0] == info["clinical"]["peak_jaw_force_N"]
    assert gym.make("softenv:SoftSphereAirway-v0").unwrapped.device.laryngoscope.c.jaw is None    # grade 1: none


def test_lever_share_is_1_for_a_blade_turned_on_the_teeth_and_0_for_a_press_clear_of_them():
    """Known answers: a moment applied only while the incisors bear the blade is all levering, one
    applied clear of them none, however large; a moment that the wrist and the grip's force cancel
    is no moment."""
    log = np.zeros((4, len(clinical.COLUMNS)))
    log[1:, 5] = [2.0, 2.0, 2.0]
    assert clinical.episode_metrics(log, 0.02, 0.0)["lever_share"] == 0.0          # pressing clear of the teeth
    log[1:, 1] = 4.0
    assert clinical.episode_metrics(log, 0.02, 0.0)["lever_share"] == 1.0          # every step on them
    log[1:, 6] = -2.0
    assert clinical.episode_metrics(log, 0.02, 0.0)["lever_share"] == 0.0          # no moment at all


def test_the_hands_moment_about_the_incisors_balances_the_tongues_when_levering():
    """Statics as the independent truth: a hand that turns the blade tip-down with its flange on the
    incisors (a lever on the teeth) comes to rest with its moment about the incisal edge equal and
    opposite to the tongue's force P n at the contact point, up to the incisors' friction on their
    round bar (at most mu N r, mu the product of the two shapes' frictions as pymunk takes it); and the episode's lever share is then near 1."""
    env = reach_env(haptic_config(None), 150)
    env.reset(seed=0)
    laryngoscope = env.device.laryngoscope
    for k in range(150):                                     # raise the hand 5 mm, turn it 0.4 rad, hold
        ramp = min(1.0, (k + 1) / 50)
        info = env.step(action_toward(env, np.array([0.0, 0.005 * ramp, 0.4 * ramp, 0.0])))[4]
    P, _, cx, cy, incisor = laryngoscope.state().contact[0]
    assert P > 20.0 and incisor > 5.0                          # on the tongue and on the teeth
    ix, iy = laryngoscope.params.incisor_segment[0]
    norm = math.hypot(cx, cy)
    tongue_moment = (cx - ix) * P * cy / norm - (cy - iy) * P * cx / norm
    row = env.device.clinical.log[env.device.clinical.steps[0], 0]
    hand_moment = row[5] + row[6]
    assert abs(hand_moment) > 1.0
    assert abs(hand_moment + tongue_moment) < SHAPE_FRICTION ** 2 * incisor * INCISOR_RADIUS
    assert info["clinical"]["lever_share"] > 0.9
