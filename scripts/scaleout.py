"""Wall time of ``softenv compare`` by executor, and proof that the executor does not change a number.

Runs one benchmark plan three ways from fresh training runs -- one process (``--jobs 1``), two local
worker processes (``--jobs 2``) and a local Ray instance with two CPUs (``--executor ray --jobs 2``)
-- checks that every table cell except the measured decision times is identical, and writes
``results/scaleout.md``. CartPole-v1's step rate, measured first, says how fast the machine was.

    python scripts/scaleout.py                 # the quick plan (SoftSphere-v0, short agent budgets)
    python scripts/scaleout.py --plan full     # the full benchmark (hours on 2 cores)
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from softenv._artifact import write_text

ROOT = Path(__file__).resolve().parent.parent
RUNS = {"one process (--jobs 1)": ["--jobs", "1"], "2 local workers (--jobs 2)": ["--jobs", "2"],
        "local Ray, 2 CPUs (--executor ray --jobs 2)": ["--executor", "ray", "--jobs", "2"]}


def compare(args: list[str], out: Path, runs: Path) -> tuple[float, dict]:
    """Run ``softenv compare`` from empty training runs; returns its wall time and its JSON report."""
    shutil.rmtree(runs, ignore_errors=True)
    command = [sys.executable, "-m", "softenv", "compare", *args, "--out", str(out), "--runs", str(runs)]
    print("$ softenv", " ".join(command[3:]), flush=True)
    t0 = time.perf_counter()
    subprocess.run(command, check=True, cwd=ROOT)
    wall = time.perf_counter() - t0
    stem = "benchmark_quick" if "--quick" in args else "benchmark"
    return wall, json.loads((out / f"{stem}.json").read_text())


def cells(report: dict) -> str:
    """Every number of the table but the decision times (measured, so never equal twice)."""
    return json.dumps([{k: v for k, v in s.items() if k != "decision_us"} for s in report["summaries"]], sort_keys=True)


def job_seconds(report: dict) -> tuple[float, float]:
    """The run's per-job wall times added up: agent jobs (training and evaluation), and all the others."""
    from softenv.baselines.benchmark import AGENTS

    timings = report["timings_s"]            # keyed "<scene> <policy>"; an agent's seeds are summed in one entry
    agents = sum(t for key, t in timings.items() if key.rsplit(" ", 1)[-1] in AGENTS)
    return agents, sum(timings.values()) - agents


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plan", choices=["quick", "full"], default="quick")
    args = parser.parse_args()
    from softenv.bench.timing import cartpole_steps_per_second

    cartpole = 1.0 / cartpole_steps_per_second(100_000).median
    plan = ["--quick"] if args.plan == "quick" else []
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for i, (how, extra) in enumerate(RUNS.items()):
            results[how] = compare(plan + extra, Path(tmp) / str(i), ROOT / "runs" / f"scaleout-{args.plan}-{i}")
    (wall1, rep1), (wall2, rep2), (wall_ray, rep_ray) = results.values()
    lines = ["# softenv compare: wall time by executor\n",
             f"Made by `python scripts/scaleout.py --plan {args.plan}` at {rep1['provenance']['code']} ({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; "
             f"{rep1['provenance']['machine']}; CartPole-v1 stepped at {cartpole:,.0f} steps/s during this run). The "
             f"{args.plan} plan: {len(rep1['summaries'])} table cells (policy x scene); every run starts "
             "from empty training runs, BLAS and torch on one thread per worker.\n",
             "| executor | wall time (s) | against one process | agent jobs summed (s) | other jobs summed (s) |",
             "|---|---|---|---|---|"]
    lines += [f"| {how} | {wall:.0f} | {wall1 / wall:.2f}x | {agents:.0f} | {others:.0f} |"
              for how, (wall, rep) in results.items() for agents, others in [job_seconds(rep)]]
    (agents1, others1), (agents2, others2) = job_seconds(rep1), job_seconds(rep2)
    lines += ["", f"Run two at a time, the agent jobs took {agents2 / agents1:.2f}x their time in one process and the "
              f"other jobs {others2 / others1:.2f}x: the factors that turn a two-worker run's summed job times into "
              "an estimate of one process."]
    lines += ["", f"Ray's overhead over local workers: {wall_ray - wall2:+.0f} s ({100 * (wall_ray / wall2 - 1):+.0f} %): "
              "starting the local instance and shipping each job's code and result.", "",
              "Identical results (every table cell except the measured decision times):", "",
              f"- 2 local workers against one process: {'yes' if cells(rep2) == cells(rep1) else '**no**'}",
              f"- Ray against one process: {'yes' if cells(rep_ray) == cells(rep1) else '**no**'}"]
    write_text(ROOT / "results" / "scaleout.md", "\n".join(lines) + "\n")
    print("\n".join(lines))
    if not cells(rep2) == cells(rep1) == cells(rep_ray):
        sys.exit(1)


if __name__ == "__main__":
    main()
