"""Whether a results folder still describes the code: each group of files names the clean commit and the
command that made it, and the sources it declares it depends on must be unchanged since.

A folder's ``sources.toml`` declares its groups (tables keyed by name)::

    [stability]
    files = ["stability.md"]              # paths or globs relative to the folder
    stamp = "stability.md"                # the file whose text names the commit and the command
    depends = ["scripts/stability.py", "softenv/envs"]   # repository paths the numbers depend on
    stale = "why it is left stale"        # optional: an admitted stale group (it must really be stale)

A stamp is what every producer here already writes: ``Made by `COMMAND` at git COMMIT`` (a JSON file's
``command`` field may carry both). ``sources.lock`` (JSON, written by ``python -m softenv.provenance lock``)
records each dependency's git object id at its group's stamped commit, so that checking needs only the
checked-out commit, not the history (a shallow clone checks as well as a full one). ``check`` reports a
group as

* ``unstamped``: no commit in its stamp, or one with uncommitted changes, or a stamp the lock does not match;
* ``stale``: a dependency's object at HEAD differs from the one at its stamp (or is gone);
* ``fresh`` otherwise.
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import re
import subprocess
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path

MANIFEST = "sources.toml"
LOCK = "sources.lock"
LOCK_FORMAT = 1
_STAMP = re.compile(r"git (?P<commit>[0-9a-f]{12})\b(?P<dirty> \+ uncommitted changes)?")
_COMMAND = re.compile(r"[Mm]ade by:? `?(?P<command>[^`\n]+?)`? at (?:commit )?`?git [0-9a-f]{12}")


@dataclass(frozen=True)
class Group:
    """One declared group of result files (a table of ``sources.toml``)."""

    name: str
    files: tuple[str, ...]
    stamp: str
    depends: tuple[str, ...]
    stale: str | None = None


@dataclass(frozen=True)
class Stamp:
    """What a group's stamp file says made it."""

    command: str | None
    commit: str | None
    dirty: bool


@dataclass(frozen=True)
class Freshness:
    """A group's standing against the checked-out commit."""

    group: Group
    stamp: Stamp
    state: str                  # "fresh", "stale" or "unstamped"
    reason: str                 # why it is not fresh ("" when fresh)

    @property
    def problem(self) -> str | None:
        """What fails the check: a group not fresh without an admitted reason, or one admitted stale
        that is fresh (its mark must go)."""
        if self.state != "fresh" and self.group.stale is None:
            return f"{self.group.name}: {self.state}: {self.reason}"
        if self.state == "fresh" and self.group.stale is not None:
            return f"{self.group.name}: marked stale ({self.group.stale!r}) but fresh: remove the mark"
        return None


def _git(repo: Path, *args: str) -> str | None:
    done = subprocess.run(["git", "-C", str(repo), *args], capture_output=True, text=True, timeout=60)
    return done.stdout.strip() if done.returncode == 0 else None


def read_manifest(folder: Path) -> list[Group]:
    """The groups ``folder/sources.toml`` declares, checked for shape (ValueError naming the group and key)."""
    with open(folder / MANIFEST, "rb") as f:
        tables = tomllib.load(f)
    groups = []
    for name, table in tables.items():
        where = f"{folder / MANIFEST} [{name}]"
        if not isinstance(table, dict):
            raise ValueError(f"{where}: must be a table with files, stamp and depends, got {table!r}")
        unknown = set(table) - {"files", "stamp", "depends", "stale"}
        if unknown:
            raise ValueError(f"{where}: unknown keys {sorted(unknown)}; allowed: files, stamp, depends, stale")
        for key in ("files", "depends"):
            value = table.get(key)
            if not (isinstance(value, list) and value and all(isinstance(v, str) for v in value)):
                raise ValueError(f"{where}: {key} must be a non-empty list of paths, got {value!r}")
        if not isinstance(table.get("stamp"), str):
            raise ValueError(f"{where}: stamp must be one file name, got {table.get('stamp')!r}")
        stale = table.get("stale")
        if stale is not None and not (isinstance(stale, str) and stale.strip()):
            raise ValueError(f"{where}: stale must say why in words, got {stale!r}")
        groups.append(Group(name, tuple(table["files"]), table["stamp"], tuple(table["depends"]), stale))
    return groups


def read_stamp(path: Path) -> Stamp:
    """The commit and command a stamp file names (the first ``git <12 hex>`` in it)."""
    try:
        text = path.read_text(encoding="utf-8")
    except (UnicodeDecodeError, FileNotFoundError):     # an image carries no stamp; coverage names a missing file
        return Stamp(None, None, False)
    command = None
    if path.suffix == ".json":
        record = json.loads(text)
        command = record.get("command") if isinstance(record, dict) else None
        command = command if isinstance(command, str) else None
    found = _COMMAND.search(text)
    if found and command is None:
        command = found["command"]
    commit = _STAMP.search(text)
    if commit is None:
        return Stamp(command, None, False)
    return Stamp(command, commit["commit"], commit["dirty"] is not None)


def _object_ids(repo: Path, commit: str, paths: tuple[str, ...]) -> dict[str, str | None]:
    return {p: _git(repo, "rev-parse", "--verify", "-q", f"{commit}:{p}") for p in paths}


def _tracked(repo: Path, folder: Path) -> list[str]:
    listed = _git(repo, "ls-files", "--", str(folder.resolve().relative_to(repo.resolve())))
    prefix = folder.resolve().relative_to(repo.resolve()).as_posix() + "/"
    return sorted(p[len(prefix):] for p in (listed or "").splitlines() if p)


