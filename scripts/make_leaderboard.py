"""Make the leaderboard's results: every built-in baseline and SB3 agent on the benchmark scenes, each as a
result file (``softenv.leaderboard``'s format) in ``results/leaderboard/``, through the public evaluation
API (``softenv.evaluation.evaluate_policy``) as anyone reporting a result would. Run it from a clean
commit; the docs' leaderboard page is built from these files.

Agents train into ``--runs`` (``<runs>/<scene>/<algo>-<seed>``, the folders ``softenv compare`` uses, so a
compare run's agents are loaded, not trained again, and a stopped run resumes where it stopped).
``--quick``: the agents as ``softenv compare --quick`` trains them (one seed, its short budgets, on
SoftSphere-v0 only; minutes); otherwise their YAML budgets over the full profile's seeds
(``benchmark.training_seeds``: 10 on the laryngoscope, 5 elsewhere; many hours on 2 cores). Then draws the aggregates across scenes of every
file in ``--out`` (``softenv leaderboard aggregate --plot``'s figure) into ``--figure``.

    python scripts/make_leaderboard.py [--quick] [--scenes ...] [--agents ...] [--runs runs] [--jobs 2]
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path
from typing import Any

from softenv import leaderboard
from softenv.baselines.agents import ALGOS, load_agent, train_agent
from softenv.baselines.anchors import scene_config
from softenv.baselines.benchmark import agent_budget, full_plan, quick_plan, scene_baselines
from softenv.baselines.evaluate import SCENES
from softenv.baselines.policies import BASELINES, make_baseline
from softenv.bench import rerun_single_threaded
from softenv.bench.timing import code_revision
from softenv.envs.world import World
from softenv.evaluation import Evaluation, evaluate_policy
from softenv.parallel import Job, run_jobs, usable_cores


def baseline_result(name: str, scene: str) -> Evaluation:
    return evaluate_policy(make_baseline(name, World(scene_config(scene))), scene, name=name, echo=print)


def train_job(algo: str, scene: str, seed: int, run_dir: str, budget: int | None) -> str:
    import torch                                    # the rl extra

    torch.set_num_threads(1)
    return str(train_agent(algo, scene, seed, Path(run_dir), budget, progress=False))


def agent_result(algo: str, scene: str, paths: list[str]) -> Evaluation:
    return evaluate_policy([load_agent(p, scene) for p in paths], scene, name=algo, echo=print)


def main() -> None:
    rerun_single_threaded()               # one BLAS thread, as softenv compare and the anchors
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="agents as softenv compare --quick trains them")
    parser.add_argument("--scenes", nargs="+", choices=list(SCENES), default=list(SCENES))
    parser.add_argument("--agents", nargs="*", choices=list(ALGOS), default=list(ALGOS))
    parser.add_argument("--runs", default="runs", help="where agents train (softenv compare's run folders)")
    parser.add_argument("--out", type=Path, default=Path("results/leaderboard"))
    parser.add_argument("--figure", type=Path, default=Path("results/leaderboard_aggregates.png"))
    parser.add_argument("--jobs", type=int, default=usable_cores())
    args = parser.parse_args()
    plan = quick_plan() if args.quick else full_plan()
    command = "python scripts/make_leaderboard.py " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    commit = code_revision()
    seeds = {s: plan.seeds.get(s, 0 if args.quick else 3) for s in args.scenes}
    trained = [(algo, scene, seed) for scene in args.scenes for algo in args.agents for seed in range(seeds[scene])]

    def run_dir(algo: str, scene: str, seed: int) -> str:
        return str(Path(args.runs) / scene.replace("/", "_") / f"{algo}-{seed}")

    jobs = [Job(f"train {scene} {algo} seed {seed}", train_job,
                (algo, scene, seed, run_dir(algo, scene, seed), plan.timesteps.get(algo)))
            for algo, scene, seed in trained]
    paths = {r.key: r.value for r in run_jobs(jobs, n_jobs=args.jobs) if r.ok}
    # the built-in baselines; the full plan's gradient planner (a planner as costly as the oracle) reports in
    # results/gradient-planner instead
    evaluations = [Job(f"{scene} {name}", baseline_result, (name, scene))
                   for scene in args.scenes for name in scene_baselines(plan, scene) if name in BASELINES]
    budgets: dict[str, Any] = {}
    for scene in args.scenes:
        for algo in args.agents:
            keys = [f"train {scene} {algo} seed {seed}" for seed in range(seeds[scene])]
            if seeds[scene] and all(k in paths for k in keys):
                evaluations.append(Job(f"{scene} {algo}", agent_result, (algo, scene, [paths[k] for k in keys])))
                budgets[f"{scene} {algo}"] = agent_budget(plan, algo, scene)
    failed = []
    for result in run_jobs(evaluations, n_jobs=args.jobs):
        if not result.ok:
            failed.append(f"{result.key}: {result.error}")
            continue
        evaluation: Evaluation = result.value
        agent = result.key in budgets
        record = leaderboard.result_record(evaluation, "agent" if agent else "baseline", f"{command} (at {commit})",
                                           training_seeds=list(range(len(evaluation.per_run))) if agent else None)
        if agent:
            record["notes"] = f"{budgets[result.key]:,} env steps per training seed" + \
                (" (softenv compare --quick's budget)" if args.quick else " (its YAML budget)")
        path = args.out / f"{evaluation.scene.replace('/', '_')}__{evaluation.policy}.json"
        leaderboard.save_result(record, path)
        print(f"wrote {path}")
    if failed:
        raise SystemExit("failed: " + "; ".join(failed))
    print(f"wrote {leaderboard.aggregates_figure(leaderboard.load_results(args.out), args.figure)}")


if __name__ == "__main__":
    main()
