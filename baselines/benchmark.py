"""``softenv compare``: every baseline and agent on the benchmark's scenes, as a table with 95 %
bootstrap intervals, a CSV, an error-against-decision-time plot, learning curves and a gallery.

Quick mode (``--quick``): every baseline on SoftSphere-v0 and on SoftSphereHaptic-v0 (the
laryngoscope), and the four agents trained briefly in this run on SoftSphere-v0, one seed each
(budgets printed); under 3 minutes on two cores. Full mode: the nine scenes (seven ideal-device, one
of them on the FE tongue, two laryngoscope), every baseline that applies to the scene's device, the four agents with their YAML
budgets over 5 training seeds on SoftSphere-v0 and SoftSphereHaptic-v0 and 3 elsewhere. Offline
mode (``--offline``): behaviour cloning and TD3+BC (:mod:`baselines.offline`) trained on each Minari
dataset of SoftSphereHaptic-v0 (:mod:`baselines.minari_datasets`, made first where the local store lacks
them), 3 seeds each, beside the expert and random baselines.
"""

from __future__ import annotations

import csv
import json
import platform
import textwrap
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable

import gymnasium as gym
import numpy as np

import softenv
from softenv._artifact import atomic_write_all
from softenv.bench.timing import code_revision, machine_info
from softenv.envs.config import make_config
from softenv.envs.world import World

from softenv.parallel import Interrupted, Job, JobResult, describe, run_jobs

from .agents import ALGOS, hyperparams, load_agent, recorded_train_seconds, train_agent
from .anchors import ORACLE, anchor_job
from .curves import RISING, RULE, Curve, convergence, convergence_report, learning_curve
from .fingerprint import library_versions
from .minari_datasets import KINDS, dataset_id, load_or_make, simulator_digest
from .evaluate import CLINICAL, GRADED_SCENES, METRICS, SCENES, Episodes, device_kind, evaluate, normalized_scores, scene_kwargs
from .policies import BASELINES, applies, make_baseline
from .run_store import RunStore


@dataclass
class Plan:
    scenes: list[str]
    baselines: list[str]
    agents: list[str]
    seeds: dict[str, int]                              # scene -> training seeds per agent
    timesteps: dict[str, int | None] = field(default_factory=dict)   # agent -> budget (None: YAML)
    episodes: int = 100
    oracle: dict[str, Any] = field(default_factory=dict)   # TrajectoryOracle settings (laryngoscope scenes)
    dataset_episodes: int = 100                        # episodes of each offline agent's dataset
    train_on: list[str] = field(default_factory=list)  # scenes the agents train on, each evaluated on every scene
                                                       # (empty: each agent trains and is evaluated on its own)


TORCH_PPO = "ppo-torch"          # baselines/ppo_torch.py: an agent on request, not in the default plans
SHAC = "shac"                    # baselines/shac.py: the first-order agent (differentiable torch twin): full plan
GRADIENT_PLANNER = "gradient"    # baselines/gradient_planner.py: a planner as costly as the oracle: full plan
POLICIES = (*BASELINES, GRADIENT_PLANNER)
OFFLINE_METHODS = ("bc", "td3bc")                      # baselines/offline.py's methods (torchrl: the offline extra)
# gradient steps: what two cores afford for 36 learners in under an hour; TD3+BC's paper trains 1M, so its rows
# here are short-budget ones (docs/datasets.md says so beside them)
OFFLINE_STEPS = {"bc": 5_000, "td3bc": 10_000}
OFFLINE_AGENTS = tuple(f"{method}-{kind}" for method in OFFLINE_METHODS for kind in KINDS)   # bc-expert: BC on expert-v0
AGENTS = (*ALGOS, TORCH_PPO, SHAC, *OFFLINE_AGENTS)


def offline_parts(agent: str) -> tuple[str, str]:
    """An offline agent's method and dataset kind (``bc-expert``: ``bc``, ``expert``)."""
    method, _, kind = agent.partition("-")
    return method, kind
QUICK_SCENES = ("SoftSphere-v0", "SoftSphereHaptic-v0")

def training_seeds(scene: str) -> int:
    """Training seeds a full run gives an agent on ``scene``: 10 on the laryngoscope, where the headline claims
    are made and seeds are known to settle apart, 5 elsewhere (enough for a seed-level interval)."""
    return 10 if device_kind(scene) == "laryngoscope" else 5


def quick_plan() -> Plan:
    """Every baseline on one ideal and one laryngoscope scene; agents (briefly) on the ideal one only."""
    return Plan(list(QUICK_SCENES), list(BASELINES), list(ALGOS), {"SoftSphere-v0": 1, "SoftSphereHaptic-v0": 0},
                {"ppo": 50_000, "sac": 10_000, "td3": 10_000, "sac-her": 10_000})


MAIN_SCENES = [s for s in SCENES if s not in GRADED_SCENES.values()]     # the graded airways run on their own
TRAIN_GRADES = (1, 2)          # the easier airways agents train on in the graded profile


def full_plan() -> Plan:
    """Every main scene: every baseline and the gradient planner, the four SB3 agents and SHAC (the gradient
    methods against the sampled ones on one table), :func:`training_seeds` each."""
    return Plan(list(MAIN_SCENES), [*BASELINES, GRADIENT_PLANNER], [*ALGOS, SHAC],
                {s: training_seeds(s) for s in MAIN_SCENES})


def haptic_plan() -> Plan:
    """The laryngoscope scenes alone: every baseline for the device, the four agents at their YAML budgets,
    :func:`training_seeds` each."""
    scenes = [s for s in MAIN_SCENES if device_kind(s) == "laryngoscope"]
    return Plan(scenes, list(BASELINES), list(ALGOS), {s: training_seeds(s) for s in scenes})


def graded_plan() -> Plan:
    """Generalisation to harder airways: every grade of SoftSphereAirway-v0 with the device's baselines
    and its own oracle anchors; the four agents trained on the easier grades (:data:`TRAIN_GRADES`) at their
    YAML budgets, 3 seeds, each evaluated on every grade."""
    scenes = list(GRADED_SCENES.values())
    return Plan(scenes, list(BASELINES), list(ALGOS), {s: 3 for s in scenes},
                train_on=[GRADED_SCENES[g] for g in TRAIN_GRADES])


def trained_policy(algo: str, train_scene: str) -> str:
    """A transferred agent's name in the tables: ``ppo (trained on grade1)``."""
    return f"{algo} (trained on {train_scene.rpartition('/')[2]})"