def coverage(folder: Path, repo: Path, groups: list[Group]) -> list[str]:
    """Problems with which group holds which file: a tracked file in no group or in two, a file a group
    lists that is not there."""
    tracked = [p for p in _tracked(repo, folder) if p not in (MANIFEST, LOCK)]
    owners: dict[str, list[str]] = {p: [] for p in tracked}
    problems = []
    for group in groups:
        for pattern in group.files:
            matched = [p for p in tracked if fnmatch.fnmatchcase(p, pattern)]
            if not matched:
                problems.append(f"{group.name}: lists {pattern!r}, which matches no tracked file")
            for p in matched:
                owners[p].append(group.name)
        if group.stamp not in owners or group.name not in owners[group.stamp]:
            problems.append(f"{group.name}: its stamp {group.stamp!r} is not one of its tracked files")
    problems += [f"{p}: in no group of {MANIFEST}" for p, o in owners.items() if not o]
    problems += [f"{p}: in {len(o)} groups ({', '.join(o)})" for p, o in owners.items() if len(o) > 1]
    return problems


def lock(folder: Path, repo: Path) -> dict:
    """The lock for ``folder``: each stamped group's commit and its dependencies' object ids there
    (needs the stamped commits in the history)."""
    entries = {}
    for group in read_manifest(folder):
        stamp = read_stamp(folder / group.stamp)
        if stamp.commit is None or stamp.dirty:
            continue
        full = _git(repo, "rev-parse", "--verify", "-q", f"{stamp.commit}^{{commit}}")
        if full is None:
            raise ValueError(f"{group.name}: its stamp names commit {stamp.commit}, which this repository "
                             f"does not have (a shallow clone? lock where the history is)")
        entries[group.name] = {"commit": stamp.commit, "depends": _object_ids(repo, full, group.depends)}
    return {"format": LOCK_FORMAT, "groups": entries}


def check(folder: Path, repo: Path) -> list[Freshness]:
    """Every group of ``folder`` against the checked-out commit (HEAD), through ``folder/sources.lock``."""
    locked = json.loads((folder / LOCK).read_text(encoding="utf-8"))
    if locked.get("format") != LOCK_FORMAT:
        raise ValueError(f"{folder / LOCK}: format {locked.get('format')!r}, this softenv reads {LOCK_FORMAT}")
    report = []
    for group in read_manifest(folder):
        stamp = read_stamp(folder / group.stamp)
        entry = locked["groups"].get(group.name)
        if stamp.commit is None:
            report.append(Freshness(group, stamp, "unstamped", f"{group.stamp} names no git commit"))
        elif stamp.dirty:
            report.append(Freshness(group, stamp, "unstamped",
                                    f"{group.stamp} was made from uncommitted changes to {stamp.commit}"))
        elif stamp.command is None:
            report.append(Freshness(group, stamp, "unstamped", f"{group.stamp} names no command"))
        elif entry is None or entry["commit"] != stamp.commit or set(entry["depends"]) != set(group.depends):
            report.append(Freshness(group, stamp, "unstamped", f"{LOCK} does not match its stamp or "
                                    f"depends: run python -m softenv.provenance lock {folder}"))
        else:
            now = _object_ids(repo, "HEAD", group.depends)
            changed = [p for p in group.depends if entry["depends"][p] is None or now[p] != entry["depends"][p]]
            if changed:
                report.append(Freshness(group, stamp, "stale", f"changed since {stamp.commit}: {', '.join(changed)}"))
            else:
                report.append(Freshness(group, stamp, "fresh", ""))
    return report


def table(report: list[Freshness]) -> str:
    """The report as a markdown table: group, state, commit, command, and why it is not fresh."""
    lines = ["| results | state | made at | by | why not fresh |", "|---|---|---|---|---|"]
    for f in report:
        why = f.group.stale or f.reason
        lines.append(f"| {f.group.name} | {f.state} | {f.stamp.commit or ''} | "
                     f"{'`' + f.stamp.command.replace('|', '/') + '`' if f.stamp.command else ''} | {why} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m softenv.provenance", description=__doc__.split("\n\n")[0])
    parser.add_argument("action", choices=["check", "lock", "table"],
                        help="check: exit 1 on a problem; lock: rewrite sources.lock; table: print states")
    parser.add_argument("folder", type=Path, nargs="?", default=Path("results"))
    args = parser.parse_args(argv)
    repo_text = _git(args.folder, "rev-parse", "--show-toplevel")
    if repo_text is None:
        parser.error(f"folder {str(args.folder)!r} is not inside a git repository")
    repo = Path(repo_text)
    if args.action == "lock":
        (args.folder / LOCK).write_text(json.dumps(lock(args.folder, repo), indent=1, sort_keys=True) + "\n",
                                        encoding="utf-8")
        return 0
    report = check(args.folder, repo)
    if args.action == "table":
        print(table(report), end="")
        return 0
    problems = coverage(args.folder, repo, read_manifest(args.folder))
    problems += [f.problem for f in report if f.problem]
    for p in problems:
        print(p)
    counts = {s: sum(f.state == s for f in report) for s in ("fresh", "stale", "unstamped")}
    print(f"{len(report)} groups: {counts['fresh']} fresh, {counts['stale']} stale, {counts['unstamped']} unstamped; "
          f"{len(problems)} problems", file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
