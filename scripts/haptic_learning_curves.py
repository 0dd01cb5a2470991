"""Learning curves of the stable-baselines3 agents on a laryngoscope scene, past the benchmark's
budgets (issue 37, part 5): several seeds, the mean and 95 % band of the test return against env steps,
and each agent's normalized score beside the scripted expert's, with bootstrap intervals. It runs
``softenv compare``'s machinery (``baselines.benchmark.run``) on a plan of its own, so a stopped run
resumes from ``--runs`` and the tables and plots are the benchmark's.

    python scripts/haptic_learning_curves.py --scene SoftSphereHapticProcedure-v0 --agents ppo \
        --timesteps 1000000 --seeds 3 --out results/haptic-curves --runs runs/haptic-curves --jobs 2
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from baselines.benchmark import ALGOS, Plan, run
from baselines.evaluate import SCENES


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scene", default="SoftSphereHapticProcedure-v0", choices=[s for s in SCENES if "Haptic" in s])
    p.add_argument("--agents", nargs="+", default=["ppo"], choices=list(ALGOS))
    p.add_argument("--timesteps", type=int, default=1_000_000, help="each agent's training budget (env steps)")
    p.add_argument("--seeds", type=int, default=3, help="training seeds per agent")
    p.add_argument("--episodes", type=int, default=100, help="test episodes per policy")
    p.add_argument("--out", type=Path, default=Path("reports/haptic-curves"))
    p.add_argument("--runs", type=Path, default=Path("runs/haptic-curves"))
    p.add_argument("--jobs", type=int, default=2)
    args = p.parse_args(argv)
    plan = Plan([args.scene], ["zero", "expert"], list(args.agents), {args.scene: args.seeds},
                {agent: args.timesteps for agent in args.agents}, episodes=args.episodes)
    command = "python scripts/haptic_learning_curves.py " + shlex.join(sys.argv[1:] if argv is None else argv)
    run(plan, args.out, args.runs, command, stem="haptic_curves", n_jobs=args.jobs)


if __name__ == "__main__":
    main()
