"""The laryngoscope's batched twin at this commit against an earlier commit's, same machine, same hour
(issue 62, part 8: no speed has fallen). Writes ``README.md`` and ``results.json`` under ``--out``.

The earlier commit is checked out into a temporary git worktree; each measurement runs in a fresh
process of one tree or the other, the two alternating, one CPU thread, and each side's rate is the median
of its rounds (the 2-core machines drift by tens of percent within the hour, so only pairs taken
side by side compare). A round is each tree's own ``softenv.bench.env.twin_step_timing``:
``SoftSphereHaptic-v0``'s batched twin on its default engine, at 1, 8, 64, 1,024 and 8,192 envs, with
uniformly random actions (the blade on the incisors much of the time: the collision's workload) and with
pressing actions (the tongue's). Each round also times a fresh process of each tree from its first line
to its first step of 8 envs (imports, the env built from the scene cache, the kernel compiled or loaded),
with Warp's kernel cache as the earlier runs left it and empty (``WARP_CACHE_PATH`` a new folder). The
default reference, ``2576317``, is the last commit whose default engine was the numba kernel the Warp
kernel replaced; its own dependencies must be importable (numba).

    python scripts/speed_against.py [--ref 2576317] [--rounds 3] [--sizes 1 8 64 1024 8192]
                                    [--out results/speed-against-numba]
"""

from __future__ import annotations

import argparse
import json
import shlex
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from softenv._artifact import write_text
from softenv.bench import single_thread_environment
from softenv.bench.timing import code_revision

ROOT = Path(__file__).resolve().parent.parent
SIZES = (1, 8, 64, 1024, 8192)
WORKLOADS = ("random", "pressing")
# one round in one tree (argv: workload, sizes...): prints {size: env-steps/s}
ROUND = """
import json, sys
import numpy as np
from softenv.bench.env import twin_step_timing
from softenv.bench.haptic import press_actions
workload, sizes = sys.argv[1], [int(n) for n in sys.argv[2:]]
out = {}
for n in sizes:
    actions = list(press_actions(np.random.default_rng(0), (16, n, 4))) if workload == "pressing" else None
    out[n] = n / twin_step_timing("SoftSphereHaptic-v0", n, max(2, 20_000 // n), actions).median
print(json.dumps(out))
"""
# a fresh process's first step (no argv): seconds from its first line to its first step of 8 envs
FIRST_STEP = """
import json, time
started = time.perf_counter()
import gymnasium as gym
import softenv
venv = gym.make_vec("SoftSphereHaptic-v0", num_envs=8, vectorization_mode="vector_entry_point")
venv.reset(seed=0)
venv.step(venv.action_space.sample())
print(json.dumps(time.perf_counter() - started))
"""
KERNEL_CACHES = ("warm", "empty")


def tree_environment(tree: Path) -> dict[str, str]:
    """The environment of a fresh process running ``tree``'s code on one thread."""
    return {**single_thread_environment(), "PYTHONPATH": str(tree)}


def one_round(tree: Path, workload: str, sizes: list[int]) -> dict[int, float]:
    """Env-steps/s at each size, measured by a fresh process running ``tree``'s code."""
    done = subprocess.run([sys.executable, "-c", ROUND, workload, *map(str, sizes)], cwd=tree,
                          env=tree_environment(tree), capture_output=True, text=True, check=True)
    return {int(n): rate for n, rate in json.loads(done.stdout.strip().splitlines()[-1]).items()}


def first_step(tree: Path, kernel_cache: str) -> float:
    """Seconds a fresh process running ``tree``'s code takes to its first step (:data:`FIRST_STEP`), with
    Warp's kernel cache ``"warm"`` (where earlier processes left it) or ``"empty"``."""
    env = tree_environment(tree)
    with tempfile.TemporaryDirectory() as cache:
        if kernel_cache == "empty":
            env["WARP_CACHE_PATH"] = cache
        done = subprocess.run([sys.executable, "-c", FIRST_STEP], cwd=tree, env=env, capture_output=True, text=True,
                              check=True)
    return float(json.loads(done.stdout.strip().splitlines()[-1]))


