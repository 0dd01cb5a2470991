"""Tune an agent's discount and learning rate with Optuna, on the training targets only.

    python scripts/tune_agents.py --algo ppo --scene SoftSphereHaptic-v0 --trials 16 [--timesteps N]
        [--seeds 0] [--episodes 50] [--confirm 3 --confirm-seeds 1 2 3 4] [--runs runs/tuning] [--out results/tuning]

Each trial trains the agent (``softenv.baselines.agents.train_agent``, its YAML settings with the trial's
``gamma`` and ``learning_rate``) on every ``--seeds`` seed for ``--timesteps`` env steps (default: the
YAML budget), and scores it by the mean summed shape error of its ``--episodes`` first training-target
episodes (the score's ``E``; lower is better): the test targets the benchmark reports are never seen.
The first trial is the YAML's own values, so the search is measured against them; then Optuna's TPE
sampler (seeded by the number of finished trials before each proposal) proposes ``gamma`` from 0.9 to 0.999 and ``learning_rate`` from 1e-5 to 1e-3 (log
scale), its first 5 trials at random. The study is an SQLite file in ``--runs``, so a
stopped search resumes: ``--trials`` is the total wanted, finished trials are kept, one cut short is
marked failed and run again as a new trial with the same proposal, so the resumed search is the unstopped
one. The study is named after the simulator it scores on (the agents' dynamics digest and training
libraries, as a trained run records them), so a search resumed after a change to what the agents learn
from starts afresh rather than ranking trials scored on two simulators.

A search on few seeds picks its best partly by luck. ``--confirm K`` trains the K best trials and the
YAML's values again on ``--confirm-seeds`` (seeds the search did not use) and decides by the seeds: the
best of them by mean is adopted only when its 95 % interval over those seeds lies wholly below the
YAML's (lower error); otherwise the YAML's values stay.

Writes ``<scene>__<algo>.md`` (every trial, and the confirmation), ``.json`` and ``.yml`` (the YAML entry
with the best trial's values, or with the confirmation's verdict, to adopt into
``softenv/baselines/hyperparams``) into ``--out``; one BLAS and torch thread.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shlex
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import optuna
import torch
import yaml

from softenv._artifact import write_text
from softenv.baselines.agents import ALGOS, hyperparams, load_agent, recorded_train_seconds, train_agent, training_fingerprint
from softenv.baselines.evaluate import SCENES, evaluate, scene_kwargs
from softenv.bench import rerun_single_threaded
from softenv.bench.timing import code_revision
from softenv.stats import bootstrap_ci

GAMMAS = (0.9, 0.95, 0.98, 0.99, 0.995, 0.999)
LEARNING_RATES = (1e-5, 1e-3)


def trained_error(args: argparse.Namespace, overrides: dict[str, float], number: int, seed: int) -> tuple[float, float | None]:
    """Train (or load the finished run of) trial ``number``'s values on ``seed``: its mean summed shape error
    over the first ``--episodes`` training-target episodes, and the training's wall time in seconds as its
    ``agent.json`` records it (None for a run trained before agents recorded it)."""
    run_dir = args.runs / args.scene.replace("/", "_") / f"{args.algo}-trial{number}-seed{seed}"
    model = train_agent(args.algo, args.scene, seed, run_dir, args.timesteps, progress=False, overrides=overrides)
    played = evaluate(load_agent(model, args.scene), args.scene, args.episodes, list(range(args.episodes)),
                      task={"split": "train"})
    return float(played.values["error_sum_mm"].mean()), recorded_train_seconds(run_dir)


def objective(trial: optuna.Trial, args: argparse.Namespace) -> float:
    overrides = {"gamma": trial.suggest_categorical("gamma", GAMMAS),
                 "learning_rate": trial.suggest_float("learning_rate", *LEARNING_RATES, log=True)}
    errors, seconds = zip(*(trained_error(args, overrides, trial.number, seed) for seed in args.seeds))
    trial.set_user_attr("error_by_seed", list(errors))
    trial.set_user_attr("train_seconds", list(seconds))
    return sum(errors) / len(errors)


def minutes(seconds: list[float | None]) -> str:
    """The trainings' total wall time in minutes, or "-" where a run did not record it."""
    known = [s for s in seconds if s is not None]
    return f"{sum(known) / 60:.1f}" if len(known) == len(seconds) else "-"