def offline_plan() -> Plan:
    """Offline learners on each dataset of SoftSphereHaptic-v0, 3 training seeds, beside the expert and random."""
    return Plan(["SoftSphereHaptic-v0"], ["expert", "random"], list(OFFLINE_AGENTS), {"SoftSphereHaptic-v0": 3})


def scene_baselines(plan: Plan, scene: str) -> list[str]:
    """The plan's baselines that exist for the scene's device (``oracle`` ideal, ``expert`` laryngoscope)."""
    kind = device_kind(scene)
    return [name for name in plan.baselines if applies(name, kind)]


def check_names(plan: Plan) -> None:
    for name in plan.scenes:
        if name not in SCENES:
            raise ValueError(f"unknown scene {name!r}; valid scenes: {list(SCENES)}")
    for name in plan.baselines:
        if name not in POLICIES:
            raise ValueError(f"unknown policy {name!r}; valid baselines: {list(POLICIES)}")
    for name in plan.agents:
        if name not in AGENTS:
            raise ValueError(f"unknown agent {name!r}; valid agents: {list(AGENTS)}")
    for name in plan.train_on:
        if name not in plan.scenes:
            raise ValueError(f"agents train on {name!r}, which is not among the plan's scenes {plan.scenes}")
    if plan.train_on and any(a not in ALGOS for a in plan.agents):
        raise ValueError(f"agents evaluated on other scenes than their own must be SB3 agents {list(ALGOS)}, "
                         f"got {plan.agents}")


def jobs(plan: Plan, runs_dir: Path) -> list[Job]:
    """The plan's independent jobs: one per (scene, baseline) and per (scene, agent, training seed),
    the long ones first (agents, then model inversions), so parallel workers finish together."""
    out: list[Job] = []
    for scene in plan.scenes:
        out.append(Job(f"{scene} anchors", anchor_job, (scene, plan.episodes, plan.oracle)))
        for name in scene_baselines(plan, scene):
            out.append(Job(f"{scene} {name}", baseline_job, (name, scene, plan.episodes)))
        for algo in plan.agents if not plan.train_on else ():
            fn = torch_agent_job if algo == TORCH_PPO else shac_agent_job if algo == SHAC else \
                offline_agent_job if algo in OFFLINE_AGENTS else agent_job
            extra = (plan.dataset_episodes,) if algo in OFFLINE_AGENTS else ()
            for seed in range(plan.seeds[scene]):
                run_dir = runs_dir / scene.replace("/", "_") / f"{algo}-{seed}"
                out.append(Job(f"{scene} {algo} seed {seed}", fn,
                               (algo, scene, seed, str(run_dir), plan.timesteps.get(algo), plan.episodes, *extra)))
    for scene in plan.train_on:                       # each trained once, then evaluated on every scene
        for algo in plan.agents:
            for seed in range(plan.seeds[scene]):
                run_dir = runs_dir / scene.replace("/", "_") / f"{algo}-{seed}"
                out.append(Job(transfer_key(scene, algo, seed), transfer_job,
                               (algo, scene, seed, str(run_dir), plan.timesteps.get(algo), plan.episodes,
                                tuple(plan.scenes))))
    expected = lambda job: 0 if job.fn in (agent_job, torch_agent_job, shac_agent_job, offline_agent_job, transfer_job) else 1 if job.fn is anchor_job or job.args[0].startswith("invert-") \
        or job.args[0] == GRADIENT_PLANNER \
        else 2  # noqa: E731
    return sorted(out, key=expected)


def baseline_job(name: str, scene: str, episodes: int, vectorization_mode: str = "vector_entry_point",
                 **make: Any) -> Episodes:
    """Evaluate one baseline on one scene's test targets (``evaluate``'s ``vectorization_mode`` and
    scene ``make`` overrides passed on). The gradient planner first plans those episodes from the
    benchmark's warm start, its step size tuned on training targets (:func:`~.gradient_planner.tune_lr`)."""
    _, kwargs = scene_kwargs(scene)
    kwargs.pop("obs_mode")
    world = World(make_config(**kwargs))
    if name != GRADIENT_PLANNER:
        return evaluate(make_baseline(name, world), scene, episodes, vectorization_mode=vectorization_mode, **make)
    from .gradient_planner import GradientPlanner, planner_warm_start, tune_lr   # torch: only where this planner runs
    warm = planner_warm_start(world)
    planner = GradientPlanner(scene, lr=tune_lr(scene, warm)[0])
    planner.plan(warm, episodes, **make)
    return evaluate(planner, scene, episodes, vectorization_mode=vectorization_mode, **make)


# the episodes, the learning curve, and the training's wall time in seconds as its run recorded it
AgentResult = tuple[Episodes, Curve | None, float | None]


def agent_job(algo: str, scene: str, seed: int, run_dir: str, budget: int | None, episodes: int) -> AgentResult:
    """Train one agent (or load it, when ``run_dir`` holds its finished run) and evaluate it; also returns
    its learning curve (test-target return against env steps) and the seconds its training took (None for
    a run that did not record them), so the driver needs no access to the worker's files."""
    evaluated, curve, seconds = transfer_job(algo, scene, seed, run_dir, budget, episodes, (scene,))
    return evaluated[0], curve, seconds


def transfer_job(algo: str, scene: str, seed: int, run_dir: str, budget: int | None, episodes: int,
                 eval_scenes: tuple[str, ...]) -> tuple[list[Episodes], Curve | None, float | None]:
    """Train one agent on ``scene`` (or load its finished run), then evaluate it on each of ``eval_scenes``
    (scenes of one observation and action space: the airway grades); its curve and time as :func:`agent_job`'s."""
    _torch_single_thread()
    path = train_agent(algo, scene, seed, Path(run_dir), budget, progress=False)
    agent = load_agent(path, scene)
    evaluated = [evaluate(agent, other, episodes) for other in eval_scenes]
    return evaluated, learning_curve(Path(run_dir)), recorded_train_seconds(Path(run_dir))


def transfer_key(scene: str, algo: str, seed: int) -> str:
    return f"{scene} {algo} seed {seed} (evaluated on every scene)"


