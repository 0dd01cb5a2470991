"""Trainee scoring: schema validation, replay physics, the score's ordering on the shipped examples."""

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from softenv.cli import main
from softenv.envs import make_config
from softenv.training.hand import haptic_config
from softenv.training.logs import EXAMPLES_DIR, FORCE_LOG, HAND_LOG, read_log, read_scene, save_log
from softenv.training.scoring import (ADVICE, COLUMNS, expert_trajectory, improvements, load_trajectory,
                                      points_to_gain, replay, replay_hand, save_trajectory, score_file, score_hand_log)
from softenv.training.trainee import (LOWERS, WORST, degrade, expert_hand_log, skill_population, spearman,
                                      withdrawn)

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = EXAMPLES_DIR / "trajectories"
DEVICE_LOGS = EXAMPLES_DIR / "device_logs"


@pytest.fixture(scope="module")
def expert_log() -> np.ndarray:
    return expert_hand_log()


def test_shipped_examples_score_expert_then_too_forceful_then_wrong_direction(tmp_path):
    scores = {s: score_file(EXAMPLES / f"{s}.csv", out_dir=tmp_path)["score"]
              for s in ("expert", "too_forceful", "wrong_direction")}
    assert scores["expert"] > scores["too_forceful"] > scores["wrong_direction"]
    assert scores["expert"] > 90
    for ext in ("json", "md", "png"):
        assert (tmp_path / f"expert_score.{ext}").stat().st_size > 100
    assert "score = 100 accuracy (0.5 accuracy" in (tmp_path / "expert_score.md").read_text()


def test_examples_are_made_by_the_committed_script(tmp_path):
    subprocess.run([sys.executable, str(ROOT / "scripts" / "make_example_trajectories.py"), "--out", str(tmp_path)],
                   check=True, capture_output=True)
    made = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*.csv"))
    assert made == sorted(p.relative_to(EXAMPLES_DIR) for p in EXAMPLES_DIR.rglob("*.csv"))
    for rel in made:
        ours = [line for line in (tmp_path / rel).read_text().splitlines() if not line.startswith("#")]
        shipped = [line for line in (EXAMPLES_DIR / rel).read_text().splitlines() if not line.startswith("#")]
        assert ours == shipped, rel


def test_doing_nothing_scores_0_and_withdrawing_about_0_on_both_log_kinds(expert_log, tmp_path):
    """Safety, teeth and smoothness are earned by progress: a session left alone gets none of them."""
    still_hand = np.column_stack([np.linspace(0.0, 3.0, 151), np.zeros((151, 4))])
    forces = expert_trajectory()
    still_forces = np.column_stack([forces[:, :2], np.zeros((len(forces), 3))])
    still_forces[:, 1] = forces[0, 1]                              # the blade held at its start
    for name, log, schema in [("hand_still", still_hand, HAND_LOG), ("hand_back", withdrawn(expert_log), HAND_LOG),
                              ("force_still", still_forces, None), ("force_back", withdrawn(forces, FORCE_LOG), None)]:
        path = tmp_path / f"{name}.csv"
        save_log(log, path, schema) if schema else save_trajectory(log, path)
        report = score_file(path)
        assert report["accuracy"] < 0.02, name
        assert report["score"] == pytest.approx(100 * report["accuracy"] * sum(
            w * report[k] for k, w in report["weights"].items()), abs=1e-9), name
        assert report["score"] < 1.0 and (report["score"] == 0.0 or "back" in name), (name, report["score"])
        if "still" in name:
            assert report["safety"] == 1.0         # the part is there, but it earns nothing without progress


def test_constant_press_has_the_analytic_force_time_integral():
    t = np.linspace(0.0, 2.0, 11)
    table = np.column_stack([t, np.full_like(t, 90.0), np.zeros_like(t), np.full_like(t, 20.0), np.zeros_like(t)])
    result = replay(table)
    assert result.peak_force_N == pytest.approx(20.0) and result.mean_force_N == pytest.approx(20.0)
    assert result.force_time_integral_Ns == pytest.approx(20.0 * 2.0)          # F T
    assert result.jerk_rms == pytest.approx(0.0, abs=1e-9)


def test_expert_scored_against_itself_gets_full_marks_but_safety(tmp_path):
    path = tmp_path / "me.csv"
    save_trajectory(expert_trajectory(), path)
    report = score_file(path)
    assert report["accuracy"] == pytest.approx(1.0) and report["speed"] == 1.0
    assert report["smoothness"] == pytest.approx(1.0, abs=1e-6)             # the file rounds to 9 digits


