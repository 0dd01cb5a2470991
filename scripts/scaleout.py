"""Wall time of ``softenv compare`` by executor, and proof that the executor does not change a number.

Runs the full benchmark with ``--jobs 1`` and ``--jobs 2`` (the second one writes ``results/benchmark.*``),
and the quick benchmark over local workers and over a local Ray instance, each from fresh training
runs; checks that every table cell except the measured decision times is identical; writes
``results/scaleout.md``. Takes about 80 minutes on 2 cores.

    python scripts/scaleout.py [--skip-full]
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

ROOT = Path(__file__).resolve().parent.parent


def compare(args: list[str], out: Path, runs: Path) -> tuple[float, dict]:
    """Run ``softenv compare`` from fresh runs; returns its wall time and its JSON report."""
    shutil.rmtree(runs, ignore_errors=True)
    command = [sys.executable, "-m", "softenv", "compare", *args, "--out", str(out), "--runs", str(runs)]
    print("$", " ".join(command[2:]), flush=True)
    t0 = time.perf_counter()
    subprocess.run(command, check=True, cwd=ROOT)
    wall = time.perf_counter() - t0
    stem = "benchmark_quick" if "--quick" in args else "benchmark"
    return wall, json.loads((out / f"{stem}.json").read_text())


def cells(report: dict) -> str:
    """Every number of the table but the decision times (measured, so never equal twice)."""
    return json.dumps([{k: v for k, v in s.items() if k != "decision_us"} for s in report["summaries"]], sort_keys=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--skip-full", action="store_true", help="only the quick benchmark (local against Ray)")
    args = parser.parse_args()
    rows, checks = [], []
    with tempfile.TemporaryDirectory() as tmp:
        scratch = Path(tmp)
        if not args.skip_full:
            wall1, rep1 = compare(["--jobs", "1"], scratch / "jobs1", ROOT / "runs" / "scaleout-jobs1")
            wall2, rep2 = compare(["--jobs", "2"], ROOT / "results", ROOT / "runs" / "scaleout-jobs2")
            rows += [("full", "local, --jobs 1", wall1, len(rep1["summaries"])),
                     ("full", "local, --jobs 2", wall2, len(rep2["summaries"]))]
            checks.append(("full benchmark: --jobs 2 against --jobs 1", cells(rep1) == cells(rep2)))
        wall_l, rep_l = compare(["--quick", "--jobs", "2"], scratch / "quick-local", ROOT / "runs" / "scaleout-quick-local")
        wall_r, rep_r = compare(["--quick", "--jobs", "2", "--executor", "ray"], scratch / "quick-ray",
                                ROOT / "runs" / "scaleout-quick-ray")
        rows += [("quick", "local, --jobs 2", wall_l, len(rep_l["summaries"])),
                 ("quick", "Ray (local instance, 2 CPUs), --jobs 2", wall_r, len(rep_r["summaries"]))]
        checks.append(("quick benchmark: Ray against local", cells(rep_l) == cells(rep_r)))
        machine = rep_l["provenance"]["machine"]
    lines = ["# softenv compare: wall time by executor\n",
             f"Made by `python scripts/scaleout.py{' --skip-full' if args.skip_full else ''}` "
             f"({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; {machine}). Every run starts from empty "
             "training runs; BLAS and torch on one thread per worker.\n",
             "| plan | executor | wall time (min) | cells |", "|---|---|---|---|"]
    lines += [f"| {plan} | {how} | {wall / 60:.1f} | {n} |" for plan, how, wall, n in rows]
    if not args.skip_full:
        lines.append(f"\nSpeed-up of `--jobs 2` over `--jobs 1`: {rows[0][2] / rows[1][2]:.2f}x.")
    lines.append(f"Ray's overhead over local workers (quick plan): {wall_r - wall_l:+.0f} s "
                 f"({100 * (wall_r / wall_l - 1):+.0f} %).\n")
    lines += ["Identical results (every table cell except the measured decision times):", ""]
    lines += [f"- {what}: {'yes' if same else '**no**'}" for what, same in checks]
    (ROOT / "results" / "scaleout.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    if not all(same for _, same in checks):
        sys.exit(1)


if __name__ == "__main__":
    main()