def torch_agent_job(algo: str, scene: str, seed: int, run_dir: str, budget: int | None,
                    episodes: int) -> AgentResult:
    """Train (or load) one ``ppo-torch`` agent (``baselines/ppo_torch.py``) on the GPU when there is one,
    else on CPU tensors, and evaluate it."""
    from . import ppo_torch                                 # torch: the rl extra

    _torch_single_thread()
    path = Path(run_dir) / "ppo-torch.pt"
    args = ppo_torch.Args(scene=scene, seed=seed, device=torch_device())
    if budget is not None:
        args.total_timesteps = budget
    try:
        agent = ppo_torch.load(path, scene, args)
    except Exception:  # noqa: BLE001 - none yet, of other settings, or damaged (torch's errors vary): train it
        agent, _ = ppo_torch.train(args, log=lambda line: None)
        path.parent.mkdir(parents=True, exist_ok=True)
        ppo_torch.save(agent, args, path)
    return evaluate(ppo_torch.TorchPolicy(agent), scene, episodes), None, None


def shac_agent_job(algo: str, scene: str, seed: int, run_dir: str, budget: int | None, episodes: int) -> AgentResult:
    """Train (or load) one SHAC agent (``baselines/shac.py``) through the differentiable torch twin on CPU
    tensors, and evaluate it; its curve and time as :func:`agent_job`'s."""
    from . import shac                                      # torch: the rl extra

    _torch_single_thread()
    args = shac.ShacArgs(scene=scene, seed=seed)
    if budget is not None:
        args.total_timesteps = budget
    path = Path(run_dir) / "shac.pt"
    try:
        agent = shac.load(path, args)
    except (FileNotFoundError, ValueError):                 # none yet, or of other settings: train it
        agent, figures = shac.train(args, Path(run_dir), log=lambda line: None)
        shac.save(agent, args, path, figures["wall_s"])
    return evaluate(shac.as_policy(agent), scene, episodes), learning_curve(Path(run_dir)), shac.train_seconds(path)


def offline_agent_job(algo: str, scene: str, seed: int, run_dir: str, budget: int | None, episodes: int,
                      dataset_episodes: int) -> AgentResult:
    """Train (or load) one offline learner (``bc-expert``: BC on the expert dataset) and evaluate it."""
    from . import offline                                   # torch and torchrl: the offline extra

    _torch_single_thread()
    method, kind = offline_parts(algo)
    args = offline.OfflineArgs(method=method, steps=budget or OFFLINE_STEPS[method])
    meta = {"scene": scene, "dataset": dataset_id(scene, kind), "dataset_episodes": dataset_episodes, "seed": seed,
            "dynamics": simulator_digest(scene), "libraries": library_versions(("torch", "torchrl", "gymnasium", "numpy"))}
    path = Path(run_dir) / "actor.pt"
    try:
        actor, _ = offline.load(path, meta | {"args": asdict(args)})
    except ValueError:                                      # none yet, of other settings, or damaged: train it
        # ensure_datasets made it before the jobs; a worker whose store lacks it (another machine) makes it
        # with the agent runs of run_dir's runs folder
        dataset = load_or_make(scene, kind, dataset_episodes, Path(run_dir).parent.parent)
        actor = offline.train(dataset, args, seed, log=lambda line: None)
        offline.save(actor, args, meta, path)
    return evaluate(offline.OfflinePolicy(actor, algo), scene, episodes), None, None


def ensure_datasets(plan: Plan, runs_dir: Path, echo: Callable[[str], None]) -> None:
    """Make, before any job runs, each dataset the plan's offline agents train on that Minari's local
    store lacks (two workers never make one together)."""
    for scene in plan.scenes:
        for kind in dict.fromkeys(offline_parts(a)[1] for a in plan.agents if a in OFFLINE_AGENTS):
            load_or_make(scene, kind, plan.dataset_episodes, runs_dir, echo)


def torch_device() -> str:
    import torch                                            # torch: the rl extra

    return "cuda" if torch.cuda.is_available() else "cpu"