def _write(tmp_path, text: str) -> Path:
    path = tmp_path / "t.csv"
    path.write_text(text)
    return path


@pytest.mark.parametrize("text, match", [
    ("time_s,insertion_deg,lateral_deg,normal_N\n0,90,0,1\n1,90,0,1\n", "missing columns \\['sideways_N'\\]"),
    ("time_s,insertion_deg,lateral_deg,normal_N,sideways_N\n0,90,0,1,0\n1,90,0,nan,0\n", "row 2, column 'normal_N'"),
    ("time_s,insertion_deg,lateral_deg,normal_N,sideways_N\n0,90,0,1,0\n0,90,0,1,0\n", "row 2, column 'time_s'"),
    ("time_s,insertion_deg,lateral_deg,normal_N,sideways_N\n0,90,0,1,0\n1,90,0,x,0\n", "row 2, column 'normal_N'"),
])
def test_bad_trajectories_name_the_row_and_column(tmp_path, text, match):
    with pytest.raises(ValueError, match=match):
        load_trajectory(_write(tmp_path, text))


def test_out_of_range_command_and_bad_files(tmp_path):
    table = expert_trajectory()
    table[5, 3] = 500.0
    with pytest.raises(ValueError, match="row 6, column 'normal_N' = 500 is outside the device range"):
        replay(table)
    with pytest.raises(ValueError, match="unknown format"):
        load_trajectory(_write(tmp_path, "x").rename(tmp_path / "t.txt"))
    np.savez(tmp_path / "t.npz", format_version=7, **{c: np.zeros(3) for c in COLUMNS})
    with pytest.raises(ValueError, match="format_version=7"):
        load_trajectory(tmp_path / "t.npz")


def test_score_command_prints_the_score_and_rejects_bad_files(tmp_path, capsys):
    from softenv.cli import main

    assert main(["score", str(EXAMPLES / "expert.csv"), "--out", str(tmp_path)]) == 0
    assert "score" in capsys.readouterr().out and (tmp_path / "expert_score.png").exists()
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,insertion_deg\n0,90\n")
    assert main(["score", str(bad)]) == 2
    assert "missing columns" in capsys.readouterr().err


def test_compare_command_rejects_unknown_names(capsys):
    from softenv.cli import main

    assert main(["compare", "--quick", "--policies", "telepathy", "--agents", "--out", "/nonexistent"]) == 2
    assert "argument --policies: invalid choice: 'telepathy' (choose from 'zero'" in capsys.readouterr().err


# -- hand-pose (device) logs -------------------------------------------------------------------

def test_shipped_device_logs_rank_the_expert_first_and_each_error_costs_its_part(tmp_path):
    reports = {p.stem: score_file(p, out_dir=tmp_path) for p in sorted(DEVICE_LOGS.glob("*.csv"))}
    expert = reports.pop("expert")
    assert expert["score"] > 95 and expert["log"] == "hand poses"
    for name, report in reports.items():
        assert report["score"] < expert["score"] - 5, name
    lever, clear = reports["levers_on_teeth"]["metrics"]["clinical"], expert["metrics"]["clinical"]
    assert reports["levers_on_teeth"]["teeth"] < 1.0 and lever["peak_incisor_force_N"] > 0.0
    assert clear["peak_incisor_force_N"] == 0.0
    assert lever["lever_share"] > 0.9 and clear["lever_share"] == 0.0          # levering, and not
    assert reports["too_forceful"]["safety"] < expert["safety"]
    assert reports["hesitant_tremulous"]["smoothness"] < 0.6 and reports["hesitant_tremulous"]["speed"] < 0.6
    assert reports["wrong_direction"]["accuracy"] < 0.7
    md = (tmp_path / "levers_on_teeth_score.md").read_text()
    assert "teeth = clip(1 - (peak_incisor_force + max(peak_jaw_force" in md and "peak incisor force" in md
    assert (tmp_path / "levers_on_teeth_score.png").stat().st_size > 1000
    # what to improve first: each log's advice names its own error; the expert has nothing to improve
    assert expert["advice"] == [] and max(expert["points_to_gain"].values()) < 0.05
    assert ADVICE["safety"].format(safe_force=30) in reports["too_forceful"]["advice"]
    assert ADVICE["smoothness"] in reports["hesitant_tremulous"]["advice"]
    assert reports["wrong_direction"]["advice"][0] == ADVICE["accuracy"]
    assert "To improve first: " + ADVICE["accuracy"] in (tmp_path / "wrong_direction_score.md").read_text()


