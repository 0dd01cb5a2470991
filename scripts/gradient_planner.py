"""Does following the gradient plan as well as sampling? The gradient planner against the planning oracle.

    python scripts/gradient_planner.py --out results/gradient-planner [--episodes 8] [--iterations 40]

On each benchmark scene, the first ``--episodes`` test episodes are planned three ways, from the same warm start (the
scripted expert on the laryngoscope, no force on the ideal device): by the gradient planner
(softenv.baselines.gradient_planner: Adam on the action sequence through the differentiable torch twin,
4 restarts), and by the benchmark's oracle (on the laryngoscope the CEM search the shipped anchors were
made with; on the ideal device the exact per-step inversion, which needs no search). Adam's step size is
picked per scene on the *training* targets (2 episodes, a short search over ``--lrs``), never on the
episodes it is scored on. Scores are the benchmark's normalized score (0 no force, 100 the oracle), each
episode scaled by the shipped anchors; the CEM search is rerun here only to time it on the same machine
(its error sums must equal the shipped anchors').

Writes ``results.json``, ``README.md`` (the table) and ``budget.png`` (each planner's mean summed shape
error against its planning wall time) into ``--out``; one BLAS and torch thread.
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
import torch  # noqa: E402

from softenv._artifact import save_figure, write_text  # noqa: E402
from softenv.baselines.anchors import load_anchors, scene_config  # noqa: E402
from softenv.baselines.evaluate import SCENES, episode_seeds, evaluate, normalized_scores  # noqa: E402
from softenv.baselines.gradient_planner import STEP_SIZES, GradientPlanner, planner_warm_start, tune_lr  # noqa: E402
from softenv.baselines.planner import TrajectoryOracle  # noqa: E402
from softenv.baselines.policies import PlanningOracle, make_baseline  # noqa: E402
from softenv.bench import rerun_single_threaded  # noqa: E402
from softenv.bench.timing import code_revision  # noqa: E402
from softenv.envs.world import World  # noqa: E402
from softenv.stats import bootstrap_ci  # noqa: E402

def summary(values: np.ndarray) -> dict[str, float]:
    mean, lo, hi = bootstrap_ci(values)
    return {"mean": mean, "ci_low": lo, "ci_high": hi}


def main() -> None:
    rerun_single_threaded()
    torch.set_num_threads(1)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--scenes", nargs="+", choices=list(SCENES), default=list(SCENES))
    parser.add_argument("--episodes", type=int, default=8)
    parser.add_argument("--iterations", type=int, default=40)
    parser.add_argument("--restarts", type=int, default=4)
    parser.add_argument("--lrs", type=float, nargs="+", default=list(STEP_SIZES))
    parser.add_argument("--tune-iterations", type=int, default=10)
    args = parser.parse_args()
    command = "python scripts/gradient_planner.py " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    started = time.perf_counter()
    seeds = episode_seeds(args.episodes)
    results = []
    columns = min(3, len(args.scenes))
    rows = -(-len(args.scenes) // columns)
    fig, axes = plt.subplots(rows, columns, figsize=(5.0 * columns, 3.8 * rows), layout="constrained", squeeze=False)
    for ax in axes.flat[len(args.scenes):]:
        ax.set_visible(False)
    for ax, scene in zip(axes.flat, args.scenes):
        world = World(scene_config(scene))
        anchors = load_anchors(scene, seeds)
        lr, tried = tune_lr(scene, planner_warm_start(world), tuple(args.lrs), args.tune_iterations)
        warm = evaluate(planner_warm_start(world), scene, len(seeds), seeds).values["error_sum_mm"]
        planner = GradientPlanner(scene, restarts=args.restarts, iterations=args.iterations, lr=lr)
        t0 = time.perf_counter()
        planned = planner.plan(planner_warm_start(world), len(seeds), seeds)
        gradient_s = time.perf_counter() - t0
        row = {"scene": scene, "device": world.device_kind.name, "episodes": len(seeds), "lr": lr, "lr_tried": tried,
               "restarts": args.restarts, "iterations": args.iterations, "anchors": anchors.source,
               "warm_start": summary(normalized_scores(warm, anchors.zero, anchors.oracle)),
               "gradient": summary(normalized_scores(planned, anchors.zero, anchors.oracle)),
               "gradient_per_episode": normalized_scores(planned, anchors.zero, anchors.oracle).tolist(),
               "gradient_s_per_episode": gradient_s / len(seeds),
               "above_oracle": int((planned < anchors.oracle).sum())}
        ax.plot(planner.elapsed, planner.history, "o-", ms=3, label=f"gradient planner (Adam, lr {lr:g})")
        if world.device_kind.name == "laryngoscope":
            oracle = TrajectoryOracle(scene)
            t0 = time.perf_counter()
            searched = oracle.plan(make_baseline("expert", world), len(seeds), seeds)
            row["oracle_s_per_episode"] = (time.perf_counter() - t0) / len(seeds)
            row["oracle_rerun_rel_diff"] = float(np.max(np.abs(searched - anchors.oracle) / anchors.oracle))
            ax.plot(oracle.elapsed, oracle.history, "s-", ms=3, label=f"planning oracle (CEM v{TrajectoryOracle.VERSION})")
        else:
            t0 = time.perf_counter()
            exact = evaluate(PlanningOracle(world), scene, len(seeds), seeds).values["error_sum_mm"]
            row["oracle_s_per_episode"] = (time.perf_counter() - t0) / len(seeds)
            row["oracle_rerun_rel_diff"] = float(np.max(np.abs(exact - anchors.oracle) / np.maximum(anchors.oracle, 1e-12)))
        ax.axhline(float(anchors.oracle.mean()), color="black", ls="--", lw=1, label="the oracle's error (score 100)")
        ax.axhline(float(warm.mean()), color="grey", ls=":", lw=1, label="warm start")
        ax.set_xlabel("planning wall time (s, all episodes)")
        ax.set_ylabel("mean summed shape error (mm x steps)")
        ax.set_title(scene, fontsize=9)
        ax.legend(fontsize=7)
        results.append(row)
        print(f"{scene}: warm {row['warm_start']['mean']:.1f}, gradient {row['gradient']['mean']:.1f} "
              f"({row['gradient_s_per_episode']:.1f} s/episode; oracle {row['oracle_s_per_episode']:.1f} s)", flush=True)
    fig.suptitle(f"the gradient planner against the planning oracle -- {command}", fontsize=8)
    args.out.mkdir(parents=True, exist_ok=True)
    save_figure(fig, args.out / "budget.png", dpi=110)
    made = {"command": command, "commit": code_revision(), "minutes": (time.perf_counter() - started) / 60}
    write_text(args.out / "results.json", json.dumps({"made_by": made, "scenes": results}, indent=1) + "\n")
    write_text(args.out / "README.md", report(results, made))


def report(results: list[dict], made: dict) -> str:
    def cell(m: dict[str, float]) -> str:
        return f"{m['mean']:.1f} [{m['ci_low']:.1f}, {m['ci_high']:.1f}]"

    lines = ["# The gradient planner against the planning oracle", "",
             f"Made by `{made['command']}` at {made['commit']} in {made['minutes']:.1f} min (one BLAS and torch "
             "thread, a 2-core machine). Normalized scores (0 no force, 100 the planning oracle), each episode scaled by "
             "the shipped anchors; mean with a 95 % bootstrap interval over the episodes. Adam's step size was picked "
             "on 2 training-target episodes (ties, where no step size improved on the warm start there, go to the "
             "smallest). The oracle's time is its search rerun here; the last column is the largest relative "
             "difference between the rerun's error sums and the shipped anchors'.", "",
             "| scene | episodes | warm start | gradient planner | episodes above 100 | planner s/episode | "
             "oracle s/episode | lr (tried: error) | oracle rerun against anchors |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        tried = ", ".join(f"{k}: {v:.1f}" for k, v in r["lr_tried"].items())
        lines.append(f"| {r['scene']} | {r['episodes']} | {cell(r['warm_start'])} | {cell(r['gradient'])} | "
                     f"{r['above_oracle']} | {r['gradient_s_per_episode']:.2f} | {r['oracle_s_per_episode']:.3f} | "
                     f"{r['lr']:g} ({tried}) | {r['oracle_rerun_rel_diff']:.1e} |")
    lines += ["", "![budget](budget.png)", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