def run(plan: Plan, out_dir: Path, runs_dir: Path, command: str, echo: Callable[[str], None] = print,
        write: bool = True, stem: str = "benchmark", executor: str = "local", n_jobs: int = 1,
        retries: int = 1) -> list[dict[str, Any]]:
    """Evaluate the plan over ``executor`` (see :mod:`softenv.parallel`); print the table; write the
    reports when ``write``. Results do not depend on the executor or the number of workers, nor on
    whether the run was stopped and resumed: each finished job is kept in ``runs_dir/jobs``
    (:mod:`baselines.run_store`) and read back by the next run of the same plan."""
    check_names(plan)
    _torch_single_thread()
    if TORCH_PPO in plan.agents and torch_device() == "cpu":
        echo(f"{TORCH_PPO}: no GPU in this process; it trains on CPU tensors (the table says so)")
    started = time.perf_counter()
    ensure_datasets(plan, runs_dir, echo)
    grid = jobs(plan, runs_dir)
    store = RunStore(runs_dir)
    results: dict[str, JobResult] = {}
    for job in grid:
        stored, why = store.load(job)
        if stored is not None:
            results[job.key] = stored
        elif why != "absent":
            echo(f"{job.key}: its entry in {store.dir} is not used ({why}); the job runs again")
    if results:
        echo(f"resuming: {len(results)} of {len(grid)} jobs were finished by an earlier run ({store.dir})")
    todo = [job for job in grid if job.key not in results]
    by_key = {job.key: job for job in todo}
    kept = list(results)

    def keep(result: JobResult) -> None:
        store.save(by_key[result.key], result)
        if result.ok:
            kept.append(result.key)

    try:
        for r in run_jobs(todo, executor, n_jobs, retries, echo, on_result=keep):
            results[r.key] = r
    except Interrupted as exc:
        exc.kept = (f"{len(kept)} of {len(grid)} jobs are finished and kept in {store.dir} (trained agents beside "
                    "it); run the same command to resume")
        raise
    reused = len(grid) - len(todo)
    summaries: list[dict[str, Any]] = []
    timings: dict[str, float] = {}
    curves: dict[tuple[str, str], list[Curve]] = {}
    trainings: dict[tuple[str, str], list[float | None]] = {}
    failed = [r for r in results.values() if not r.ok]
    for scene in plan.scenes:
        anchors = results[f"{scene} anchors"]
        timings[anchors.key] = anchors.wall_s
        if not anchors.ok:
            continue
        zero, oracle, planned = anchors.value
        anchored = lambda e: _anchored(e, zero, oracle)  # noqa: E731
        if planned is not None:
            summaries.append(_summary(anchored(planned), kind="oracle (CEM through the device)", seeds=1))
        for name in scene_baselines(plan, scene):
            r = results[f"{scene} {name}"]
            timings[r.key] = r.wall_s
            if r.ok:
                summaries.append(_summary(anchored(r.value), kind="baseline", seeds=1))
        # each agent's runs by training seed on this scene: its own, or each training scene's evaluated here
        trained = [(algo, scene, algo, [results[f"{scene} {algo} seed {seed}"] for seed in range(plan.seeds[scene])],
                    lambda value: value[0]) for algo in plan.agents if not plan.train_on]
        at = plan.scenes.index(scene)
        trained += [(algo, train, trained_policy(algo, train),
                     [results[transfer_key(train, algo, seed)] for seed in range(plan.seeds[train])],
                     lambda value: value[0][at]) for train in plan.train_on for algo in plan.agents]
        for algo, train, policy, runs, episodes_of in trained:
            timings[f"{scene} {policy}"] = sum(r.wall_s for r in runs)
            done = [r.value for r in runs if r.ok]
            if not done:
                continue
            curves[(train, algo)] = [value[1] for value in done if value[1] is not None]
            trainings[(train, algo)] = [value[2] for value in done]
            pooled = [episodes_of(v) for v in done]
            values = {m: np.concatenate([e.values[m] for e in pooled]) for m in pooled[0].values}
            merged = Episodes(policy, scene, values, float(np.median([e.decision_us for e in pooled])), runs=len(pooled))
            merged.values["normalized_score"] = np.concatenate(
                [anchored(e).values["normalized_score"] for e in pooled])
            seed_scores = [anchored(episodes_of(r.value)).summary()["normalized_score"] if r.ok else None for r in runs]
            summaries.append(_summary(merged, kind=_agent_kind(plan, algo, train), seeds=len(done),
                                      seed_scores=seed_scores))
    elapsed = time.perf_counter() - started
    how = describe(executor, n_jobs)
    echo("")
    echo(format_compact(summaries))
    echo(f"\n{len(summaries)} policy x scene cells ({len(grid)} jobs, {how}) in {elapsed:.0f} s")
    if write:
        write_reports(summaries, plan, out_dir, command, elapsed, timings, curves, trainings, how, failed, stem, reused)
        echo(f"wrote {out_dir / stem}.md, .csv and .json (every column, the agents' budgets, the clinical metrics), "
             f"{out_dir / _error_plot_name(stem)}, {out_dir / stem}_learning_curves.png and _gallery.png")
    if failed:
        raise ValueError(f"{len(failed)} of {len(grid)} jobs failed (reported in the tables as missing cells): "
                         + "; ".join(f"{r.key}: {r.error}" for r in failed))
    return summaries


def agent_budget(plan: Plan, algo: str, scene: str) -> int:
    """The env steps an agent trains for on a scene: the plan's, else its YAML's (``ppo-torch``: its Args'); an
    offline learner's gradient steps."""
    given = plan.timesteps.get(algo)
    if given:
        return given
    if algo in OFFLINE_AGENTS:
        return OFFLINE_STEPS[offline_parts(algo)[0]]
    if algo in (SHAC, TORCH_PPO):
        return _torch_agent_budget(algo)
    return int(hyperparams(algo, scene_kwargs(scene)[0])["n_timesteps"])


def _agent_kind(plan: Plan, algo: str, scene: str) -> str:
    steps = agent_budget(plan, algo, scene)
    if algo in OFFLINE_AGENTS:
        return f"offline ({steps:,} gradient steps on {offline_parts(algo)[1]}-v0, {plan.dataset_episodes} episodes)"
    how = f", torch on {torch_device()}" if algo == TORCH_PPO else ", first-order" if algo == SHAC else ""
    return f"agent ({steps:,} steps{how})"


def _torch_agent_budget(algo: str) -> int:
    """A torch agent's own default budget (its arguments' ``total_timesteps``)."""
    from .ppo_torch import Args                             # torch: the rl extra
    from .shac import ShacArgs                              # torch: the rl extra

    return (ShacArgs if algo == SHAC else Args).total_timesteps


def _listed(value: Any) -> str:
    """A value, or values by name, as a report's prose writes them: ``SoftSphere-v0 1, SoftSphereHaptic-v0 0``
    (integers with thousands separators)."""
    if isinstance(value, dict):
        return ", ".join(f"{name} {_listed(v)}" for name, v in value.items())
    return f"{value:,}" if isinstance(value, int) and not isinstance(value, bool) else str(value)


def _oracle_text(plan: Plan) -> str:
    """The device oracle's search settings as the plan runs it (the shipped oracle's, then the plan's)."""
    shipped = ORACLE["laryngoscope"]["settings"]
    settings = {**shipped, **plan.oracle}                  # as anchor_job runs it
    return _listed(settings) + ("; the anchors that ship with the package, `softenv/baselines/shipped_anchors/`"
                                if settings == shipped else "")


def _anchored(episodes: Episodes, zero: np.ndarray, oracle: np.ndarray) -> Episodes:
    """``episodes`` with the benchmark's normalized score (:func:`normalized_scores`) in place of the env's."""
    values = {**episodes.values, "normalized_score": normalized_scores(episodes.values["error_sum_mm"], zero, oracle)}
    return Episodes(episodes.policy, episodes.scene, values, episodes.decision_us)


def _torch_single_thread() -> None:
    import torch                                            # torch: the rl extra

    torch.set_num_threads(1)


ABOVE = 100.0 + 1e-6       # an episode "above the planning oracle": by more than its anchors' rounding


def _summary(episodes: Episodes, **extra: Any) -> dict[str, Any]:
    """A cell: the episodes' summary, their normalized scores by run (per-episode, so anyone can recount),
    the share of episodes above the planning oracle's 100, and ``extra``."""
    scores = episodes.values["normalized_score"].reshape(episodes.runs, -1)
    return {**episodes.summary(), "above_100": float(np.mean(scores > ABOVE)),
            "episode_scores": np.round(scores, 4).tolist(), **extra}


def _fmt(m: dict[str, float], digits: int = 2) -> str:
    if not np.isfinite(m["mean"]):
        return "-"
    return f"{m['mean']:.{digits}f} [{m['ci_low']:.{digits}f}, {m['ci_high']:.{digits}f}]"


