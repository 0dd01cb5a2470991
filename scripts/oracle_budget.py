"""How close is the planning oracle to an optimum? Its score against its search budget, per episode.

    python scripts/oracle_budget.py --out results/oracle-budget [--episodes 20] [--iterations 240]

On each laryngoscope scene the first ``--episodes`` test episodes are planned by the benchmark's
trajectory oracle (``softenv.baselines.planner.TrajectoryOracle``, its shipped settings but the number of
iterations), which searches from three starts side by side: the scripted expert's actions with the
shipped sampler seed, the same with another sampler seed (a restart), and no force at all (a start that
owes nothing to the expert). Each start's best summed shape error after every iteration, and the best
over the starts (the oracle's plan), are scored against the shipped anchors (0 no force, 100 the oracle
at its shipped budget), so the table says how much a longer search would move the 100, on how many
episodes, and which start wins. At the shipped budget the best over the starts is the anchor itself
(checked to the last bits, which another BLAS kernel set rounds differently: the script stops if not).

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
STARTS = ("expert", "expert, another sampler seed", "no force")     # TrajectoryOracle's, in its order
MARKS = (0, 10, 30, 60, 120, 240, 480)     # iterations tabled (those within the run)


def scores(errors: np.ndarray, zero: np.ndarray, oracle: np.ndarray) -> np.ndarray:
    """Normalized scores of error sums ``(..., episodes)`` against per-episode anchors."""
    return 100.0 * (zero - errors) / (zero - oracle)


def main() -> None:
    rerun_single_threaded()
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--scenes", nargs="+", choices=LARYNGOSCOPE, default=LARYNGOSCOPE)
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--iterations", type=int, default=240)
    args = parser.parse_args()
    if args.episodes < 1 or args.iterations < 1:
        parser.error(f"--episodes {args.episodes} and --iterations {args.iterations}: each must be >= 1")
    command = "python scripts/oracle_budget.py " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    started = time.perf_counter()
    seeds = episode_seeds(args.episodes)
    marks = [m for m in MARKS if m < args.iterations] + [args.iterations]     # and the full budget
    record: dict[str, dict] = {}
    rows = []
    # top: every start over the whole range; bottom: the starts from the expert near 100, which the
    # start from no force would squash
    fig, axes = plt.subplots(2, len(args.scenes), figsize=(6.2 * len(args.scenes), 8.0), squeeze=False)
    for scene, ax, zoom in zip(args.scenes, axes[0], axes[1]):
        anchors = load_anchors(scene, seeds, echo=print)
        shipped = oracle_of(scene)["settings"]
        oracle = TrajectoryOracle(scene, **{**shipped, "iterations": args.iterations})
        oracle.plan(make_baseline("expert", World(scene_config(scene))), args.episodes, seeds)
        if len(STARTS) != len(oracle.history_by_start):
            raise SystemExit(f"the oracle searched from {len(oracle.history_by_start)} starts; this script names {len(STARTS)}")
        at_shipped = oracle.history_by_episode[min(shipped["iterations"], args.iterations)]
        # equal to the last bits' rounding: OpenBLAS's kernel set (AVX2 or AVX-512, by CPU) rounds products
        # differently (1e-15 apart on a Haswell-kernel host); another search differs by far more
        if args.iterations >= shipped["iterations"] and not np.allclose(at_shipped, anchors.oracle, rtol=1e-9, atol=0.0):
            raise SystemExit(f"{scene}: the search at the shipped budget is not the shipped anchors "
                             f"({at_shipped[:3]} against {anchors.oracle[:3]}): remake the anchors first")
        curves = {label: scores(history, anchors.zero, anchors.oracle)      # (iterations + 1, episodes)
                  for label, history in zip(STARTS, oracle.history_by_start)}
        best = scores(oracle.history_by_episode, anchors.zero, anchors.oracle)
        wins = {label: int(np.sum(np.argmin(oracle.history_by_start[:, -1], axis=0) == i)) for i, label in enumerate(STARTS)}
        seconds = np.array(oracle.elapsed) / args.episodes
        for label, colour in zip(STARTS, ("C0", "C1", "C2")):
            curve = curves[label]
            for panel in (zoom, ax) if label.startswith("expert") else (ax,):
                panel.plot(np.arange(len(curve)), curve, color=colour, lw=0.4, alpha=0.35)
                panel.plot(np.arange(len(curve)), curve.mean(axis=1), color=colour, lw=1.5, label=f"from {label} (mean)")
        for panel in (ax, zoom):
            panel.plot(np.arange(len(best)), best.mean(axis=1), color="k", lw=2.0, label="best of the starts (mean)")
        for label, curve in [*curves.items(), ("best of the starts", best)]:
            for m in marks:
                at = curve[m]
                rows.append((scene, label, m, at.mean(), at.min(), at.max(), int(np.sum(at > 100.0 + 1e-6)), seconds[m]))
        print(f"{scene}: best of the starts {best[-1].mean():.2f} after {args.iterations} iterations "
              f"({oracle.elapsed[-1]:.0f} s); won by {wins}", flush=True)
        for panel in (ax, zoom):
            panel.axhline(100.0, color="k", lw=0.8, ls="--", label="shipped anchor")
            panel.axvline(shipped["iterations"], color="0.5", lw=0.8, ls=":")
            panel.set_xlabel(f"CEM iterations ({shipped['candidates']} candidates a start each)")
            panel.set_ylabel("normalized score against the shipped anchors")
            panel.legend(fontsize=7, loc="lower right")
        ax.set_title(f"{scene}: every start", fontsize=10)
        zoom.set_title(f"{scene}: the starts from the expert, closer", fontsize=9)
        settled = np.concatenate([curves[k][min(10, args.iterations):].ravel() for k in STARTS[:2]])
        zoom.set_ylim(float(np.percentile(settled, 2)) - 0.5, float(best.max()) + 0.5)
        record[scene] = {"seeds": seeds, "zero": anchors.zero.tolist(), "oracle": anchors.oracle.tolist(),
                         "seconds_per_episode": seconds.tolist(), "won_by": wins,
                         "starts": {k: np.round(v, 6).tolist() for k, v in curves.items()},
                         "best": np.round(best, 6).tolist()}
    fig.suptitle(f"the planning oracle against its budget, each episode (thin) and the mean (thick)\n{command}",
                 fontsize=8)
    fig.tight_layout()
    save_figure(fig, args.out / "budget.png", dpi=110)
    elapsed = time.perf_counter() - started
    shown = ", ".join(f"{k} {v}" for k, v in shipped.items() if k not in ("iterations", "seed"))
    lines = ["# The planning oracle against its search budget", "",
             f"Made by `{command}` at {code_revision()} in {elapsed / 60:.1f} min (one BLAS thread). The first "
             f"{args.episodes} test episodes of each laryngoscope scene, planned by the trajectory oracle "
             f"(version {TrajectoryOracle.VERSION}: {shown}) for {args.iterations} iterations instead of its shipped "
             f"{shipped['iterations']}; each start's best plan, and the best over the starts (the oracle's plan), "
             "scored against the shipped anchors (0 no force, 100 the oracle at its shipped budget). Score: mean over "
             "the episodes [lowest, highest]; above 100: episodes a longer search beat the shipped plan on (by more "
             "than 1e-6); seconds: the oracle's planning wall time per episode so far (all starts together).", "",
             "| scene | start | iterations | score | above 100 | s/episode |", "|---|---|---|---|---|---|"]
    for scene, label, m, mean, lo, hi, above, secs in rows:
        lines.append(f"| {scene} | {label} | {m} | {mean:.2f} [{lo:.2f}, {hi:.2f}] | {above} of {args.episodes} | {secs:.1f} |")
    lines += ["", "Episodes each start won at the full budget: "
              + "; ".join(f"{scene}: " + ", ".join(f"{k} {v}" for k, v in r["won_by"].items()) for scene, r in record.items())
              + ".", "", "![score against budget](budget.png)", ""]
    write_text(args.out / "README.md", "\n".join(lines))
    write_text(args.out / "budget.json", json.dumps({"command": command, "commit": code_revision(),
                                                     "scenes": record}, indent=1))
    print(f"wrote {args.out / 'README.md'}, budget.json and budget.png in {elapsed / 60:.1f} min")


if __name__ == "__main__":
    main()
