"""Trainee scoring: schema validation, replay physics, the score's ordering on the shipped examples."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from softenv.scoring import COLUMNS, expert_trajectory, load_trajectory, replay, save_trajectory, score_file

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples" / "trajectories"


def test_shipped_examples_score_expert_then_too_forceful_then_wrong_direction(tmp_path):
    scores = {s: score_file(EXAMPLES / f"{s}.csv", out_dir=tmp_path)["score"]
              for s in ("expert", "too_forceful", "wrong_direction")}
    assert scores["expert"] > scores["too_forceful"] > scores["wrong_direction"]
    assert scores["expert"] > 90
    for ext in ("json", "md", "png"):
        assert (tmp_path / f"expert_score.{ext}").stat().st_size > 100
    assert "score = 100 (0.5 accuracy" in (tmp_path / "expert_score.md").read_text()


def test_examples_are_made_by_the_committed_script(tmp_path):
    subprocess.run([sys.executable, str(ROOT / "scripts" / "make_example_trajectories.py"), "--out", str(tmp_path)],
                   check=True, capture_output=True)
    for style in ("expert", "too_forceful", "wrong_direction"):
        ours = [l for l in (tmp_path / f"{style}.csv").read_text().splitlines() if not l.startswith("#")]
        shipped = [l for l in (EXAMPLES / f"{style}.csv").read_text().splitlines() if not l.startswith("#")]
        assert ours == shipped


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
    assert report["accuracy"] == pytest.approx(1.0) and report["speed"] == 1.0 and report["smoothness"] == 1.0


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
    assert "valid baselines" in capsys.readouterr().err