HEADER = ["scene", "policy", "kind", "normalized score", "IQM score", "episodes above 100 (%)", "final error (mm)",
          "success rate", "steps to success", "peak force (N)", "decision (us)"]


def format_table(summaries: list[dict[str, Any]]) -> str:
    lines = ["| " + " | ".join(HEADER) + " |", "|" + "---|" * len(HEADER)]
    for s in summaries:
        cells = [s["scene"], s["policy"], s["kind"], _fmt(s["normalized_score"], 1), f"{s['normalized_score']['iqm']:.1f}",
                 f"{100 * s['above_100']:.0f}", _fmt(s["final_error_mm"], 3), _fmt(s["success"], 2), _fmt(s["steps_to_success"], 1),
                 _fmt(s["peak_force_N"], 1), f"{s['decision_us']:.0f}"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


COMPACT = [("scene", 36), ("policy", 12), ("score [95 % CI]", 20), ("IQM", 5), ("err mm", 6), ("success", 7),
           ("peak N", 6), ("us/step", 7)]


def format_compact(summaries: list[dict[str, Any]]) -> str:
    """The table for a terminal: one line a cell, at most 120 columns (the full tables go to the files)."""
    def row(cells: list[str]) -> str:
        return "  ".join(c.ljust(w) if i < 2 else c.rjust(w) for i, (c, (_, w)) in enumerate(zip(cells, COMPACT)))

    lines = [row([name for name, _ in COMPACT])]
    for s in summaries:
        score = s["normalized_score"]
        lines.append(row([s["scene"], s["policy"], _fmt(score, 1), f"{score['iqm']:.1f}",
                          f"{s['final_error_mm']['mean']:.3f}", f"{s['success']['mean']:.2f}",
                          f"{s['peak_force_N']['mean']:.1f}", f"{s['decision_us']:.0f}"]))
    return "\n".join(lines)


CLINICAL_HEADER = ["scene", "policy", "peak tongue force (N)", "tongue force-time (N s)", "peak incisor force (N)",
                   "peak lower-incisor force (N)", "incisor contact (s)", "lever share", "hand path (m)", "SPARC", "LDLJ", "glottic view (%)"]


def format_clinical(summaries: list[dict[str, Any]]) -> str:
    """The clinical metrics (means [95 % interval]) of the cells that have them: the laryngoscope scenes."""
    keys = ("peak_tongue_force_N", "tongue_force_time_Ns", "peak_incisor_force_N", "peak_jaw_force_N", "incisor_contact_s",
            "lever_share", "hand_path_m", "sparc", "ldlj", "glottic_view_pct")
    digits = (1, 1, 2, 2, 2, 2, 3, 2, 1, 1)
    lines = ["| " + " | ".join(CLINICAL_HEADER) + " |", "|" + "---|" * len(CLINICAL_HEADER)]
    for s in summaries:
        if CLINICAL[0] in s:
            lines.append("| " + " | ".join([s["scene"], s["policy"], *(_fmt(s[k], d) for k, d in zip(keys, digits))]) + " |")
    return "\n".join(lines)


def format_seeds(summaries: list[dict[str, Any]]) -> str:
    """Each agent's normalized score by training seed, mean [95 % interval] over its test episodes (a seed
    that learned apart from the others shows)."""
    agents = [s for s in summaries if "seed_scores" in s]
    width = max((len(s["seed_scores"]) for s in agents), default=0)
    lines = ["| scene | policy | " + " | ".join(f"seed {i}" for i in range(width)) + " |", "|" + "---|" * (width + 2)]
    for s in agents:
        cells = ["failed" if v is None else _fmt(v, 1) for v in s["seed_scores"]] + ["-"] * (width - len(s["seed_scores"]))
        lines.append("| " + " | ".join([s["scene"], s["policy"], *cells]) + " |")
    return "\n".join(lines)


def provenance(command: str) -> dict[str, Any]:
    import stable_baselines3                  # the rl extra: only when a report is written
    import torch                                            # torch: the rl extra

    machine = machine_info()  # the BLAS kernels are named because they change the bits of every product
    return {"command": command, "code": code_revision(), "softenv": softenv.__version__, "numpy": np.__version__,
            "gymnasium": gym.__version__, "stable_baselines3": stable_baselines3.__version__,
            "torch": torch.__version__, "python": platform.python_version(),
            "machine": f"{machine['cpu']} ({platform.machine()}, {machine['logical_cores']} cores, OpenBLAS "
                       f"{machine['openblas_kernels']} kernels)",
            "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}


def write_reports(summaries: list[dict[str, Any]], plan: Plan, out_dir: Path, command: str, elapsed: float,
                  timings: dict[str, float], curves: dict[tuple[str, str], list[Curve]],
                  trainings: dict[tuple[str, str], list[float | None]], how: str, failed: list[Any], stem: str = "benchmark",
                  reused: int = 0) -> None:
    prov = {**provenance(command), "executor": how, "jobs_from_earlier_runs": reused}
    curve_table, curve_rows = convergence_report(curves, trainings)

    def write_csv(fh: Any) -> None:
        fh.write(f"# made by: {command} at {prov['code']} ({prov['date']}; softenv {prov['softenv']}, "
                 f"sb3 {prov['stable_baselines3']})\n")
        writer = csv.writer(fh)
        quantities = ("mean", "ci_low", "ci_high", "iqm")
        writer.writerow(["scene", "policy", "kind", "seeds", "episodes", "decision_us"] +
                        [f"{m}_{q}" for m in (*METRICS, *CLINICAL) for q in quantities])
        for s in summaries:       # clinical columns stay empty on the ideal-device scenes
            writer.writerow([s["scene"], s["policy"], s["kind"], s["seeds"], s["episodes"], f"{s['decision_us']:.1f}"] +
                            [f"{s[m][q]:.6g}" if m in s else "" for m in (*METRICS, *CLINICAL) for q in quantities])

    points = {f"{scene} {algo}": [{"env_steps": steps.tolist(), "test_return": np.round(returns, 4).tolist()}
                                  for steps, returns in runs] for (scene, algo), runs in curves.items()}
    numbers = json.dumps({"provenance": prov, "summaries": summaries, "timings_s": timings, "learning_curves": points,
                          "convergence": curve_rows, "failed_jobs": {r.key: r.error for r in failed}}, indent=1, default=float)
    budgets = {a: plan.timesteps.get(a) or (agent_budget(plan, a, plan.scenes[0]) if a == TORCH_PPO else
                                            {s: agent_budget(plan, a, s) for s in plan.scenes})
               for a in plan.agents}
    md = ["# Benchmark: baselines and agents on SoftSphere\n",
          f"Made by `{command}` at {prov['code']} in {elapsed / 60:.1f} min over {how}"
          f"{f' ({reused} of its jobs read from an earlier run of the same plan)' if reused else ''} "
          f"({prov['date']}; {prov['machine']}, single-threaded torch "
          f"and BLAS; softenv {prov['softenv']}, numpy {prov['numpy']}, gymnasium {prov['gymnasium']}, "
          f"stable-baselines3 {prov['stable_baselines3']}, torch {prov['torch']}).\n",
          f"Protocol: test targets only; {plan.episodes} episodes per policy and scene (per training seed for "
          f"agents); training seeds per agent: {_listed(plan.seeds)}; agent budgets (env steps): "
          f"{'; '.join(f'{a} {_listed(b)}' for a, b in budgets.items()) or 'none'}"
          + (f"; agents trained on {', '.join(plan.train_on)} (their budgets those scenes'), each evaluated on every "
             "scene" if plan.train_on else "") + ". Cells: "
          "mean [95 % interval: a bootstrap over the test episodes; for agents over their training seeds, then the "
          "episodes of each drawn seed, so seeds that learned apart widen it]; IQM = interquartile mean; episodes above 100: the share of "
          "episodes scoring above the planning oracle (by more than 1e-6). Normalized score: 100 (E_zero - E) / (E_zero - "
          "E_oracle) per episode, E = the episode's summed RMS shape error on its target; 0 = no force, 100 = the planning "
          "oracle: on the ideal device the true response and creep planned ahead (`baselines.policies.PlanningOracle`), "
          "on the laryngoscope every episode planned through the device, contact and tissue by the cross-entropy "
          f"method from the scripted expert's actions (`baselines.planner.TrajectoryOracle`, {_oracle_text(plan)}; "
          "its decision time is its planning time per control step). Decision time: one observation, median.\n",
          format_table(summaries), "",
          *(["Clinical metrics on the laryngoscope scenes (per episode, `softenv.devices.laryngoscope.clinical`; mean [95 % interval]):\n",
             format_clinical(summaries), ""] if any(CLINICAL[0] in s for s in summaries) else []),
          *(["Agents by training seed (normalized score, mean [95 % bootstrap interval] over each seed's test "
             "episodes; the table above pools them):\n", format_seeds(summaries), ""]
            if any("seed_scores" in s for s in summaries) else []),
          *([f"Learning curves against the convergence rule (`baselines/curves.py`), on test-target returns: {RULE}; {RISING}. "
             "Agents compared at equal environment steps, not equal wall time: each curve's last evaluation at or "
             "before the smallest budget among the agents on the scene (mean [95 % interval over seeds]); beside "
             "it, the training's wall time (with its evaluations, single-threaded) as each seed's run recorded it.\n", curve_table, ""] if curve_rows else []),
          f"Files: `{stem}.csv` (all numbers), `{stem}.json` (with per-cell wall times, every episode's score by "
          f"run and the learning curves' points), "
          f"`{_error_plot_name(stem)}`, `{stem}_learning_curves.png`, `{stem}_gallery.png`"
          + (f", `{stem}_grades.png` (score against airway grade)" if any(s in GRADED_SCENES.values() for s in plan.scenes)
             else "") + "."]
    if failed:
        md += ["", "Failed jobs (missing from the table): " + "; ".join(f"{r.key}: {r.error}" for r in failed)]
    figures = _plots(summaries, plan, out_dir, curves, command, stem)
    try:                    # the report set all or nothing: a failed write (or plot) leaves the old set whole
        atomic_write_all([(out_dir / f"{stem}.csv", write_csv, True),
                          (out_dir / f"{stem}.json", lambda fh: fh.write(numbers), True),
                          (out_dir / f"{stem}.md", lambda fh: fh.write("\n".join(md) + "\n"), True),
                          *[(path, lambda fh, fig=fig: fig.savefig(fh, format="png", dpi=120), False)
                            for path, fig in figures]])
    finally:
        import matplotlib.pyplot as plt                     # the viz extra (loaded by _plots)

        for _, fig in figures:
            plt.close(fig)


ERROR_FLOOR_MM = 1e-3         # the error axes start here (1 um); below it, a policy is drawn at it


def _plots(summaries: list[dict[str, Any]], plan: Plan, out_dir: Path,
           curves: dict[tuple[str, str], list[Curve]], command: str,
           stem: str) -> list[tuple[Path, Any]]:
    """The report's figures, drawn, with the paths they are saved to (by the caller, with the tables)."""
    import matplotlib                                       # the viz extra

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt                         # the viz extra

    graded = [(g, scene) for g, scene in GRADED_SCENES.items() if scene in plan.scenes]
    return [(out_dir / _error_plot_name(stem), _error_plot(summaries, plan.scenes, command, plt)),
            (out_dir / f"{stem}_learning_curves.png", _learning_curves(plan, curves, command, plt)),
            (out_dir / f"{stem}_gallery.png", _gallery(plan.scenes[0], command, plt)),
            *([(out_dir / f"{stem}_grades.png", _grade_plot(summaries, graded, plan, command, plt))] if graded else [])]


def _grade_plot(summaries: list[dict[str, Any]], graded: list[tuple[int, str]], plan: Plan, command: str,
                plt: Any) -> Any:
    """Each policy's normalized score (mean, 95 % interval) against the airway grade: generalisation to
    harder airways, the grades agents trained on shaded; the right panel zooms on the policies above 50."""
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8), sharex=True)
    scenes = dict(graded)
    names = list(dict.fromkeys(s["policy"] for s in summaries if s["scene"] in scenes.values()))
    grade_of = {scene: g for g, scene in GRADED_SCENES.items()}
    lowest = 100.0
    for ax, zoom in zip(axes, (False, True)):
        for i, name in enumerate(names):
            cells = {s["scene"]: s["normalized_score"] for s in summaries if s["policy"] == name}
            grades = [g for g, scene in graded if scene in cells]
            score = [cells[scenes[g]] for g in grades]
            mean = np.array([c["mean"] for c in score])
            if zoom and mean.min() < 50:
                continue
            lowest = min(lowest, min(c["ci_low"] for c in score)) if zoom else lowest
            offset = (i - (len(names) - 1) / 2) * 0.02           # side by side where they agree
            ax.errorbar(np.array(grades) + offset, mean, yerr=[mean - [c["ci_low"] for c in score],
                                                               [c["ci_high"] for c in score] - mean],
                        fmt=policy_style(name, plt)["marker"] + "-", color=policy_style(name, plt)["color"], ms=4,
                        capsize=2, lw=1, label=name)
        for scene in plan.train_on:
            ax.axvspan(grade_of[scene] - 0.3, grade_of[scene] + 0.3, color="0.92", zorder=0)
        ax.set_xticks([g for g, _ in graded])
        ax.set_xlabel("airway grade (shaded: the grades agents trained on)")
    axes[0].set_ylabel("normalized score (0 no force, 100 the oracle)")
    axes[0].set_title("every policy", fontsize=8)
    axes[1].set_ylim(max(50.0, lowest - 2.0), 101.0)
    axes[1].set_title("the policies above 50, closer", fontsize=8)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="center right", fontsize=7, frameon=False)
    _suptitle(fig, "score against airway grade (mean, 95 % interval)", command)
    fig.tight_layout(rect=(0, 0, 0.83, 1))
    return fig


