"""``scripts/oracle_budget.py`` at its smallest: the search the shipped anchors ran, continued, scores
100 at the shipped budget (its own plan, found again, to the last bits, which the host's BLAS kernels
round), and no episode's score ever falls."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.slow
def test_the_budget_curve_meets_the_shipped_anchor_at_the_shipped_budget(tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, "scripts/oracle_budget.py", "--out", str(tmp_path), "--episodes", "2",
                           "--iterations", "121", "--scenes", "SoftSphereHaptic-v0"],
                          cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-2000:]
    record = json.loads((tmp_path / "budget.json").read_text())["scenes"]["SoftSphereHaptic-v0"]
    best = np.array(record["best"])                                        # (iterations + 1, episodes)
    starts = {k: np.array(v) for k, v in record["starts"].items()}
    assert best.shape == (122, 2) and np.all(np.diff(best, axis=0) >= 0)
    np.testing.assert_array_equal(best, np.max(list(starts.values()), axis=0))   # the plan: each episode's best start
    np.testing.assert_allclose(best[120], 100.0, atol=1e-9)               # the shipped search, found again
    assert np.all(starts["no force"][0] == 0.0)                            # no force scores 0 by definition
    assert sum(record["won_by"].values()) == 2
    table = (tmp_path / "README.md").read_text()
    assert "| SoftSphereHaptic-v0 | best of the starts | 121 |" in table and "git " in table
