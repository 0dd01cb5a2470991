"""Difficult airways (softenv.airway): the settings, the grades, what each changes in the scene, and the
scripted expert on every grade."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import softenv  # noqa: F401
from softenv.airway import GRADES, SETTINGS, airway, scene_title
from softenv.envs import AIRWAY_DEVICE, airway_scene
from softenv.envs.config import config_key, make_config
from softenv.envs.scene import degrees_to_features
from softenv.cli import main
from softenv.training.hand import haptic_config
from softenv.training.scoring import (ADVICE, AIRWAY_ADVICE, INCISOR_LIMIT_N, replay_hand, score_file, score_hand_log,
                                      score_log)
from softenv.training.logs import HAND_LOG, read_log, read_scene, save_log
from softenv.training.trainee import degrade, expert_hand_log

from lever_support import incisor_reach, jaw_depth

KEYED = ("tissue", "mesh", "shape_model", "response", "device", "dynamics", "task")


def test_each_setting_left_at_none_takes_its_grades_value_and_a_given_one_wins():
    for grade, (name, *values) in GRADES.items():
        a = airway(make_config(airway={"grade": grade}, device=AIRWAY_DEVICE)["airway"])
        assert a.settings == tuple(values) and a.name == name
    a = airway(make_config(airway={"grade": 4, "mouth_opening": 7.5}, device=AIRWAY_DEVICE)["airway"])
    assert a.mouth_opening == 7.5 and a.neck_extension == GRADES[4][2]


def test_the_normal_airway_is_keyed_as_before_airways_existed_and_another_is_not():
    """Caches, saved agents and anchors made before grades existed stay valid: grade 1 (or its settings
    given by hand) adds nothing to a scene's key; any other airway does."""
    plain = config_key(make_config(), KEYED)
    assert "airway" not in plain
    assert config_key(make_config(airway={"grade": 1, "mouth_opening": 3.0}), KEYED) == plain
    graded = config_key(make_config(airway={"grade": 2}, device=AIRWAY_DEVICE), KEYED)
    assert "airway" in graded and graded != config_key(make_config(device=AIRWAY_DEVICE), KEYED)
    assert config_key(make_config(airway={"grade": 2}, device=AIRWAY_DEVICE), ("render",)) == \
        config_key(make_config(), ("render",))                         # not keyed where it bears on nothing
    # grades without lower teeth are keyed by the five settings there were before; a gap (given, or the grade's) is keyed
    assert "interincisal_gap" not in graded
    gapped = config_key(make_config(airway={"grade": 2, "interincisal_gap": 30.0}, device=AIRWAY_DEVICE), KEYED)
    assert "('interincisal_gap', 30.0)" in gapped and gapped != graded
    assert f"('interincisal_gap', {GRADES[3][6]})" in config_key(make_config(airway={"grade": 3}, device=AIRWAY_DEVICE), KEYED)


@pytest.mark.parametrize("sections, match", [
    ({"airway": {"grade": 5}}, r"airway\.grade.*5"),
    ({"airway": {"mouth_opening": -1.0}}, r"airway\.mouth_opening.*\[0, 20\]"),
    ({"airway": {"neck_extension": 0.6}}, r"airway\.neck_extension.*\[0\.1, 0\.5\]"),
    ({"airway": {"tongue_stiffness": float("nan")}}, r"airway\.tongue_stiffness"),
    ({"airway": {"interincisal_gap": 10.0}}, r"airway\.interincisal_gap.*\[22, 80\]"),
    ({"airway": {"lift": 1.0}}, r"unknown key 'lift' in scene section 'airway'.*larynx_lift"),
    # the hardest grade's targets need more force than SoftSphereHaptic-v0's device gives
    ({"airway": {"grade": 4}}, r"task\.target_normal_force=\(20\.0, 40\.0\) \(on airway grade 4: \(28\.7.*57\.5.*\)\) "
                               r"must lie within the device range \[0, 40\]"),
])
def test_bad_airways_name_the_key_value_and_range(sections, match):
    with pytest.raises(ValueError, match=match):
        make_config(**sections)