def test_points_to_gain_are_the_score_with_one_part_as_good_as_the_experts():
    """Hand-computed from the formula: 100 accuracy (weighted sum)."""
    weights = {"accuracy": 0.5, "speed": 0.2, "safety": 0.3}
    parts = {"accuracy": 0.5, "speed": 1.0, "safety": 0.4}
    expert = {"accuracy": 1.0, "speed": 0.5, "safety": 1.0}
    now = 100 * 0.5 * (0.25 + 0.2 + 0.12)
    gain = points_to_gain(parts, expert, weights)
    assert gain["accuracy"] == pytest.approx(100 * 1.0 * (0.5 + 0.2 + 0.12) - now)
    assert gain["speed"] == 0.0                                         # better than the expert: nothing to gain
    assert gain["safety"] == pytest.approx(100 * 0.5 * (0.25 + 0.2 + 0.3) - now)
    report = {"points_to_gain": gain, "safe_force_N": 12.0}
    assert improvements(report) == [ADVICE["accuracy"], ADVICE["safety"].format(safe_force=12.0)]
    assert "12 N" in improvements(report)[1] and improvements(report, 1) == [ADVICE["accuracy"]]


def test_replaying_a_recorded_hand_reproduces_the_run_that_recorded_it():
    """The expert's log (its lift unbounded in rate: the controller alone) was recorded from a controller
    driving the env; replayed (closed loop on the hand pose) it gives the same shape error at every step."""
    import gymnasium as gym

    from softenv.devices.laryngoscope.control import HandController

    env = gym.make("SoftSphereHaptic-v0").unwrapped
    world = env.world
    target = (world.family.low + world.family.high) / 2
    obs, _ = env.reset(seed=0, options={"target": world.force_box.normalised(target)})
    controller, device = HandController(world.config), slice(2 * world.k, 2 * world.k + world.device_obs_size)
    expert_log = expert_hand_log(force_rate=None)
    errors = []
    for _ in range(len(expert_log) - 1):
        obs, _, _, _, info = env.step(controller.act(obs[None, device], target[None])[0].astype(np.float32))
        errors.append(info["shape_error_mm"])
    np.testing.assert_allclose(replay_hand(expert_log).error_mm, errors, rtol=1e-6, atol=1e-9)


def test_npz_device_log_scores_as_its_csv_and_poses_are_relative_to_the_first_row(tmp_path, expert_log):
    shifted = expert_log.copy()
    shifted[:, 0] += 12.5                                  # a device's own clock and origin
    shifted[:, 1:] += [0.3, -0.2, 0.1, 0.05]
    np.savez(tmp_path / "log.npz", format_version=1, **{c: shifted[:, j] for j, c in enumerate(HAND_LOG.columns)})
    save_log(expert_log, tmp_path / "log.csv", HAND_LOG)
    assert score_file(tmp_path / "log.npz")["score"] == pytest.approx(score_file(tmp_path / "log.csv")["score"], abs=1e-6)


def test_score_ranks_graded_skill_and_each_error_lowers_its_part(expert_log):
    """The ordering scripts/scoring_validity.py reports, on a smaller population."""
    parts, _, expert = score_hand_log(expert_log)
    population = skill_population(expert_log, levels=3, per_level=3)
    skill = [2 - level for level, _, _ in population]
    scores = [score_hand_log(log, expert=expert)[0]["score"] for _, _, log in population]
    assert spearman(np.array(skill), np.array(scores)) >= 0.9
    for name, part in LOWERS.items():
        degraded = score_hand_log(degrade(expert_log, **{name: WORST.get(name, 1.0)}), expert=expert)[0]
        assert degraded[part] < parts[part] - 0.1 and degraded["score"] < parts["score"], name
        half = score_hand_log(degrade(expert_log, **{name: 0.5 * WORST.get(name, 1.0)}), expert=expert)[0]
        assert parts[part] >= half[part] >= degraded[part], name          # the part falls as the error grows


