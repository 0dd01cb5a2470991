"""Fault injection: stop ``softenv compare`` at random points, resume it, and compare the tables.

    python scripts/fault_tolerance.py --out results            # writes results/fault_tolerance.md/.json
    python scripts/fault_tolerance.py --smoke --out /tmp/ft     # two stops of a small plan (tests/test_fault_tolerance.py)

Full form: one uninterrupted ``softenv compare --quick --jobs 2`` (the reference), then

* local trials: the parent killed (SIGKILL, SIGTERM or SIGINT, in turn) once a number of jobs drawn
  uniformly from 1 to 90 % of the plan's have finished (a point in the run's work, not in time: another
  process's load cannot move it past the end), then the same command run again to the end;
* Ray trials (``--executor ray``): a task worker (``ray::_attempt``) killed by SIGKILL mid-job, which
  Ray retries within the run; and the driver killed by SIGKILL, then the command run again.

For each trial: the exit status; how long the longest process the run started outlived its parent (or,
for a killed Ray worker, nothing to wait for); the resumed run's "resuming: k of n jobs" line; the
table cells equal to the reference's (every column but the measured decision time); files found
truncated in the report and run directories (each ``.npz``, ``.zip``, ``.json``, ``.png`` opened and
read whole); and temporary files left behind by a write that was stopped (never read).
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from softenv._artifact import write_text
from softenv.bench.timing import code_revision
from softenv.parallel import descendants

ROOT = Path(__file__).resolve().parents[1]
QUICK = ["compare", "--quick", "--jobs", "2"]
SMOKE = ["compare", "--scenes", "SoftSphere-v0", "--policies", "zero", "random", "direct-poly3", "--agents",
         "--episodes", "8", "--jobs", "2"]


def alive(pid: int) -> bool:
    """A process that runs (a zombie has ended: only its exit status waits to be read)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


def start(args: list[str], out: Path, runs: Path) -> subprocess.Popen:
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    return subprocess.Popen([sys.executable, "-m", "softenv", *args, "--out", str(out), "--runs", str(runs)], cwd=ROOT,
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            start_new_session=True)     # a signal for the parent alone, as `kill PID` sends it


def finish(args: list[str], out: Path, runs: Path) -> tuple[int, str]:
    proc = start(args, out, runs)
    output, _ = proc.communicate()
    return proc.returncode, output.decode(errors="replace")


def outlived(pids: set[int], since: float, limit_s: float = 300.0) -> float:
    """Seconds from ``since`` (monotonic) until none of ``pids`` runs."""
    while any(alive(p) for p in pids) and time.monotonic() - since < limit_s:
        time.sleep(0.05)
    return time.monotonic() - since


RAY_SERVICES = ("gcs_server", "raylet", "dashboard", "DashboardAgent", "RuntimeEnvAgent", "log_monitor", "monitor.py")


def survivors(seen: dict[int, str], since: float) -> dict[str, float]:
    """How long after ``since`` (the stop, monotonic) the processes ``seen`` still ran: the job workers
    (local workers, Ray task workers) and, apart, Ray's own services (a local instance's head node)."""
    services = {pid for pid, line in seen.items() if any(name in line for name in RAY_SERVICES)}
    return {"orphan_s": round(outlived(set(seen) - services, since), 2),
            "ray_services_s": round(outlived(services, since), 1) if services else 0.0}


def cells(out: Path) -> list[list[str]]:
    """The report's CSV rows, without the measured decision time."""
    (path,) = out.glob("benchmark*.csv")
    rows = list(csv.reader(io.StringIO("".join(line for line in path.read_text().splitlines(True)
                                               if not line.startswith("#")))))
    drop = rows[0].index("decision_us")
    return [[c for i, c in enumerate(row) if i != drop] for row in rows]