def measure(trees: dict[str, Path], rounds: int, sizes: list[int]
            ) -> tuple[dict[str, dict[str, dict[int, list[float]]]], dict[str, dict[str, list[float]]]]:
    """Every round's rates ``[workload][tree][size]`` and first-step times ``[kernel cache][tree]``, the
    trees alternating. A first process of each tree (not counted) fills the scene's and the kernel's caches."""
    for tree in trees.values():
        first_step(tree, "warm")
    rates: dict[str, dict[str, dict[int, list[float]]]] = {
        w: {name: {n: [] for n in sizes} for name in trees} for w in WORKLOADS}
    starts: dict[str, dict[str, list[float]]] = {c: {name: [] for name in trees} for c in KERNEL_CACHES}
    for r in range(rounds):
        for workload in WORKLOADS:
            for name, tree in trees.items():
                for n, rate in one_round(tree, workload, sizes).items():
                    rates[workload][name][n].append(rate)
                print(f"round {r + 1}/{rounds} {workload} {name}: done", flush=True)
        for cache in KERNEL_CACHES:
            for name, tree in trees.items():
                starts[cache][name].append(first_step(tree, cache))
    return rates, starts


def report(samples: dict[str, dict[str, dict[int, list[float]]]], starts: dict[str, dict[str, list[float]]],
           ref: str, ref_commit: str, command: str) -> tuple[str, dict[str, Any]]:
    lines = [f"# The laryngoscope's batched twin at this commit against `{ref_commit}`", "",
             f"Made by `{command}` at commit `{code_revision()}`; the reference `{ref}` = `{ref_commit}` ran from a "
             "git worktree in the same venv. Fresh processes alternating between the trees, one CPU thread; each "
             "cell the median over rounds (the ratio's range over the rounds' pairs in brackets).", "",
             "| workload | envs | reference (env-steps/s) | this commit (env-steps/s) | this / reference |",
             "|---|---|---|---|---|"]
    table: list[dict[str, Any]] = []
    for workload, trees in samples.items():
        for n in trees["reference"]:
            old, new = samples[workload]["reference"][n], samples[workload]["this commit"][n]
            pairs = np.array(new) / np.array(old)
            ratio = float(np.median(new) / np.median(old))
            lines.append(f"| {workload} | {n:,} | {np.median(old):,.0f} | {np.median(new):,.0f} | {ratio:.2f} "
                         f"[{pairs.min():.2f}, {pairs.max():.2f}] |")
            table.append({"workload": workload, "envs": n, "reference": old, "this_commit": new, "ratio": ratio})
    lowest = min(row["ratio"] for row in table)
    lines += ["", f"Lowest ratio: {lowest:.2f} ({'no' if lowest >= 1.0 else 'a'} row slower than the reference).", "",
              "A fresh process from its first line to its first step of 8 envs (seconds, median over rounds; the "
              "numba kernel has no disk cache, so it compiles in every process):", "",
              "| Warp's kernel cache | reference (s) | this commit (s) |", "|---|---|---|"]
    lines += [f"| {cache} | {np.median(by_tree['reference']):.2f} | {np.median(by_tree['this commit']):.2f} |"
              for cache, by_tree in starts.items()]
    return "\n".join(lines) + "\n", {"command": command, "commit": code_revision(), "reference": ref,
                                    "reference_commit": ref_commit, "rows": table, "first_step_s": starts}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--ref", default="2576317", help="the earlier commit (default: the last on numba)")
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds a tree (default 3)")
    parser.add_argument("--sizes", type=int, nargs="+", default=list(SIZES), help="batch sizes (envs)")
    parser.add_argument("--out", type=Path, default=Path("results/speed-against-numba"))
    args = parser.parse_args()
    if args.rounds < 1:
        raise SystemExit(f"--rounds {args.rounds}: at least 1")
    if min(args.sizes) < 1:
        raise SystemExit(f"--sizes {args.sizes}: every size at least 1")
    command = shlex.join(["python", "scripts/speed_against.py", *sys.argv[1:]])
    ref_commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short=12", args.ref], capture_output=True,
                                text=True, check=True).stdout.strip()
    with tempfile.TemporaryDirectory() as tmp:
        old = Path(tmp) / "reference"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(old), ref_commit], check=True,
                       capture_output=True)
        try:
            samples, starts = measure({"reference": old, "this commit": ROOT}, args.rounds, args.sizes)
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(old)], check=True)
    text, data = report(samples, starts, args.ref, ref_commit, command)
    write_text(args.out / "README.md", text)
    write_text(args.out / "results.json", json.dumps(data, indent=2) + "\n")
    print(text)


if __name__ == "__main__":
    main()
