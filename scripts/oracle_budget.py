"""How close is the planning oracle to an optimum? Its score against its search budget, per episode.

    python scripts/oracle_budget.py --out results/oracle-budget [--episodes 20] [--iterations 120]

On each laryngoscope scene the first ``--episodes`` test episodes are planned by the benchmark's
trajectory oracle (``softenv.baselines.planner.TrajectoryOracle``, its shipped settings but the number of
iterations) from three starts: the scripted expert's actions with the shipped sampler seed (the search
the shipped anchors ran, continued past its 30 iterations), the same with another sampler seed (a
restart), and no force at all (a start that owes nothing to the expert). Each episode's best summed
shape error after every iteration is scored against the shipped anchors (0 no force, 100 the shipped
oracle), so the table says how much a longer search, another restart or another start would move the
100, and on how many episodes. The best of the three starts at the full budget is the strongest plan
found here.

Writes ``README.md`` (the table), ``budget.json`` (every episode's curve) and ``budget.png`` into
``--out``; one BLAS thread.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from softenv._artifact import save_figure, write_text  # noqa: E402
from softenv.baselines.anchors import load_anchors, oracle_of, scene_config  # noqa: E402
from softenv.baselines.evaluate import SCENES, device_kind, episode_seeds  # noqa: E402
from softenv.baselines.planner import TrajectoryOracle  # noqa: E402
from softenv.baselines.policies import make_baseline  # noqa: E402
from softenv.bench import rerun_single_threaded  # noqa: E402
from softenv.bench.timing import code_revision  # noqa: E402
from softenv.envs.world import World  # noqa: E402

LARYNGOSCOPE = [s for s in SCENES if device_kind(s) == "laryngoscope" and "Airway" not in s]
STARTS = {"expert": ("expert", 0), "expert, another sampler seed": ("expert", 1), "no force": ("zero", 0)}
MARKS = (0, 10, 30, 60, 120, 240)          # iterations tabled (those within the run)


def scores(errors: np.ndarray, zero: np.ndarray, oracle: np.ndarray) -> np.ndarray:
    """Normalized scores of error sums ``(..., episodes)`` against per-episode anchors."""
    return 100.0 * (zero - errors) / (zero - oracle)


def main() -> None:
    rerun_single_threaded()
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--scenes", nargs="+", choices=LARYNGOSCOPE, default=LARYNGOSCOPE)
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--iterations", type=int, default=120)
    parser.add_argument("--starts", nargs="+", choices=list(STARTS), default=list(STARTS))
    args = parser.parse_args()
    if args.episodes < 1 or args.iterations < 1:
        parser.error(f"--episodes {args.episodes} and --iterations {args.iterations}: each must be >= 1")
    command = "python scripts/oracle_budget.py " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    started = time.perf_counter()
    seeds = episode_seeds(args.episodes)
    marks = [m for m in MARKS if m <= args.iterations]
    record: dict[str, dict] = {}
    rows = []
    # top: every start over the whole range; bottom: the starts from the expert near 100, which the
    # start from no force would squash
    fig, axes = plt.subplots(2, len(args.scenes), figsize=(6.2 * len(args.scenes), 8.0), squeeze=False)
    for scene, ax, zoom in zip(args.scenes, axes[0], axes[1]):
        anchors = load_anchors(scene, seeds, echo=print)
        shipped = oracle_of(scene)["settings"]
        world = World(scene_config(scene))
        curves = {}
        for label, colour in zip(args.starts, ("C0", "C1", "C2")):
            warm, sampler = STARTS[label]
            oracle = TrajectoryOracle(scene, **{**shipped, "iterations": args.iterations, "seed": sampler})
            oracle.plan(make_baseline(warm, world), args.episodes, seeds)
            curve = scores(oracle.history_by_episode, anchors.zero, anchors.oracle)      # (iterations + 1, episodes)
            curves[label] = {"score": curve, "seconds": oracle.elapsed}
            for panel in (ax, zoom) if warm == "expert" else (ax,):
                panel.plot(np.arange(len(curve)), curve, color=colour, lw=0.4, alpha=0.35)
                panel.plot(np.arange(len(curve)), curve.mean(axis=1), color=colour, lw=2.0,
                           label=f"from {label} (mean)")
            for m in marks:
                at = curve[m]
                rows.append((scene, label, m, at.mean(), at.min(), at.max(), int(np.sum(at > 100.0 + 1e-6)),
                             oracle.elapsed[m] / args.episodes))
            print(f"{scene}, from {label}: {curve[-1].mean():.2f} after {args.iterations} iterations "
                  f"({oracle.elapsed[-1]:.0f} s)", flush=True)
        best = np.max([c["score"][-1] for c in curves.values()], axis=0)
        rows.append((scene, f"best of the {len(curves)} starts", args.iterations, best.mean(), best.min(), best.max(),
                     int(np.sum(best > 100.0 + 1e-6)), float("nan")))
        near = [c["score"] for k, c in curves.items() if STARTS[k][0] == "expert"]
        for panel in (ax, zoom):
            panel.axhline(100.0, color="k", lw=0.8, ls="--", label="shipped anchor (16 x 30 from the expert)")
            panel.axvline(shipped["iterations"], color="0.5", lw=0.8, ls=":")
            panel.set_xlabel("CEM iterations (16 candidates each)")
            panel.set_ylabel("normalized score against the shipped anchors")
            panel.legend(fontsize=7, loc="lower right")
        ax.set_title(f"{scene}: every start", fontsize=10)
        zoom.set_title(f"{scene}: the starts from the expert, closer", fontsize=9)
        if near:
            settled = np.concatenate([c[min(10, len(c) - 1):].ravel() for c in near])
            zoom.set_ylim(float(np.percentile(settled, 2)) - 0.5, float(np.max(near)) + 0.5)
        record[scene] = {"seeds": seeds, "zero": anchors.zero.tolist(), "oracle": anchors.oracle.tolist(),
                         "starts": {k: {"score": np.round(v["score"], 6).tolist(), "seconds": v["seconds"]}
                                    for k, v in curves.items()}}
    fig.suptitle(f"the planning oracle against its budget, each episode (thin) and the mean (thick)\n{command}",
                 fontsize=8)
    fig.tight_layout()
    save_figure(fig, args.out / "budget.png", dpi=110)
    elapsed = time.perf_counter() - started
    lines = ["# The planning oracle against its search budget", "",
             f"Made by `{command}` at {code_revision()} in {elapsed / 60:.1f} min (one BLAS thread). The first "
             f"{args.episodes} test episodes of each laryngoscope scene, planned by the trajectory oracle at its "
             f"shipped settings ({', '.join(f'{k} {v}' for k, v in shipped.items() if k not in ('iterations', 'seed'))}) for "
             f"{args.iterations} iterations from each start; each episode's best plan scored against the shipped "
             "anchors (0 no force, 100 the shipped oracle: 30 iterations from the expert, sampler seed 0). "
             "Score: mean over the episodes [lowest, highest]; above 100: episodes the search beat the shipped "
             "plan on (by more than 1e-6); seconds: planning wall time per episode so far.", "",
             "| scene | start | iterations | score | above 100 | s/episode |", "|---|---|---|---|---|---|"]
    for scene, label, m, mean, lo, hi, above, seconds in rows:
        lines.append(f"| {scene} | {label} | {m} | {mean:.2f} [{lo:.2f}, {hi:.2f}] | {above} of {args.episodes} | "
                     + ("-" if np.isnan(seconds) else f"{seconds:.1f}") + " |")
    lines += ["", "![score against budget](budget.png)", ""]
    write_text(args.out / "README.md", "\n".join(lines))
    write_text(args.out / "budget.json", json.dumps({"command": command, "commit": code_revision(),
                                                     "scenes": record}, indent=1))
    print(f"wrote {args.out / 'README.md'}, budget.json and budget.png in {elapsed / 60:.1f} min")


if __name__ == "__main__":
    main()