def test_the_target_family_is_deepened_lifted_and_stiffened_as_set():
    config = make_config(airway={"grade": 1, "larynx_depth": 5.0, "larynx_lift": 1.2, "tongue_stiffness": 1.1},
                         device=AIRWAY_DEVICE)
    world = gym.make("SoftSphereAirway-v0", **{k: config[k] for k in ("airway",)}).unwrapped.world
    task, R = config["task"], config["tissue"]["radius"]
    low = [task["target_insertion_deg"][0] + 5.0, task["target_lateral_deg"][0], task["target_normal_force"][0] * 1.32,
           task["target_sideways_force"][0] * 1.1]
    high = [task["target_insertion_deg"][1] + 5.0, task["target_lateral_deg"][1], task["target_normal_force"][1] * 1.32,
            task["target_sideways_force"][1] * 1.1]
    np.testing.assert_allclose(world.family.low, degrees_to_features(low, R), rtol=1e-12)
    np.testing.assert_allclose(world.family.high, degrees_to_features(high, R), rtol=1e-12)


def test_a_stiffer_tongue_needs_proportionally_more_force_for_the_same_shape():
    """Linear tissue: displacement ~ F / E, so the stiff tongue's target under s times the force is the
    normal tongue's shape; both share one shape model, so the same shape has the same b."""
    normal = gym.make("SoftSphereAirway-v0").unwrapped
    stiff = gym.make("SoftSphereAirway-v0", airway={"tongue_stiffness": 1.5}).unwrapped
    assert np.array_equal(normal.world.scene.shape_model.components_, stiff.world.scene.shape_model.components_)
    force = normal.world.family.centre
    scaled = force * np.array([1.0, 1.0, 1.5, 1.5])
    b_normal = normal.world.scene.response.predict_rowwise(force[None])[0]
    b_stiff = stiff.world.scene.response.predict_rowwise(scaled[None])[0]
    shape = normal.world.vertices(b_normal) - normal.world.vertices(normal.world.b_rest)
    # the two tables interpolate the same law on grids of different force spacing: agreement to their error
    assert np.max(np.abs(stiff.world.vertices(b_stiff) - normal.world.vertices(b_normal))) < 0.02 * np.max(np.abs(shape))
    b_half = stiff.world.scene.response.predict_rowwise(force[None])[0]      # the normal force on the stiff tongue
    shallow = stiff.world.vertices(b_half) - stiff.world.vertices(stiff.world.b_rest)
    assert np.max(np.abs(shallow)) < 0.75 * np.max(np.abs(shape))


@pytest.mark.parametrize("mouth_opening", [0.5, 3.0, 10.0])
def test_the_mouth_opening_is_the_incisors_clearance_above_the_flange_at_the_start(mouth_opening):
    env = gym.make("SoftSphereAirway-v0", airway={"mouth_opening": mouth_opening}).unwrapped
    env.reset(seed=0)
    env.step(np.zeros(4, np.float32))                # the hand held still: pymunk's shapes placed where the blade is
    assert env.device.laryngoscope.incisor_clearance() == pytest.approx(mouth_opening * 1e-3, abs=1e-9)


