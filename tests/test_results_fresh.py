"""Results that cannot go stale: every file under ``results/`` belongs to a group of
``results/sources.toml`` whose stamp names a clean commit and a command, and whose declared sources are
unchanged since that commit, unless the group says why it is left stale (``softenv.provenance``)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from softenv import provenance

ROOT = Path(__file__).resolve().parent.parent


def test_the_results_folder_checks() -> None:
    done = subprocess.run([sys.executable, "-m", "softenv.provenance", "check", "results"], cwd=ROOT,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr


def test_every_stamp_names_its_own_producer() -> None:
    """A group's first source is what made it (a script, or the package code a command runs), and its
    stamp's command names that script."""
    for group in provenance.read_manifest(ROOT / "results"):
        first = group.depends[0]
        stamp = provenance.read_stamp(ROOT / "results" / group.stamp)
        if first.startswith("scripts/") and stamp.command is not None:
            assert first in stamp.command, (group.name, first, stamp.command)


def _git(repo: Path, *args: str) -> str:
    return subprocess.run(["git", "-C", str(repo), *args], capture_output=True, text=True, check=True).stdout.strip()


def _commit(repo: Path, message: str) -> str:
    _git(repo, "add", "-A")
    _git(repo, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-q", "-m", message)
    return _git(repo, "rev-parse", "--short=12", "HEAD")


def _lock(folder: Path, repo: Path) -> None:
    (folder / provenance.LOCK).write_text(json.dumps(provenance.lock(folder, repo)))


@pytest.fixture
def repo(tmp_path: Path) -> Path:
    """A repository with one script, one library file and one result made at a clean commit."""
    repo = tmp_path / "repo"
    (repo / "src").mkdir(parents=True)
    (repo / "results").mkdir()
    _git(repo, "init", "-q")
    (repo / "src" / "law.py").write_text("K = 1\n")
    (repo / "src" / "other.py").write_text("X = 1\n")
    (repo / "make.py").write_text("print('made')\n")
    (repo / "results" / provenance.MANIFEST).write_text(
        '[law]\nfiles = ["law.md", "law_*.png"]\nstamp = "law.md"\ndepends = ["make.py", "src/law.py"]\n')
    made = _commit(repo, "code")
    (repo / "results" / "law.md").write_text(f"Made by `python make.py` at git {made} in 1 s.\n")
    (repo / "results" / "law_plot.png").write_bytes(b"\x89PNG\r\n")
    _lock(repo / "results", repo)
    _commit(repo, "results")
    return repo


def _states(repo: Path) -> dict[str, str]:
    return {f.group.name: f.state for f in provenance.check(repo / "results", repo)}


def test_a_result_stays_fresh_until_what_it_declares_changes(repo: Path) -> None:
    assert _states(repo) == {"law": "fresh"}
    (repo / "src" / "other.py").write_text("X = 2\n")          # not declared: still fresh
    _commit(repo, "elsewhere")
    assert _states(repo) == {"law": "fresh"}
    assert provenance.coverage(repo / "results", repo, provenance.read_manifest(repo / "results")) == []
    (repo / "src" / "law.py").write_text("K = 2\n")
    _commit(repo, "the law")
    [report] = provenance.check(repo / "results", repo)
    assert report.state == "stale" and "src/law.py" in report.reason and report.problem is not None
    (repo / "make.py").unlink()                               # a producer that left the tree is a change too
    _commit(repo, "gone")
    [report] = provenance.check(repo / "results", repo)
    assert report.state == "stale" and "make.py" in report.reason


def test_an_admitted_stale_group_must_be_stale(repo: Path) -> None:
    manifest = repo / "results" / provenance.MANIFEST
    manifest.write_text(manifest.read_text() + 'stale = "hours to remake"\n')
    _commit(repo, "mark")
    [report] = provenance.check(repo / "results", repo)
    assert report.state == "fresh" and "remove the mark" in (report.problem or "")
    (repo / "src" / "law.py").write_text("K = 2\n")
    _commit(repo, "the law")
    [report] = provenance.check(repo / "results", repo)
    assert report.state == "stale" and report.problem is None


def test_a_dirty_or_missing_stamp_or_a_stale_lock_is_unstamped(repo: Path) -> None:
    stamp = repo / "results" / "law.md"
    made = provenance.read_stamp(stamp).commit
    stamp.write_text(f"Made by `python make.py` at git {made} + uncommitted changes.\n")
    assert _states(repo) == {"law": "unstamped"}
    stamp.write_text("Made by `python make.py` (no commit).\n")
    assert _states(repo) == {"law": "unstamped"}
    head = _commit(repo, "more")
    stamp.write_text(f"Made by `python make.py` at git {head}.\n")    # remade, but the lock not rewritten
    [report] = provenance.check(repo / "results", repo)
    assert report.state == "unstamped" and "provenance lock" in report.reason
    _lock(repo / "results", repo)
    assert _states(repo) == {"law": "fresh"}


def test_the_check_needs_no_history(repo: Path, tmp_path: Path) -> None:
    """A shallow clone holds only HEAD; the lock carries the stamped commits' object ids."""
    (repo / "src" / "law.py").write_text("K = 2\n")
    _commit(repo, "the law")
    shallow = tmp_path / "shallow"
    subprocess.run(["git", "clone", "-q", "--depth", "1", f"file://{repo}", str(shallow)], check=True)
    assert _git(shallow, "rev-parse", "--is-shallow-repository") == "true"
    [report] = provenance.check(shallow / "results", shallow)
    assert report.state == "stale" and "src/law.py" in report.reason
    with pytest.raises(ValueError, match="does not have"):
        provenance.lock(shallow / "results", shallow)


def test_every_tracked_file_belongs_to_exactly_one_group(repo: Path) -> None:
    folder = repo / "results"
    (folder / "loose.csv").write_text("a\n")
    manifest = folder / provenance.MANIFEST
    manifest.write_text(manifest.read_text() + '\n[twice]\nfiles = ["law_plot.png", "missing.md"]\n'
                        'stamp = "missing.md"\ndepends = ["make.py"]\n')
    _commit(repo, "loose")
    problems = provenance.coverage(folder, repo, provenance.read_manifest(folder))
    assert "loose.csv: in no group of sources.toml" in problems
    assert "law_plot.png: in 2 groups (law, twice)" in problems
    assert "twice: lists 'missing.md', which matches no tracked file" in problems
    assert "twice: its stamp 'missing.md' is not one of its tracked files" in problems


@pytest.mark.parametrize("table, message", [
    ('files = ["a"]\nstamp = "a"\n', "depends must be a non-empty list"),
    ('files = []\nstamp = "a"\ndepends = ["x"]\n', "files must be a non-empty list"),
    ('files = ["a"]\nstamp = 3\ndepends = ["x"]\n', "stamp must be one file name, got 3"),
    ('files = ["a"]\nstamp = "a"\ndepends = ["x"]\nstale = ""\n', "stale must say why"),
    ('files = ["a"]\nstamp = "a"\ndepends = ["x"]\nmade = "y"\n', "unknown keys \\['made'\\]"),
])
def test_a_malformed_manifest_is_refused_naming_group_and_key(tmp_path: Path, table: str, message: str) -> None:
    (tmp_path / provenance.MANIFEST).write_text("[g]\n" + table)
    with pytest.raises(ValueError, match=r"\[g\].*" + message):
        provenance.read_manifest(tmp_path)


def test_stamps_as_the_producers_write_them(tmp_path: Path) -> None:
    cases = {
        "a.md": ("Made by `softenv compare --quick` at git 0123456789ab in 1.3 min", "softenv compare --quick"),
        "b.txt": ("made by: python scripts/x.py --out results at git 0123456789ab\n", "python scripts/x.py --out results"),
        "c.md": ("Made by `python s.py` at commit `git 0123456789ab`; built", "python s.py"),
        "d.json": ('{"command": "python s.py (at git 0123456789ab)"}', "python s.py (at git 0123456789ab)"),
    }
    for name, (text, command) in cases.items():
        (tmp_path / name).write_text(text)
        assert provenance.read_stamp(tmp_path / name) == provenance.Stamp(command, "0123456789ab", False), name
