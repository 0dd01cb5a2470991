"""``scripts/engine_agreement.py`` at its smallest: on every laryngoscope benchmark scene (both ids and each
airway grade) the batched twin's episodes equal the single envs' bit for bit."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from softenv.baselines.evaluate import SCENES, device_kind

ROOT = Path(__file__).resolve().parent.parent


def test_every_laryngoscope_scene_agrees_bit_for_bit(tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, "scripts/engine_agreement.py", "--episodes", "2", "--policies", "expert",
                           "--out", str(tmp_path)], cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-2000:]
    table = json.loads((tmp_path / "engine_agreement.json").read_text())["table"]
    assert sorted(table) == sorted(s for s in SCENES if device_kind(s) == "laryngoscope")
    for scene, policies in table.items():
        assert all(m["equal"] == 2 and m["max_diff"] == 0.0 for m in policies["expert"].values()), scene