@pytest.mark.parametrize("mouth_opening, gap", [(3.0, 26.0), (0.0, 40.0)])
def test_the_interincisal_gap_is_the_edges_distance_with_the_blade_between(mouth_opening, gap):
    """The lower incisal edge lies ``gap`` under the upper one (their roundings' facing points, the upper
    incisors where pymunk holds them), and ``gap - mouth_opening - 22 mm`` under the blade's underside in
    the start pose; without the setting there is no jaw; a gap the blade cannot fit in is refused."""
    env = gym.make("SoftSphereAirway-v0", airway={"mouth_opening": mouth_opening, "interincisal_gap": gap}).unwrapped
    env.reset(seed=0)
    env.step(np.zeros(4, np.float32))
    device = env.device.laryngoscope
    segment = device._space.incisors[0]
    upper_edge = segment.a.y - segment.radius
    assert upper_edge - (device.c.jaw[1] + device.c.jaw_radius) == pytest.approx(gap * 1e-3, abs=1e-12)
    depth = jaw_depth(device)
    assert depth == pytest.approx((mouth_opening + 22.0 - gap) * 1e-3, abs=1e-9)
    assert gym.make("SoftSphereAirway-v0").unwrapped.device.laryngoscope.c.jaw is None
    with pytest.raises(ValueError, match=r"airway\.interincisal_gap = 30 mm .*allowed >= .* = 32 mm"):
        gym.make("SoftSphereAirway-v0", airway={"mouth_opening": 10.0, "interincisal_gap": 30.0})


@pytest.mark.parametrize("grade", [1, 2])
def test_the_neck_extension_bounds_the_blades_pitch(grade):
    env = gym.make("SoftSphereAirway-v0", airway={"grade": grade}).unwrapped
    env.reset(seed=0)
    for _ in range(60):                                           # the wrist turned as far as it goes
        env.step(np.array([0.0, 0.0, 0.0, 1.0], np.float32))
    assert env.device.laryngoscope.hand_pose[2] == pytest.approx(GRADES[grade][2], abs=1e-12)


def test_the_expert_succeeds_on_every_grade_with_its_forces_and_time_rising_and_its_upper_teeth_untouched():
    """The published direction (Davis et al. 2023: tongue-base force rises from the normal to the most
    restricted setting, for every group). The scripted expert lifts along the handle, so it never loads the
    upper teeth on any grade (docs/airways.md says why no technique can at the family's centre); on the
    restricted mouth openings (grades 3 and 4) its lift presses the blade onto the lower incisors, so the
    force on the teeth rises from none to some there. Its lift builds force at a bounded rate, so the
    harder airway, which needs more force, takes longer."""
    peaks, jaw, times = [], [], []
    for grade in GRADES:
        config = haptic_config(airway_scene(grade))
        r = replay_hand(expert_hand_log(config), config)
        assert r.time_to_target_s is not None and r.final_error_mm < 0.1 * r.rest_error_mm
        assert r.clinical["peak_incisor_force_N"] == 0.0
        peaks.append(r.clinical["peak_tongue_force_N"])
        jaw.append(r.clinical["peak_jaw_force_N"])
        times.append(r.time_to_target_s)
    assert all(b > a + 2.0 for a, b in zip(peaks, peaks[1:])), peaks
    assert jaw[0] == jaw[1] == 0.0 and min(jaw[2:]) > 3.0, jaw
    assert all(b > a + 0.05 for a, b in zip(times, times[1:])), times


@pytest.mark.parametrize("grade", [1, 4])
def test_an_overshoot_presses_on_from_where_the_experts_lift_is_done(grade):
    """Until the expert's lift is done the overshooting trainee's hand is the expert's, so it reaches the
    target's shape at the same step (the expert's slower lift once overlapped the overshoot's growth, and
    the overshooter never passed the target); then it presses deeper: more force, a worse final shape."""
    config = haptic_config(airway_scene(grade))
    log = expert_hand_log(config)
    expert, pressed = replay_hand(log, config), replay_hand(degrade(log, config, overshoot=5.0), config)
    assert expert.time_to_target_s is not None and pressed.time_to_target_s == expert.time_to_target_s
    assert pressed.clinical["peak_tongue_force_N"] > expert.clinical["peak_tongue_force_N"] + 0.3
    assert pressed.final_error_mm > expert.final_error_mm