def confirm(finished: list[optuna.trial.FrozenTrial], args: argparse.Namespace) -> list[dict[str, Any]]:
    """The ``--confirm`` best trials and the YAML's, each trained on every ``--confirm-seeds`` seed: their
    errors by seed and mean with its 95 % bootstrap interval over the seeds, best mean first."""
    ranked = sorted(finished, key=lambda t: t.value)
    chosen = ranked[:args.confirm] + [t for t in ranked[args.confirm:] if t.user_attrs.get("yaml")]
    rows = []
    for t in chosen:
        errors, seconds = zip(*(trained_error(args, t.params, t.number, seed) for seed in args.confirm_seeds))
        mean, low, high = bootstrap_ci(np.array(errors))
        rows.append({"number": t.number, "yaml": bool(t.user_attrs.get("yaml")), **t.params,
                     "error_by_seed": list(errors), "train_seconds": list(seconds), "mean": mean, "ci_low": low,
                     "ci_high": high})
        print(f"confirm trial {t.number}: mean error sum {mean:.2f} [{low:.2f}, {high:.2f}] over seeds "
              f"{args.confirm_seeds}", flush=True)
    return sorted(rows, key=lambda r: r["mean"])


def verdict(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The confirmation's choice: its best row when that row's interval lies wholly below the YAML's,
    else the YAML's row."""
    best, own = rows[0], next(r for r in rows if r["yaml"])
    return best if best["ci_high"] < own["ci_low"] else own


def main() -> None:
    rerun_single_threaded()
    torch.set_num_threads(1)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--algo", choices=list(ALGOS), required=True)
    parser.add_argument("--scene", choices=list(SCENES), required=True)
    parser.add_argument("--trials", type=int, required=True, help="total finished trials wanted")
    parser.add_argument("--timesteps", type=int, default=None, help="env steps a trial trains (default: the YAML's)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--episodes", type=int, default=50, help="training-target episodes a trial is scored on")
    parser.add_argument("--confirm", type=int, default=0, help="best trials trained again on --confirm-seeds (0: none)")
    parser.add_argument("--confirm-seeds", type=int, nargs="+", default=[1, 2, 3, 4])
    parser.add_argument("--runs", type=Path, default=Path("runs/tuning"))
    parser.add_argument("--out", type=Path, default=Path("results/tuning"))
    args = parser.parse_args()
    for name in ("trials", "episodes"):
        if getattr(args, name) < 1:
            parser.error(f"--{name} {getattr(args, name)}: must be >= 1")
    if not 0 <= args.confirm <= args.trials:
        parser.error(f"--confirm {args.confirm}: must be from 0 to --trials ({args.trials})")
    if args.confirm and (len(args.confirm_seeds) < 2 or set(args.confirm_seeds) & set(args.seeds)):
        parser.error(f"--confirm-seeds {args.confirm_seeds}: give at least 2 seeds, none of --seeds {args.seeds}")
    env_id = scene_kwargs(args.scene)[0]
    yaml_params = hyperparams(args.algo, env_id)
    budget = args.timesteps or int(yaml_params["n_timesteps"])
    command = "python scripts/tune_agents.py " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    args.runs.mkdir(parents=True, exist_ok=True)
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    fingerprint = training_fingerprint(args.algo, args.scene)
    simulator = hashlib.sha256((fingerprint["dynamics"] + json.dumps(fingerprint["libraries"])).encode()).hexdigest()[:16]
    study = optuna.create_study(
        study_name=f"{args.scene} {args.algo} {budget} steps seeds {args.seeds} episodes {args.episodes} "
                   f"simulator {simulator}",
        storage=f"sqlite:///{(args.runs / 'tuning.db').resolve()}", direction="minimize", load_if_exists=True)
    for cut in study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.RUNNING,)):
        study.tell(cut.number, state=optuna.trial.TrialState.FAIL)        # a run that was stopped
    chosen = {"gamma": yaml_params["gamma"], "learning_rate": yaml_params["learning_rate"]}
    if not study.trials:
        study.enqueue_trial(chosen, user_attrs={"yaml": True})     # the values the search must beat
    started = time.perf_counter()
    while len(finished := study.get_trials(states=(optuna.trial.TrialState.COMPLETE,))) < args.trials:
        # a sampler seeded by the finished trials' count proposes what an unstopped search would have
        # proposed next: a resumed search is the same search (one seeded once would start its stream again)
        study.sampler = optuna.samplers.TPESampler(seed=len(finished), n_startup_trials=5)
        trial = study.ask()
        value = objective(trial, args)
        study.tell(trial, value)
        print(f"trial {trial.number}: gamma {trial.params['gamma']}, learning_rate {trial.params['learning_rate']:.3g}: "
              f"mean error sum {value:.2f} mm-steps", flush=True)
    best = study.best_trial
    confirmed = confirm(finished, args) if args.confirm else []
    choice = verdict(confirmed) if confirmed else {"number": best.number, **best.params}
    stem = f"{args.scene.replace('/', '_')}__{args.algo}"
    tuned = {**{k: v for k, v in yaml_params.items() if k != "env_kwargs"},
             "gamma": choice["gamma"], "learning_rate": choice["learning_rate"],
             "n_timesteps": int(yaml_params["n_timesteps"])}
    header = (f"# Tuning {args.algo} on {args.scene}\n\nMade by `{command}` at {code_revision()} "
              f"({(time.perf_counter() - started) / 60:.1f} min this call; {len(finished)} finished trials). "
              f"Each trial trains {budget:,} env steps on seeds {args.seeds} and is scored by the mean summed shape "
              f"error (mm-steps) of the first {args.episodes} training-target episodes; lower is better. "
              f"Search: Optuna {optuna.__version__} TPE (seed 0, 5 random trials first), gamma in {list(GAMMAS)}, "
              f"learning_rate log-uniform in {list(LEARNING_RATES)}. The YAML's values: gamma "
              f"{yaml_params.get('gamma')}, learning_rate {yaml_params.get('learning_rate')}.\n")
    rows = ["| trial | gamma | learning_rate | mean error sum | by seed | training minutes |", "|---|---|---|---|---|---|"]
    rows += [f"| {t.number}{' (the YAML)' if t.user_attrs.get('yaml') else ''} | "
             f"{t.params['gamma']} | {t.params['learning_rate']:.3g} | {t.value:.2f} | "
             f"{', '.join(f'{e:.2f}' for e in t.user_attrs['error_by_seed'])} | "
             f"{minutes(t.user_attrs.get('train_seconds', [None]))} |"
             for t in sorted(finished, key=lambda t: t.value)]
    best_line = (f"\nBest: trial {best.number}, gamma {best.params['gamma']}, learning_rate "
                 f"{best.params['learning_rate']:.3g} (mean error sum {best.value:.2f}); its YAML entry: `{stem}.yml`. "
                 f"Each trial is {len(args.seeds)} training seed(s): trials closer than the spread between seeds are "
                 "not told apart by this search.\n")
    confirmation = ""
    if confirmed:
        kept = choice["yaml"]
        confirmation = (
            f"\n## Confirmation on seeds {args.confirm_seeds}\n\nThe {args.confirm} best trials and the YAML's values, "
            f"each trained again on seeds the search did not use; mean summed shape error [95 % bootstrap interval "
            "over the seeds]:\n\n| trial | gamma | learning_rate | mean error sum | by seed | training minutes |\n"
            "|---|---|---|---|---|---|\n"
            + "".join(f"| {r['number']}{' (the YAML)' if r['yaml'] else ''} | {r['gamma']} | {r['learning_rate']:.3g} "
                      f"| {r['mean']:.2f} [{r['ci_low']:.2f}, {r['ci_high']:.2f}] | "
                      f"{', '.join(f'{e:.2f}' for e in r['error_by_seed'])} | {minutes(r['train_seconds'])} |\n"
                      for r in confirmed)
            + ("\nVerdict: keep the YAML's values: no trial's interval lies wholly below the YAML's, so the seeds do "
               "not tell them apart from it.\n" if kept else
               f"\nVerdict: adopt trial {choice['number']} (gamma {choice['gamma']}, learning_rate "
               f"{choice['learning_rate']:.3g}): its interval lies wholly below the YAML's; `{stem}.yml` carries it.\n"))
    write_text(args.out / f"{stem}.md", header + "\n" + "\n".join(rows) + "\n" + best_line + confirmation)
    record: dict[str, Any] = {"command": command, "commit": code_revision(), "study": study.study_name,
                              "timesteps": budget, "seeds": args.seeds,
                              "episodes": args.episodes, "best": {"number": best.number, **best.params,
                                                                   "value": best.value},
                              "trials": [{"number": t.number, **t.params, "value": t.value, **t.user_attrs}
                                         for t in finished],
                              "confirm_seeds": args.confirm_seeds if confirmed else [], "confirmation": confirmed,
                              "chosen": choice}
    write_text(args.out / f"{stem}.json", json.dumps(record, indent=1))
    write_text(args.out / f"{stem}.yml", f"# {command} at {code_revision()}: trial {choice['number']} of "
               f"{len(finished)}{' (the confirmation kept the YAML)' if choice.get('yaml') else ''}\n"
               + yaml.safe_dump({env_id: tuned}, sort_keys=False))
    print(f"wrote {args.out / stem}.md, .json and .yml")


if __name__ == "__main__":
    main()
