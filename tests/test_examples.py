"""Every fenced Python or shell block of the README and the docs runs as written: each in a fresh
interpreter (or shell) from the repository root, on its own imports. A block that needs a GPU, a
cluster, a display or more than a minute says so in the line above it,
``<!-- example: syntax only (why) -->``, and is checked for syntax alone."""

from __future__ import annotations

import ast
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("**/*.md"))]
LIMIT_S = 300      # a hard stop against a hang, not a speed check: the slowest block nears 2 min on a slow host
BLOCK = re.compile(r"(?:<!-- example: (?P<mark>[^>]*?) -->\n)?```(?P<lang>python|bash)\n(?P<code>.*?)\n```", re.S)


def blocks() -> list:
    found = []
    for page in PAGES:
        if "_generated" in page.parts or "_build" in page.parts:
            continue
        text = page.read_text()
        for m in BLOCK.finditer(text):
            line = text[:m.start()].count("\n") + 1
            found.append(pytest.param(m.group("lang"), m.group("code"), m.group("mark"),
                                      id=f"{page.relative_to(ROOT)}:{line}"))
    return found


@pytest.mark.parametrize("lang, code, mark", blocks())
def test_example_runs_as_written(lang: str, code: str, mark: str | None, tmp_path: Path) -> None:
    if mark is not None:
        assert mark.startswith("syntax only ("), f"unknown example mark {mark!r}"
        if lang == "python":
            ast.parse(code)
        else:
            subprocess.run(["bash", "-n", "-c", code], check=True)
        return
    env = {**os.environ, "MPLBACKEND": "Agg"}
    if lang == "python":                       # a file, as a user saves it (spawned workers re-import it)
        script = tmp_path / "example.py"
        script.write_text(code)
        command = [sys.executable, str(script)]
    else:
        command = ["bash", "-e", "-o", "pipefail", "-c", code]
    proc = subprocess.Popen(command, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True)
    try:
        output, _ = proc.communicate(timeout=LIMIT_S)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)    # the block and everything it started
        proc.communicate()
        pytest.fail(f"ran over {LIMIT_S} s: mark it <!-- example: syntax only (why) --> or make it smaller")
    assert proc.returncode == 0, f"exit {proc.returncode}\n{output[-4000:]}"


def git_status() -> set[str]:
    done = subprocess.run(["git", "status", "--porcelain", "--untracked-files=all"], cwd=ROOT, capture_output=True,
                          text=True)
    return set(done.stdout.splitlines()) if done.returncode == 0 else set()


@pytest.fixture(scope="module", autouse=True)
def status_before() -> set[str]:
    return git_status()


def test_examples_leave_the_repository_as_they_found_it(status_before: set[str]) -> None:
    """Blocks write into ignored folders or a temporary one: ``git status`` shows nothing they made."""
    assert git_status() - status_before == set()
