"""``scripts/oracle_budget.py`` at its smallest: the search the shipped anchors ran, continued, scores
exactly 100 at the shipped budget (its own plan, found again), and no episode's score ever falls."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def test_the_budget_curve_meets_the_shipped_anchor_at_the_shipped_budget(tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, "scripts/oracle_budget.py", "--out", str(tmp_path), "--episodes", "2",
                           "--iterations", "31", "--scenes", "SoftSphereHaptic-v0", "--starts", "expert", "no force"],
                          cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    record = json.loads((tmp_path / "budget.json").read_text())
    starts = record["scenes"]["SoftSphereHaptic-v0"]["starts"]
    expert = np.array(starts["expert"]["score"])                           # (iterations + 1, episodes)
    assert expert.shape == (32, 2) and np.all(np.diff(expert, axis=0) >= 0)
    np.testing.assert_allclose(expert[30], 100.0, atol=1e-6)              # the shipped search, found again
    assert np.all(np.array(starts["no force"]["score"])[0] == 0.0)         # no force scores 0 by definition
    table = (tmp_path / "README.md").read_text()
    assert "| SoftSphereHaptic-v0 | best of the 2 starts | 31 |" in table and "git " in table
