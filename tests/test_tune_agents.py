"""``scripts/tune_agents.py`` at its smallest: Optuna's trials train and score agents on the training
targets, the search resumes from its study file as the search that never stopped, and the YAML it writes
is the best trial's."""

from __future__ import annotations

import json
import re
import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parent.parent


def _tune(tmp_path: Path, trials: int, *more: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "scripts/tune_agents.py", "--algo", "ppo", "--scene", "SoftSphere-v0",
                           "--trials", str(trials), "--timesteps", "64", "--episodes", "3", "--runs",
                           str(tmp_path / "runs"), "--out", str(tmp_path / "out"), *more],
                          cwd=ROOT, capture_output=True, text=True, timeout=600)


@pytest.mark.slow
def test_a_search_resumes_and_writes_the_best_trial(tmp_path: Path) -> None:
    first = _tune(tmp_path, 2)
    assert first.returncode == 0, first.stderr[-2000:]
    assert first.stdout.count("trial ") == 2
    again = _tune(tmp_path, 3)                     # one more trial; the two kept are not trained again
    assert again.returncode == 0, again.stderr[-2000:]
    assert [line.split(":")[0] for line in again.stdout.splitlines() if line.startswith("trial ")] == ["trial 2"]
    record = json.loads((tmp_path / "out" / "SoftSphere-v0__ppo.json").read_text())
    assert len(record["trials"]) == 3
    # the study is the simulator's: trials scored on another simulator (its study renamed, as a change to the
    # dynamics or the libraries would name it) are not resumed; the search starts afresh beside them
    assert re.fullmatch(r".* simulator [0-9a-f]{16}", record["study"])
    other = tmp_path / "other"
    shutil.copytree(tmp_path / "runs", other / "runs")
    with sqlite3.connect(other / "runs" / "tuning.db") as db:
        db.execute("UPDATE studies SET study_name = ?", (record["study"][:-16] + "0" * 16,))
    fresh = _tune(other, 2)
    assert fresh.returncode == 0, fresh.stderr[-2000:]
    assert [line.split(":")[0] for line in fresh.stdout.splitlines() if line.startswith("trial ")] == ["trial 0", "trial 1"]
    whole = _tune(tmp_path / "whole", 3)           # the same search, never stopped: the same proposals and scores
    assert whole.returncode == 0, whole.stderr[-2000:]
    unstopped = json.loads((tmp_path / "whole" / "out" / "SoftSphere-v0__ppo.json").read_text())["trials"]
    assert [(t["gamma"], t["learning_rate"], t["value"]) for t in unstopped] == \
        [(t["gamma"], t["learning_rate"], t["value"]) for t in record["trials"]]
    assert len({(t["gamma"], t["learning_rate"]) for t in record["trials"]}) == 3
    first = record["trials"][0]                    # the YAML's own values, scored the same way
    assert first["number"] == 0 and first["yaml"] and (first["gamma"], first["learning_rate"]) == (0.95, 3e-4)
    best = min(record["trials"], key=lambda t: t["value"])
    assert record["best"]["number"] == best["number"]
    entry = yaml.safe_load((tmp_path / "out" / "SoftSphere-v0__ppo.yml").read_text())["SoftSphere-v0"]
    assert (entry["gamma"], entry["learning_rate"]) == (best["gamma"], best["learning_rate"])
    assert 0.9 <= entry["gamma"] <= 0.999 and 1e-5 <= entry["learning_rate"] <= 1e-3
    assert entry["n_timesteps"] == 300_000                   # the YAML's budget, not the search's
    for trial in record["trials"]:                           # its score is its own agent's, on training targets
        assert trial["value"] == sum(trial["error_by_seed"]) / len(trial["error_by_seed"]) > 0
        # its training time is the one agent.json recorded when the agent was trained, also when re-read
        run = tmp_path / "runs" / "SoftSphere-v0" / f"ppo-trial{trial['number']}-seed0"
        assert trial["train_seconds"] == [json.loads((run / "agent.json").read_text())["train_seconds"]]
        assert trial["train_seconds"][0] > 0
    assert "| training minutes |" in (tmp_path / "out" / "SoftSphere-v0__ppo.md").read_text()
    # the confirmation: the best trial and the YAML's trained again on two other seeds, decided by their intervals
    bad = _tune(tmp_path, 3, "--confirm", "1", "--confirm-seeds", "0", "5")
    assert bad.returncode == 2 and "--confirm-seeds [0, 5]" in bad.stderr and "none of --seeds [0]" in bad.stderr
    confirmed = _tune(tmp_path, 3, "--confirm", "1", "--confirm-seeds", "1", "2")
    assert confirmed.returncode == 0, confirmed.stderr[-2000:]
    record = json.loads((tmp_path / "out" / "SoftSphere-v0__ppo.json").read_text())
    rows = {r["number"]: r for r in record["confirmation"]}
    assert set(rows) == {best["number"], 0} and record["confirm_seeds"] == [1, 2]
    for r in rows.values():
        assert len(r["error_by_seed"]) == 2 and r["mean"] == sum(r["error_by_seed"]) / 2
        assert r["ci_low"] <= r["mean"] <= r["ci_high"]
    top = min(rows.values(), key=lambda r: r["mean"])
    expected = top if top["ci_high"] < rows[0]["ci_low"] else rows[0]
    assert record["chosen"]["number"] == expected["number"]
    entry = yaml.safe_load((tmp_path / "out" / "SoftSphere-v0__ppo.yml").read_text())["SoftSphere-v0"]
    assert (entry["gamma"], entry["learning_rate"]) == (expected["gamma"], expected["learning_rate"])
    assert "## Confirmation on seeds [1, 2]" in (tmp_path / "out" / "SoftSphere-v0__ppo.md").read_text()