def _error_plot(summaries: list[dict[str, Any]], scenes: list[str], command: str, plt: Any) -> Any:
    """Final shape error against decision time, one log-log panel per scene."""
    # one panel per scene in a grid; every policy keeps its colour and marker across panels, and the
    # names sit in one legend below the grid (point labels would overlap where policies agree)
    fig, axes = _grid(plt, len(scenes), legend_room=1.2)
    for ax, scene in zip(axes.flat, scenes):
        lowest = min((max(s["final_error_mm"]["ci_low"], ERROR_FLOOR_MM) for s in summaries if s["scene"] == scene),
                     default=ERROR_FLOOR_MM)
        for s in (s for s in summaries if s["scene"] == scene):
            e, style = s["final_error_mm"], policy_style(s["policy"], plt)
            x = max(s["decision_us"], 0.5)
            if e["mean"] < ERROR_FLOOR_MM:        # the oracle's ~1e-7 mm would squash every other policy
                ax.plot(x, ERROR_FLOOR_MM, marker="v", color=style["color"], ms=6, ls="none", label=s["policy"])
                continue
            ax.errorbar(x, e["mean"], yerr=[[e["mean"] - max(e["ci_low"], ERROR_FLOOR_MM)], [e["ci_high"] - e["mean"]]],
                        fmt=style["marker"], color=style["color"], ms=5, capsize=2, label=s["policy"])
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_ylim(bottom=0.7 * lowest)            # down to the floor only where a policy reaches it
        ax.set_xlabel("decision time per step (us)")
        ax.set_ylabel("final shape error (mm)")
        ax.set_title(scene, fontsize=8)
    handles: dict[str, Any] = {}
    for ax in axes.flat:
        for handle, label in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(label, handle)
    ncol = _legend_columns(fig, len(handles))
    fig.legend(handles.values(), handles.keys(), loc="lower center", ncol=ncol, fontsize=7, frameon=False)
    _suptitle(fig, f"final shape error against decision time (mean, 95 % interval; errors under "
                   f"{ERROR_FLOOR_MM * 1e3:g} um drawn as a triangle at {ERROR_FLOOR_MM * 1e3:g} um)", command)
    fig.tight_layout(rect=(0, _legend_room(fig, len(handles), ncol), 1, 1))
    return fig