def _device_log(tmp_path, rows: list[str], header: str = "time_s,hand_x_m,hand_z_m,hand_pitch_rad,hand_y_m") -> Path:
    path = tmp_path / "log.csv"
    path.write_text(header + "\n" + "\n".join(rows) + "\n")
    return path


@pytest.mark.parametrize("rows, header, match", [
    (["0,0,0,0,0", "0.1,0,-0.05,0,0"], None, "row 2, column 'hand_z_m' = -0.05 is outside the device range"),
    (["0,0,0,0,0", "0.02,0,-0.02,0,0"], None, "row 2, column 'hand_x_m / hand_z_m \\(across the blade\\)': the hand "
                                              "moves at 1 m/s"),
    (["0,0,0,0,0", "1,0,0,0.1,nan"], None, "row 2, column 'hand_y_m' = nan is not finite"),
    (["0,0,0,0,0", "0.01,0,0,0,0"], None, "shorter than one control period"),
    (["0,0,0,0", "1,0,0,0"], "time_s,hand_x_m,hand_z_m,hand_pitch_rad", "missing columns \\['hand_y_m'\\].*force commands"),
])
def test_bad_device_logs_get_one_line_exit_2_and_nothing_written(tmp_path, capsys, rows, header, match):
    import re

    from softenv.cli import main

    path = _device_log(tmp_path, rows, header or "time_s,hand_x_m,hand_z_m,hand_pitch_rad,hand_y_m")
    out = tmp_path / "out"
    assert main(["score", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(path) in err and re.search(match, err), err
    assert not out.exists()


STIFF = {"tissue": {"law": "stiffening"}}


def test_scoring_a_log_makes_its_scene_once(expert_log, tmp_path, scene_makes):
    """The scene is made where the log is read (the id's scene, then the recorded sections over it) and the
    made config is passed to the replays, the expert's log and the ranges: it was made 24 times for a hand log."""
    save_log(expert_log, tmp_path / "hand.csv", HAND_LOG, scene=STIFF)
    save_trajectory(expert_trajectory(duration_s=1.0), tmp_path / "force.csv")
    made = scene_makes
    made.clear()                                            # the logs' own making above
    score_file(tmp_path / "hand.csv")
    assert len(made) == 2                                   # scene_config: SoftSphereHaptic-v0's scene, then STIFF
    made.clear()
    score_file(tmp_path / "force.csv")
    assert len(made) == 1                                   # SoftSphere-v0's scene with the log's (empty) sections


def test_a_log_records_its_scene_and_is_replayed_on_it(expert_log, tmp_path):
    """A log scores the same whoever scores it: on the scene it records, not on whatever the reader names."""
    path = tmp_path / "stiff.csv"
    save_log(expert_log, path, HAND_LOG, scene=STIFF)
    assert read_scene(path) == STIFF
    report = score_file(path)
    assert report["scene"] == STIFF and report["scene_from"] == "the log"
    table = read_log(path)[1]                                                # as written: 9 digits
    assert report["score"] == score_hand_log(table, haptic_config(STIFF))[0]["score"] != score_hand_log(table)[0]["score"]
    same = {"tissue": {"law": "stiffening", "E": make_config()["tissue"]["E"]}}     # the same config, spelt out
    assert score_file(path, scene=same)["score"] == report["score"]
    with pytest.raises(ValueError, match=r"was recorded on scene \{'tissue': \{'law': 'stiffening'\}\}; scene=\{\} asks "
                                         "for another scene"):
        score_file(path, scene={})


def test_a_scene_of_another_device_is_refused_by_device_kind(expert_log, tmp_path, capsys):
    """A hand-pose log needs the laryngoscope: a scene naming the ideal device, given by the caller or
    recorded in the log, is refused in one line naming device.kind (it raised AttributeError inside)."""
    ideal = {"device": {"kind": "ideal"}}
    why = "device.kind='ideal': a hand-pose log moves the laryngoscope, so replaying and scoring it needs device.kind='laryngoscope'"
    with pytest.raises(ValueError, match=re.escape(why)):
        score_hand_log(expert_log, make_config(**ideal))        # a made config of another device
    with pytest.raises(ValueError, match=re.escape(why)):
        haptic_config(ideal)
    path = tmp_path / "ideal.csv"
    save_log(expert_log, path, HAND_LOG, scene=ideal)
    with pytest.raises(ValueError, match="the scene it records is not valid here: " + re.escape(why)):
        score_file(path)
    assert main(["score", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and why in err[0]


def test_the_command_line_names_the_options_a_contradiction_comes_from(expert_log, tmp_path, capsys):
    path = tmp_path / "stiff.csv"
    save_log(expert_log, path, HAND_LOG, scene=STIFF)
    assert main(["score", str(path), "--law", "linear", "--scene", "viscoelastic"]) == 2
    err = capsys.readouterr().err
    assert "; --scene viscoelastic --law linear asks for another scene (omit it" in err and "scene={" not in err


def test_old_logs_without_a_scene_replay_on_the_named_scene(expert_log, tmp_path):
    path = tmp_path / "old.csv"
    save_log(expert_log, path, HAND_LOG)
    path.write_text("".join(line for line in path.read_text().splitlines(keepends=True) if not line.startswith("#")))
    assert read_scene(path) is None
    assert score_file(path)["scene_from"] == "the id's own (the log records none)"
    assert score_file(path, scene=STIFF)["score"] == score_hand_log(read_log(path)[1], haptic_config(STIFF))[0]["score"]
    np.savez(tmp_path / "old.npz", format_version=1, **{c: expert_log[:, j] for j, c in enumerate(HAND_LOG.columns)})
    assert score_file(tmp_path / "old.npz", scene=STIFF)["score"] == score_hand_log(expert_log, haptic_config(STIFF))[0]["score"]


def test_npz_logs_record_their_scene_in_a_string_member(expert_log, tmp_path):
    columns = {c: expert_log[:, j] for j, c in enumerate(HAND_LOG.columns)}
    np.savez(tmp_path / "new.npz", format_version=2, scene=np.array(json.dumps(STIFF)), **columns)
    assert read_scene(tmp_path / "new.npz") == STIFF
    assert score_file(tmp_path / "new.npz")["score"] == score_hand_log(expert_log, haptic_config(STIFF))[0]["score"]
    bad = {"no scene": (dict(format_version=2), "format_version=2 needs a scene member"),
           "scene in v1": (dict(format_version=1, scene=np.array("{}")), "format_version=1 has no scene member"),
           "not JSON": (dict(format_version=2, scene=np.array("{tissue")), "member 'scene' is not JSON"),
           "not sections": (dict(format_version=2, scene=np.array('{"tissue": 5}')), "a JSON object of sections"),
           "numbers": (dict(format_version=2, scene=np.arange(3)), "member 'scene' declares shape"),
           "bad value": (dict(format_version=2, scene=np.array('{"tissue": {"E": -1}}')), "the scene it records is not "
                                                                                          "valid here: .*tissue.E")}
    for case, (extra, match) in bad.items():
        np.savez(tmp_path / f"{case}.npz", **extra, **columns)
        with pytest.raises(ValueError, match=match):
            score_file(tmp_path / f"{case}.npz")


def test_score_refuses_a_scene_that_contradicts_the_logs_own_in_one_line(expert_log, tmp_path, capsys):
    from softenv.cli import main

    path = tmp_path / "stiff.csv"
    save_log(expert_log, path, HAND_LOG, scene=STIFF)
    assert main(["score", str(path), "--law", "linear"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "was recorded on scene" in err and str(path) in err
    assert main(["score", str(path), "--law", "stiffening"]) == 0
    path.write_text(path.read_text().replace('"law": "stiffening"', '"law": "stiffening"}, "x": {'))
    assert main(["score", str(path)]) == 2
    assert "not valid here" in capsys.readouterr().err


def test_profiles_built_to_published_measurements_reach_them_and_rank_in_the_published_order(expert_log):
    """Carlson et al. 2012's intermediates and novices (time only) and Bishop et al. 1992's novices: each
    profile reaches its asked time ratio, and the scores fall expert > intermediate > novice."""
    from softenv.training import profiles

    parts, _, expert = score_hand_log(expert_log)
    built = {name: profiles.build(name, study, ratios, expert_log, expert, iterations=8)
             for name, study, *ratios in profiles.PROFILES if name in ("intermediate", "novice (time)")}
    for p in built.values():
        assert p.reached[0] == pytest.approx(p.asked[0], rel=0.05) and p.amounts["hesitation"] > 0.0, p.name
        assert p.reached[2] == pytest.approx(1.0)                       # only the time was asked of these
    scores = [parts["score"]] + [score_hand_log(p.log, expert=expert)[0]["score"] for p in built.values()]
    assert scores[0] > scores[1] > scores[2]
