"""The smallest form of ``scripts/fault_tolerance.py``: ``softenv compare`` killed (SIGKILL) and stopped
(SIGTERM) after its first finished job, then run again: no worker outlives it, the stop says what was
kept, the resumed table equals the uninterrupted one, and no file is truncated."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="follows processes through Linux /proc")
def test_compare_stopped_by_sigkill_or_sigterm_resumes_to_the_same_table(tmp_path):
    done = subprocess.run([sys.executable, "scripts/fault_tolerance.py", "--smoke", "--out", str(tmp_path),
                           "--work", str(tmp_path / "work")], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    killed, stopped = json.loads((tmp_path / "fault_tolerance.json").read_text())["trials"]
    for trial in (killed, stopped):
        assert trial["orphan_s"] < 3.0                    # the workers ended with their parent
        assert trial["cells_equal"] == trial["cells"] == 3
        assert trial["truncated"] == [] and trial["resumed_exit_status"] == 0
        kept = int(trial["resume_line"].split()[1])        # "resuming: k of 4 jobs ..."
        assert 1 <= kept < 4 and trial["resume_line"].startswith(f"resuming: {kept} of 4 jobs")
    assert killed["exit_status"] == -9 and stopped["exit_status"] == 143
    assert stopped["stop_line"].startswith("softenv compare: stopped by SIGTERM; ")
    assert "of 4 jobs are finished and kept in" in stopped["stop_line"] and "run the same command to resume" in stopped["stop_line"]