def damaged(*dirs: Path) -> tuple[list[str], list[str]]:
    """Files that do not read whole, and temporary files a stopped write left."""
    bad, litter = [], []
    for root in dirs:
        for path in sorted(p for p in root.rglob("*") if p.is_file()):
            if path.suffix == ".tmp":
                litter.append(str(path))
                continue
            try:
                if path.suffix == ".npz":
                    with np.load(path, allow_pickle=False) as data:
                        for name in data.files:
                            data[name]
                elif path.suffix == ".zip":
                    with zipfile.ZipFile(path) as z:
                        assert z.testzip() is None
                elif path.suffix == ".json":
                    json.loads(path.read_text())
                elif path.suffix == ".png":
                    assert path.read_bytes()[-8:-4] == b"IEND"
                elif path.suffix in (".md", ".csv"):
                    assert path.read_text().endswith("\n")
            except Exception as exc:  # noqa: BLE001 - every failure to read is a finding
                bad.append(f"{path}: {type(exc).__name__}")
    return bad, litter


def trial(kind: str, args: list[str], after: int, sig: signal.Signals, work: Path,
          reference: list[list[str]]) -> dict[str, Any]:
    """One stop and resume: ``kind`` is ``parent`` (signal the command) or ``ray-worker`` (SIGKILL a Ray
    task worker; Ray retries it), once ``after`` jobs have finished."""
    out, runs = work / "out", work / "runs"
    proc = start(args, out, runs)
    os.set_blocking(proc.stdout.fileno(), False)      # type: ignore[union-attr]
    t0 = time.monotonic()
    seen: dict[int, str] = {}                           # every process the run started: its command line
    text, struck = "", None
    while proc.poll() is None and struck is None:
        seen |= {pid: cmdline(pid) for pid in descendants(proc.pid) - seen.keys()}
        text += (proc.stdout.read() or b"").decode(errors="replace")   # type: ignore[union-attr]
        due = f"[{after}/" in text
        if due and kind == "ray-worker":
            workers = [pid for pid in seen if alive(pid) and cmdline(pid).startswith("ray::_attempt")]
            if workers:                                     # else wait until a job runs
                os.kill(workers[0], signal.SIGKILL)
                struck = time.monotonic() - t0
        elif due:
            os.kill(proc.pid, sig)
            struck = time.monotonic() - t0
            while proc.poll() is None:                    # the parent's own end (SIGTERM, SIGINT: its cleanup)
                time.sleep(0.01)
        time.sleep(0.05)
    stopped = time.monotonic()                        # workers outlive the parent from here
    os.set_blocking(proc.stdout.fileno(), True)       # type: ignore[union-attr]
    record: dict[str, Any] = {"kind": kind, "signal": sig.name if kind == "parent" else "SIGKILL (one Ray worker)",
                              "after_jobs": after,
                              "at_s": round(struck, 1) if struck is not None else "never (the run had ended)"}
    if kind == "parent":
        rest, _ = proc.communicate()
        text += rest.decode(errors="replace")
        record["exit_status"] = proc.returncode
        record |= survivors(seen, stopped)
        record["stop_line"] = next((line for line in text.splitlines() if "stopped by" in line), "")
        status, resumed = finish(args, out, runs)
        record["resumed_exit_status"] = status
        record["resume_line"] = next((line.split(" (")[0] for line in resumed.splitlines() if line.startswith("resuming:")),
                                     "nothing finished before the stop: ran from the start")
    else:
        proc.communicate()
        record["exit_status"] = proc.returncode
        record |= survivors(seen, time.monotonic())      # after the run's own end
        record["resume_line"] = "(not stopped: Ray retried the task)"
    got = cells(out)
    record["cells_equal"] = sum(a == b for a, b in zip(got[1:], reference[1:])) if len(got) == len(reference) else 0
    record["cells"] = len(reference) - 1
    bad, litter = damaged(out, runs)
    record["truncated"] = bad
    record["temporary_left"] = len(litter)
    return record


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, required=True, help="where fault_tolerance.md and .json go")
    parser.add_argument("--work", type=Path, default=Path("runs/fault_tolerance"), help="scratch runs go in a fresh folder here (default: runs/fault_tolerance, ignored)")
    parser.add_argument("--local-kills", type=int, default=4)
    parser.add_argument("--ray-kills", type=int, default=2, help="of each Ray kind (a worker, the driver)")
    parser.add_argument("--seed", type=int, default=0, help="draws the kill points")
    parser.add_argument("--smoke", action="store_true",
                        help="a small plan stopped once by SIGKILL and once by SIGTERM, each after its first finished job")
    a = parser.parse_args(argv)
    args = SMOKE if a.smoke else QUICK
    a.work.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix="run-", dir=a.work)).resolve()   # fresh: an earlier run's jobs would resume
    t0 = time.monotonic()
    status, text = finish(args, work / "reference" / "out", work / "reference" / "runs")
    if status != 0:
        raise SystemExit(f"the reference run failed ({status}):\n{text}")
    run_s = time.monotonic() - t0
    reference = cells(work / "reference" / "out")
    jobs = int(re.findall(r"\[\d+/(\d+) jobs", text)[-1])
    rng = np.random.default_rng(a.seed)
    draw = lambda top: int(rng.integers(1, max(2, int(top * jobs)) + 1))  # noqa: E731 - finished jobs
    plans: list[tuple[str, list[str], int, signal.Signals]] = []
    if a.smoke:
        plans += [("parent", args, 1, signal.SIGKILL), ("parent", args, 1, signal.SIGTERM)]
    else:
        signals = [signal.SIGKILL, signal.SIGTERM, signal.SIGINT]
        plans += [("parent", args, draw(0.9), signals[i % 3]) for i in range(a.local_kills)]
        ray = [*args, "--executor", "ray"]
        plans += [("ray-worker", ray, draw(0.6), signal.SIGKILL) for _ in range(a.ray_kills)]
        plans += [("parent", ray, draw(0.9), signal.SIGKILL) for _ in range(a.ray_kills)]
    records = []
    for i, (kind, cmd, after, sig) in enumerate(plans):
        record = trial(kind, cmd, after, sig, work / f"trial-{i}", reference)
        record["executor"] = "ray" if "ray" in cmd else "local"
        records.append(record)
        print(json.dumps(record), flush=True)
    command = "python scripts/fault_tolerance.py " + " ".join(sys.argv[1:] if argv is None else argv)
    summary = {"command": command, "code": code_revision(), "compare": "softenv " + " ".join(args),
               "reference_s": round(run_s, 1),
               "trials": records, "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
    a.out.mkdir(parents=True, exist_ok=True)
    write_text(a.out / "fault_tolerance.json", json.dumps(summary, indent=1) + "\n")
    lines = ["# Fault tolerance: `softenv compare` stopped and resumed\n",
             f"Made by `{command}` at {summary['code']} ({summary['date']}, {os.cpu_count()} cores). Each trial runs `{summary['compare']}` (the uninterrupted "
             f"reference took {run_s:.0f} s), stops it, runs the same command again, and compares the table with the "
             "reference's: every column but the measured decision time. *Outlived*: how long after the stop the last "
             "process the run had started still ran (SIGKILL gives the parent no chance to act: its workers see it "
             "gone). *Truncated*: files in the report and run directories that do not read whole. *Temporary*: files "
             "a stopped write left beside its target (never read).\n",
             "| # | executor | stopped by | after jobs | at (s) | exit status | workers outlived (s) | Ray services "
             "outlived (s) | resumed run | cells equal | truncated | temporary |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for i, r in enumerate(records):
        lines.append(f"| {i} | {r['executor']} | {r['signal']} | {r['after_jobs']} of {jobs} | {r['at_s']} | "
                     f"{r['exit_status']} | {r['orphan_s']} | "
                     f"{r['ray_services_s'] if r['executor'] == 'ray' else '-'} | "
                     f"{r['resume_line']} | {r['cells_equal']} of {r['cells']} | {len(r['truncated'])} | "
                     f"{r['temporary_left']} |")
    stopped = [r for r in records if r.get("stop_line")]
    if stopped:
        lines += ["", "What a stopped run said (SIGTERM, SIGINT):", "", *sorted({f"    {r['stop_line']}" for r in stopped})]
    write_text(a.out / "fault_tolerance.md", "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
