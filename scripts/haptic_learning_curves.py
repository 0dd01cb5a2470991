"""Learning curves of the stable-baselines3 agents on a laryngoscope scene, past the benchmark's
budgets (issue 37, part 5): several seeds, the mean and 95 % band of the test return against env steps,
and each agent's normalized score beside the scripted expert's, with bootstrap intervals. It runs
``softenv compare``'s machinery (``softenv.baselines.benchmark.run``) on a plan of its own, so a stopped run
resumes from ``--runs`` and the tables and plots are the benchmark's.

    python scripts/haptic_learning_curves.py --scene SoftSphereHapticProcedure-v0 \
        --agents ppo sac td3 sac-her --timesteps ppo=4000000 sac=150000 td3=150000 sac-her=100000 \
        --seeds 3 --out results/haptic-curves --runs runs/haptic-curves --jobs 2
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from softenv.baselines.benchmark import ALGOS, Plan, run
from softenv.baselines.evaluate import SCENES


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scene", default="SoftSphereHapticProcedure-v0", choices=[s for s in SCENES if "Haptic" in s])
    p.add_argument("--agents", nargs="+", default=["ppo"], choices=list(ALGOS))
    p.add_argument("--timesteps", nargs="+", default=["1000000"], metavar="[AGENT=]STEPS",
                   help="training budgets in env steps: one number for every agent, or AGENT=STEPS each "
                   "(default: 1000000)")
    p.add_argument("--seeds", type=int, default=3, help="training seeds per agent")
    p.add_argument("--episodes", type=int, default=100, help="test episodes per policy")
    p.add_argument("--out", type=Path, default=Path("reports/haptic-curves"))
    p.add_argument("--runs", type=Path, default=Path("runs/haptic-curves"))
    p.add_argument("--jobs", type=int, default=2)
    args = p.parse_args(argv)
    plan = Plan([args.scene], ["zero", "expert"], list(args.agents), {args.scene: args.seeds},
                budgets(args.timesteps, args.agents, p), episodes=args.episodes)
    command = "python scripts/haptic_learning_curves.py " + shlex.join(sys.argv[1:] if argv is None else argv)
    run(plan, args.out, args.runs, command, stem="haptic_curves", n_jobs=args.jobs)


def budgets(items: list[str], agents: list[str], parser: argparse.ArgumentParser) -> dict[str, int | None]:
    """``--timesteps`` as a budget per agent: ``N`` for all, or ``agent=N`` each (every agent named once)."""
    if len(items) == 1 and "=" not in items[0]:
        items = [f"{agent}={items[0]}" for agent in agents]
    out: dict[str, int | None] = {}
    for item in items:
        agent, _, steps = item.partition("=")
        if agent not in agents or not steps.isdigit() or int(steps) < 1:
            parser.error(f"--timesteps {item!r}: give AGENT=STEPS with AGENT one of {agents} and STEPS a positive "
                         "whole number, or one number for every agent")
        out[agent] = int(steps)
    missing = [agent for agent in agents if agent not in out]
    if missing:
        parser.error(f"--timesteps names no budget for {missing}")
    return out


if __name__ == "__main__":
    main()