@pytest.mark.parametrize("grade", [1, 4])
def test_the_experts_lift_takes_at_least_the_force_over_its_rate(grade):
    """The force the lift tracks rises at ``force_rate`` from the blade's first touch, so the target's shape
    (nearly its whole force) comes no sooner than that force over the rate; twice the rate is sooner, and an
    unbounded one (the controller's own proportional law) sooner still."""
    config = haptic_config(airway_scene(grade))
    times = {}
    for rate in (20.0, 40.0, None):
        r = replay_hand(expert_hand_log(config, force_rate=rate), config)
        assert r.time_to_target_s is not None
        times[rate] = r.time_to_target_s
        if rate is not None:
            assert r.time_to_target_s >= 0.8 * r.clinical["peak_tongue_force_N"] / rate, (rate, r.time_to_target_s)
    assert times[20.0] > times[40.0] > times[None], times
    with pytest.raises(ValueError, match=r"force_rate.*\[1, 10000\]"):
        expert_hand_log(config, force_rate=0.0)


def test_lifting_reaches_as_deep_a_view_as_the_lever_with_the_teeth_untouched():
    """Why the expert's incisor force cannot rise (scripts/incisor_reach.py, docs/airways.md): on the
    restricted mouth opening, at the family's centre force, the expert's lift reaches views far deeper than
    the centre with the teeth untouched, and the lever on the incisors, which loads them with tens of newtons,
    holds the same force at a view within a degree of the lift's deepest; a step past that, the lift fails or
    touches the teeth."""
    centre_deg, force = incisor_reach.centre(3)
    reach = incisor_reach.lift_reach(3, 0.5)
    deepest, failed = reach["deepest"], reach["first_failed"]
    assert deepest["insertion_deg"] >= centre_deg + 10.0 and deepest["peak_incisor_N"] == 0.0
    assert failed is not None and (not failed["reached"] or failed["peak_incisor_N"] > 0.0)
    lever = incisor_reach.lever(3)
    assert not lever["at_neck_limit"] and lever["held_N"] == pytest.approx(force, rel=0.01)
    assert lever["incisor_N"] > 10.0
    assert abs(lever["insertion_deg"] - deepest["insertion_deg"]) < 1.0


def test_lower_incisors_stop_the_lift_short_and_the_lever_on_the_teeth_reaches_past_them():
    """What closer lower incisors would make of grade 3 (scripts/incisor_reach.py's jaw table, docs/airways.md):
    30 mm between the incisal edges (grade 3's own are 35 mm apart), the expert's lift stalls on the jaw with the tongue short of the centre's
    force, the jaw carrying the rest; turned about the upper incisal edge, the blade holds that force and
    loads the teeth with tens of newtons. 40 mm apart, the lift reaches the centre as without them."""
    force = incisor_reach.centre(3)[1]
    stalled, lever = incisor_reach.lift(3, incisor_reach.centre(3)[0], 30.0), incisor_reach.lever(3, 30.0)
    assert not stalled["reached"] and stalled["tongue_N"] < 0.9 * force and stalled["peak_jaw_N"] > 10.0
    assert not lever["at_neck_limit"] and lever["held_N"] == pytest.approx(force, rel=0.01) and lever["incisor_N"] > 10.0
    assert incisor_reach.lift(3, incisor_reach.centre(3)[0], 40.0)["reached"]


def test_a_lever_loads_the_teeth_sooner_through_a_restricted_mouth_opening():
    normal, restricted = (haptic_config(airway_scene(grade)) for grade in (1, 3))
    for config, loaded in ((normal, False), (restricted, True)):
        r = replay_hand(degrade(expert_hand_log(config), config, lever=0.25), config)
        assert (r.clinical["peak_incisor_force_N"] > 1.0) is loaded