def _grid(plt: Any, panels: int, legend_room: float = 0.0) -> tuple[Any, np.ndarray]:
    """A figure with one panel per scene, at most three a row; unused panels hidden."""
    cols = min(3, panels)
    rows = -(-panels // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.4 * cols, 3.4 * rows + legend_room), squeeze=False)
    for ax in list(axes.flat)[panels:]:
        ax.axis("off")
    return fig, axes


def _error_plot_name(stem: str) -> str:
    return "policy_error_vs_runtime.png" if stem == "benchmark" else f"{stem}_error_vs_runtime.png"


_MARKERS = "osD^v<>ph*"


def policy_style(name: str, plt: Any) -> dict[str, Any]:
    """A policy's colour and marker, the same in every figure of every report: an agent its
    :func:`agent_colours` colour (a transferred one, ``ppo (trained on ...)``, its agent's, the marker
    naming the grade it trained on), a baseline its own from tab20b in :data:`POLICIES` order."""
    algo, _, trained = name.partition(" (trained on ")
    if algo in AGENTS:
        grade = int(trained[-2]) if trained[-2:-1].isdigit() else 0
        return {"color": agent_colours([algo], plt)[algo], "marker": "PXd*h"[grade % 5]}
    i = POLICIES.index(name) if name in POLICIES else len(POLICIES)
    return {"color": plt.get_cmap("tab20b").colors[i % 20], "marker": _MARKERS[i % len(_MARKERS)]}


def agent_colours(agents: list[str], plt: Any) -> dict[str, Any]:
    """One colour per agent in every report, whichever agents a plan trains."""
    known = [*ALGOS, TORCH_PPO, SHAC]
    colours = {algo: plt.get_cmap("tab10").colors[i] for i, algo in enumerate(known)}
    colours |= {algo: plt.get_cmap("tab20").colors[i] for i, algo in enumerate(OFFLINE_AGENTS)}   # 12 more
    return {algo: colours[algo] for algo in agents}


def _learning_curves(plan: Plan, curves: dict[tuple[str, str], list[Curve]],
                     command: str, plt: Any) -> Any:
    """Test-target return against env steps, one panel per scene that trained agents; each agent one
    colour in every panel, named in one legend below the grid."""
    from matplotlib.ticker import EngFormatter, MaxNLocator  # the viz extra

    scenes = [scene for scene in plan.scenes if any(curves.get((scene, algo)) for algo in plan.agents)]
    fig, axes = _grid(plt, max(len(scenes), 1), legend_room=0.6)
    colours = agent_colours(plan.agents, plt)
    for ax, scene in zip(axes.flat, scenes):
        lows: list[float] = []                     # each curve's band after its first fifth, and before
        firsts: list[float] = []
        highs: list[float] = []
        unconverged: list[str] = []                # agents the convergence rule does not find converged
        for algo in plan.agents:
            runs = curves.get((scene, algo), [])
            if not runs:
                continue
            if convergence(runs)["converged"] is False:
                unconverged.append(algo)
            n = min(len(c[0]) for c in runs)
            steps, values = runs[0][0][:n], np.stack([c[1][:n] for c in runs])
            mean = values.mean(axis=0)
            half = 1.96 * values.std(axis=0, ddof=1) / np.sqrt(len(values)) if len(values) > 1 else np.zeros_like(mean)
            ax.plot(steps, mean, color=colours[algo], label=algo)
            ax.fill_between(steps, mean - half, mean + half, color=colours[algo], alpha=0.25)
            later = steps >= 0.2 * steps[-1]
            lows.append(float(np.min((mean - half)[later])))
            highs.append(float(np.max((mean + half)[later])))
            firsts.append(float(np.min(mean - half)))
        if firsts and min(firsts) < min(lows) - (max(highs) - min(lows)):
            # a first evaluation far below the rest would flatten every curve: the axis starts at the rest
            ax.set_ylim(min(lows) - 0.1 * (max(highs) - min(lows)), None)
            ax.text(0.98, 0.02, f"earlier points down to {min(firsts):.0f} below the axis", ha="right",
                    va="bottom", fontsize=6, transform=ax.transAxes)
        if unconverged:
            ax.text(0.02, 0.02, "not converged (rule in the report): " + ", ".join(unconverged), ha="left", va="bottom",
                    fontsize=6, transform=ax.transAxes)
        ends = [float(curves[scene, algo][0][0][-1]) for algo in plan.agents if curves.get((scene, algo))]
        if max(ends) >= 4 * min(ends):              # budgets a decade apart: each agent's curve readable
            ax.set_xscale("log")
        else:
            ax.xaxis.set_major_locator(MaxNLocator(4))
        ax.xaxis.set_major_formatter(EngFormatter(sep=""))        # 100k, not 100000: labels that fit
        ax.set_xlabel("env steps" + (" (log scale)" if ax.get_xscale() == "log" else ""))
        ax.set_ylabel("test-target episode return")
        ax.set_title(scene, fontsize=8)
    if not scenes:
        axes.flat[0].axis("off")
        axes.flat[0].text(0.5, 0.5, "no learning curves in this run (online agents draw them)", ha="center", transform=axes.flat[0].transAxes)
    seeds = {algo: [len(curves[s, algo]) for s in scenes if curves.get((s, algo))] for algo in plan.agents}
    handles = [plt.Line2D([], [], color=colours[a], label=seed_label(a, seeds[a])) for a in plan.agents if seeds[a]]
    ncol = _legend_columns(fig, len(handles))
    if handles:
        fig.legend(handles=handles, loc="lower center", ncol=ncol, fontsize=7, frameon=False)
    _suptitle(fig, "learning curves (mean, 95 % band over seeds)", command)
    fig.tight_layout(rect=(0, _legend_room(fig, len(handles), ncol), 1, 1))
    return fig


def seed_label(agent: str, counts: list[int]) -> str:
    """A legend entry: the agent and its seeds a panel (a range where scenes differ, as 3 and 5)."""
    low, high = min(counts), max(counts)
    return f"{agent} ({low if low == high else f'{low}-{high}'} seed{'s' if high != 1 else ''})"


def _legend_columns(fig: Any, entries: int) -> int:
    """Columns of a legend below the panels: as many entries a row as fit the figure's width (1.6 in each)."""
    return max(1, min(entries, int(fig.get_figwidth() / 1.6)))


def _legend_room(fig: Any, entries: int, ncol: int) -> float:
    """The figure fraction a legend of ``entries`` in ``ncol`` columns takes below the panels."""
    rows = -(-entries // ncol) if entries else 0
    return (rows * 7 * 1.8 + (8 if rows else 0)) / (fig.get_figheight() * 72)


def _suptitle(fig: Any, text: str, command: str, fontsize: float = 7) -> None:
    """``text`` and the command that made the figure as its title, wrapped to its width (a long command is
    not cut off at the edges); tight and constrained layouts make room for it."""
    width = max(20, int(fig.get_figwidth() * 72 / (0.55 * fontsize)))    # characters a line at this size
    lines = textwrap.wrap(text, width) + textwrap.wrap(command, width, break_on_hyphens=False)
    fig.suptitle("\n".join(lines), fontsize=fontsize)


GALLERY = ["zero", "invert-poly1", "invert-poly3", "invert-anfis", "direct-mlp", "oracle", "expert"]


def _gallery(scene: str, command: str, plt: Any) -> Any:
    """Final shapes against targets after 20 steps of one test episode of ``scene`` (a report's first), for
    the baselines of :data:`GALLERY` that exist for its device."""
    from softenv.render import displacement_colorbar         # matplotlib: the viz extra

    names = [name for name in GALLERY if applies(name, device_kind(scene))]
    env_id, kwargs = scene_kwargs(scene)
    kwargs.pop("obs_mode")
    world = World(make_config(**kwargs))
    frames: list[np.ndarray] = []
    errors: list[float] = []
    for name in names:
        env = gym.make(env_id, render_mode="rgb_array", **kwargs)
        policy = make_baseline(name, world)
        obs, _ = env.reset(seed=3)
        for _ in range(20):
            obs, _, _, _, info = env.step(policy.predict(obs))
        frames.append(np.asarray(env.render()))
        errors.append(info["shape_error_mm"])
        env.close()
    aspect = frames[0].shape[1] / frames[0].shape[0]            # the laryngoscope's frame is twice as wide
    columns = len(names) if aspect < 1.5 else 3
    rows = -(-len(names) // columns)
    fig, axes = plt.subplots(rows, columns, figsize=(2.4 * aspect * columns, 2.4 * rows + 0.9), layout="constrained",
                             squeeze=False)
    for ax in axes.flat[len(names):]:
        ax.axis("off")
    for ax, name, frame, error in zip(axes.flat, names, frames, errors):
        ax.imshow(frame)
        ax.set_title(f"{name}\n{error:.2f} mm", fontsize=7)
        ax.axis("off")
    displacement_colorbar(fig, axes.flat[:len(names)], world.scene.tissue.radius, orientation="horizontal",
                          shrink=0.4, aspect=40)
    _suptitle(fig, f"final shape (colour) and target (blue wireframe) after 20 steps of one test episode of {scene}, "
              "with its shape error", command, fontsize=6)
    return fig
