"""softenv as users get it: the wheel, installed into a fresh virtual environment, run from an empty folder
outside the repository. The main job (softenv compare --quick) runs with every job succeeding, and every
command and documented entry point runs on what the wheel ships (package data, no source tree)."""

from __future__ import annotations

import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
POLICY = "import numpy as np\n\n\ndef policy(obs):\n    return np.zeros((len(obs), 4), np.float32)\n"


def run(args: list[str], cwd: Path, env: dict[str, str], timeout: float = 600) -> str:
    done = subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert done.returncode == 0, f"{' '.join(args)}: exit {done.returncode}\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    return done.stdout + done.stderr


@pytest.mark.slow
def test_the_wheel_runs_every_command_outside_the_repository(tmp_path):
    wheels = tmp_path / "wheels"
    run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", str(ROOT), "-w", str(wheels)],
        tmp_path, dict(os.environ))
    (wheel,) = wheels.glob("softenv-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    assert {n.split("/")[0] for n in names} == {"softenv", wheel.name.split("-")[0] + "-" + wheel.name.split("-")[1] +
                                                 ".dist-info"}, "the wheel installs a top-level name besides softenv"
    for data in ("softenv/baselines/hyperparams/ppo.yml", "softenv/baselines/shipped_anchors/SoftSphereHaptic-v0.json",
                 "softenv/training/examples/device_logs/expert.csv", "softenv/fem/shipped/SoftSphere-v0.npz",
                 "softenv/skills/templates/cohort.html", "softenv/skills/migrations/env.py",
                 "softenv/skills/migrations/versions/v0002_pass_marks.py"):
        assert data in names

    venv = tmp_path / "venv"
    run([sys.executable, "-m", "venv", str(venv)], tmp_path, dict(os.environ))
    python, softenv = str(venv / "bin" / "python"), str(venv / "bin" / "softenv")
    env = {key: value for key, value in os.environ.items() if key not in ("VIRTUAL_ENV", "PYTHONPATH")}
    env["PATH"] = f"{venv / 'bin'}{os.pathsep}{env['PATH']}"
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    run([python, "-m", "pip", "install", "-q", "-c", str(ROOT / "constraints.txt"), f"{wheel}[all,play,offline,lab]"], tmp_path, env,
        timeout=1200)

    work = tmp_path / "empty"
    work.mkdir()
    env["SOFTENV_CACHE_DIR"] = str(tmp_path / "cache")
    where = run([python, "-c", "import softenv, sys; print(softenv.__file__); import importlib.util as u; "
                 "print(u.find_spec('baselines'))"], work, env)
    assert str(venv) in where.splitlines()[0] and where.splitlines()[1] == "None"

    report = run([softenv, "compare", "--quick", "--jobs", "2"], work, env, timeout=1200)
    assert "failed" not in report.lower() and (work / "reports" / "benchmark_quick.md").exists()
    assert "SoftSphereHaptic-v0 | expert" in (work / "reports" / "benchmark_quick.md").read_text()
    assert "score" in run([softenv, "score", "--example", "device_logs/levers_on_teeth", "--out", "scored"], work, env)
    assert (work / "scored" / "levers_on_teeth_score.md").exists()
    run([softenv, "score", "--example", "trajectories/expert"], work, env)
    # the skills lab: the store migrates from the wheel's migrations, the dashboard's pages load
    kept = run([softenv, "score", "--example", "device_logs/expert", "--trainee", "T-1", "--store", "lab.sqlite"], work, env)
    assert "kept as session 1 of trainee T-1" in kept
    run([python, "-c", "from softenv.skills.web import TEMPLATES; [TEMPLATES.get_template(p) for p in "
         "('cohort.html', 'trainee.html', 'session.html', 'upload.html', 'job.html', 'passmarks.html')]"], work, env)
    run([softenv, "bench", "--quick", "--only", "decode", "--out", "bench"], work, env)
    run([softenv, "play", "--headless", "--seconds", "0.5", "--out", "play"], work, env)
    (work / "still.py").write_text(POLICY)
    out = run([softenv, "evaluate", "still:policy", "--scene", "SoftSphereHaptic-v0", "--out", "still.json"], work, env)
    assert "computing" not in out                     # the anchors ship: no oracle planned here
    run([softenv, "leaderboard", "check", "still.json"], work, env)
    assert "| 1 | **still:policy** |" in run([softenv, "leaderboard", "show", "still.json"], work, env)
    run([softenv, "data", "--points", "441", "--out", "data"], work, env)
    run([softenv, "fit", "--points", "441", "--response", "poly2"], work, env)
    env["MINARI_DATASETS_PATH"] = str(tmp_path / "minari")
    made = run([softenv, "datasets", "make", "--kinds", "expert", "--episodes", "2", "--reference-episodes", "1"], work, env)
    assert "softenv/SoftSphereHaptic-v0/expert-v0: 2 episodes, 500 steps" in made
    assert "expert-v0: 2 episodes" in run([softenv, "datasets", "list"], work, env)
    for module in ("softenv.baselines.train", "softenv.baselines.ppo_torch"):
        run([python, "-m", module, "--help"], work, env)
    assert not any(p.name in ("baselines", "examples") for p in work.iterdir())