def test_a_graded_log_records_its_airway_and_scores_against_that_grades_expert(tmp_path):
    config = haptic_config(airway_scene(3))
    log = degrade(expert_hand_log(config), config, tremor=1.0)
    path = tmp_path / "graded.csv"
    save_log(log, path, HAND_LOG, scene=airway_scene(3))
    assert read_scene(path) == airway_scene(3)
    report = score_file(path)
    parts, _, expert = score_hand_log(read_log(path, HAND_LOG)[1], config)       # as written (9 digits)
    assert {k: report["airway"][k] for k in ("grade", "name", "title")} == \
        {"grade": 3, "name": GRADES[3][0], "title": scene_title(config["airway"])}
    assert report["airway"]["target_force_N"] == pytest.approx(30.0 * GRADES[3][4])
    assert report["score"] == parts["score"]
    assert report["expert"]["peak_force_N"] == expert.peak_force_N
    normal_expert = replay_hand(expert_hand_log(haptic_config(None)), haptic_config(None))
    assert report["expert"]["peak_force_N"] > normal_expert.peak_force_N + 5.0
    assert main(["score", str(path), "--grade", "1"]) == 2            # a grade that contradicts the log's own


@pytest.mark.parametrize("grade", [3, 4])
def test_the_restricted_openings_gap_is_the_narrowest_the_lift_reaches_with_the_hand_free_to_press_harder(grade):
    """docs/airways.md's choice of grades 3 and 4's interincisal gaps: at the grade's own, the expert's lift reaches the
    centre with the jaw loaded and the hand above its workspace's floor; 1 mm narrower, the hand needs the floor's
    whole depth (no trainee could press harder than the expert)."""
    gap, insertion = GRADES[grade][6], incisor_reach.centre(grade)[0]
    own, narrower = incisor_reach.lift(grade, insertion), incisor_reach.lift(grade, insertion, gap - 1.0)
    assert own["reached"] and own["peak_jaw_N"] > 3.0 and own["above_floor_mm"] > 1.0
    assert narrower["above_floor_mm"] == pytest.approx(0.0, abs=1e-9)


def test_pressing_harder_than_the_lift_needs_costs_the_teeth_part_where_there_are_lower_incisors():
    """On grade 3 the expert's own lift rests the blade on the lower incisors at no cost to its teeth part; a trainee
    who presses 3 mm deeper squeezes the jaw beyond the expert's force, and the teeth part loses that excess over
    INCISOR_LIMIT_N (SCORE_VERSION 2); the advice names the lower teeth, not levering. Without lower teeth (grade 1)
    the same press costs the teeth nothing."""
    config = haptic_config(airway_scene(3))
    log = expert_hand_log(config)
    expert = score_log(log, HAND_LOG, config, "expert.csv", airway_scene(3), "the caller")
    assert expert["metrics"]["clinical"]["peak_jaw_force_N"] > 3.0 and expert["teeth"] == 1.0
    report = score_log(degrade(log, config, overshoot=3.0), HAND_LOG, config, "press.csv", airway_scene(3), "the caller")
    trainee = report["metrics"]["clinical"]
    excess = trainee["peak_jaw_force_N"] - expert["metrics"]["clinical"]["peak_jaw_force_N"]
    assert trainee["peak_incisor_force_N"] == 0.0 and excess > 2.0
    assert report["teeth"] == pytest.approx(1.0 - excess / INCISOR_LIMIT_N, abs=1e-12)
    assert any(a.startswith(AIRWAY_ADVICE["lower teeth"].format(interincisal_gap=GRADES[3][6])) for a in report["advice"])
    assert not any(ADVICE["teeth"] in a for a in report["advice"])
    normal = haptic_config(None)
    plain = score_log(degrade(expert_hand_log(normal), normal, overshoot=3.0), HAND_LOG, normal, "press.csv", {}, "c")
    assert plain["teeth"] == 1.0


