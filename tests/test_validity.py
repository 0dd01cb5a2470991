"""The smallest form of ``scripts/validity.py`` (the trainee score's validity argument across airway
grades): every source of evidence is computed and reported, and what it says holds on its own numbers."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_the_validity_argument_reports_every_source_of_evidence_on_each_grade(tmp_path):
    done = subprocess.run([sys.executable, "scripts/validity.py", "--out", str(tmp_path), "--members", "5",
                           "--retest", "10", "--grades", "1", "4"], cwd=ROOT, capture_output=True, text=True,
                          timeout=900)
    assert done.returncode == 0, done.stdout + done.stderr
    result = json.loads((tmp_path / "validity.json").read_text())
    text = (tmp_path / "validity.md").read_text()
    for section in ("## 1. Known groups", "## 2. Internal structure", "## 3. Test-retest reliability",
                    "## 4. Relations to difficulty", "## 5. Consequences of a pass mark",
                    "## What synthetic trainees cannot show"):
        assert section in text
    assert (tmp_path / "validity.png").stat().st_size > 10_000
    for grade in ("1", "4"):
        groups = result["known_groups"][grade]
        assert groups["expert"][0] > groups["novice"][0]                        # known groups apart
        for mean, low, high in groups.values():
            assert low <= mean <= high
        g, low, high = result["effect_sizes"][grade]["expert vs novice"]
        assert g > 0.8 and low <= g <= high                                     # a large effect, with its interval
        mark = result["pass_marks"][grade]
        assert groups["novice"][0] < mark["mark"] < groups["expert"][0]
        assert 0.0 <= mark["false_pass"] <= 1.0 and 0.0 <= mark["false_fail"] <= 1.0
        r = result["retest"][grade]
        assert -1.0 <= r["low"] <= r["high"] <= 1.0 and r["trainees"] == 10
    correlations = result["internal"]["spearman"]
    assert all(abs(c) <= 1.0 + 1e-12 for row in correlations for c in row)
    assert all(correlations[i][i] == 1.0 for i in range(len(correlations)))
    d = result["difficulty"]
    assert d["4"]["expert_peak_tongue_N"] > d["1"]["expert_peak_tongue_N"]   # the published direction
    assert d["4"]["expert_time_to_target_s"] > d["1"]["expert_time_to_target_s"]          # Yu et al. 2025's
    assert "Yu et al. 2025" in text and "expert group: time to target (s)" in text
    assert result["commit"] and "scripts/validity.py" in result["command"]