def test_advice_on_a_graded_airway_says_what_that_airway_asks():
    config = haptic_config(airway_scene(4))
    report = score_log(degrade(expert_hand_log(config), config, lever=0.3), HAND_LOG, config, "lever.csv",
                       airway_scene(4), "the caller")
    deeper = AIRWAY_ADVICE["accuracy"].format(**report["airway"]["settings"], target_force=0.0)
    assert "4 deg deeper" in deeper
    assert report["advice"][0] == ADVICE["accuracy"] + " " + deeper
    normal = haptic_config(None)
    plain = score_log(degrade(expert_hand_log(normal), normal, lever=0.3), HAND_LOG, normal, "lever.csv", {},
                      "the caller")
    assert plain["advice"][0] == ADVICE["accuracy"]                 # the normal airway's advice alone


def test_play_runs_a_grade_and_its_log_records_it(tmp_path, capsys):
    assert main(["play", "--headless", "--seconds", "0.3", "--grade", "4", "--out", str(tmp_path)]) == 0
    log = next(tmp_path.glob("session_*.csv"))
    assert read_scene(log) == airway_scene(4)
    assert "airway grade 4" in "".join(log.read_text().splitlines()[:3])       # the note names it
    assert main(["play", "--headless", "--grade", "0"]) == 2
    assert "--grade" in capsys.readouterr().err


def test_every_setting_is_documented_with_its_grades_values():
    table = softenv.describe_config()
    for key in ("grade", *SETTINGS):
        assert f"| airway | {key} |" in table


def test_the_graded_profile_trains_on_the_easier_grades_and_evaluates_every_grade(tmp_path):
    from softenv.baselines.benchmark import Plan, graded_plan, run, trained_policy
    from softenv.baselines.evaluate import GRADED_SCENES

    full = graded_plan()
    assert full.scenes == list(GRADED_SCENES.values()) and full.train_on == [GRADED_SCENES[1], GRADED_SCENES[2]]
    easy, hard = GRADED_SCENES[1], GRADED_SCENES[4]
    plan = Plan([easy, hard], ["zero", "expert"], ["ppo"], {easy: 1, hard: 1}, {"ppo": 2048}, episodes=3,
                oracle={"candidates": 4, "iterations": 2, "elites": 2}, train_on=[easy])
    lines: list[str] = []
    summaries = run(plan, tmp_path, tmp_path / "runs", "softenv compare --graded --test", echo=lines.append,
                    stem="benchmark_graded")
    cells = {(s["scene"], s["policy"]): s for s in summaries}
    agent = trained_policy("ppo", easy)
    assert agent == "ppo (trained on grade1)" and (easy, agent) in cells and (hard, agent) in cells
    assert len(list((tmp_path / "runs" / easy.replace("/", "_")).glob("ppo-0"))) == 1     # trained once
    assert not (tmp_path / "runs" / hard.replace("/", "_")).exists()
    # the expert on each grade against that grade's own oracle; the hard grade needs more force
    assert cells[(hard, "expert")]["peak_tongue_force_N"]["mean"] > cells[(easy, "expert")]["peak_tongue_force_N"]["mean"]
    assert (tmp_path / "benchmark_graded_grades.png").stat().st_size > 10_000
    md = (tmp_path / "benchmark_graded.md").read_text()
    assert f"agents trained on {easy} (their budgets those scenes'), each evaluated on every scene" in md
    assert f"| {hard} | {agent} |" in md
    with pytest.raises(ValueError, match="not among the plan's scenes"):
        run(Plan([hard], ["zero"], ["ppo"], {hard: 1}, train_on=[easy]), tmp_path, tmp_path / "r", "", write=False)


def test_a_device_driving_a_graded_session_is_held_to_that_grades_workspace(monkeypatch):
    from softenv.training import play
    from softenv.training.hand import workspace

    seen = {}

    def bridge(host, port, config=None):
        seen["config"] = config
        raise ValueError("stopped before the session")

    monkeypatch.setattr(play, "open_bridge", bridge)
    assert main(["play", "--headless", "--grade", "2", "--bridge", "0"]) == 2
    low, high = workspace(seen["config"])
    assert (low[2], high[2]) == (-GRADES[2][2], GRADES[2][2])          # the neck's pitch range, not grade 1's
