"""Train one SB3 agent on a SoftSphere scene.

    python -m softenv.baselines.train --algo sac --scene SoftSphere-v0 --seed 0 --out runs/sac-0
    python -m softenv.baselines.train --algo ppo --timesteps 20000 --out runs/ppo-quick

Hyper-parameters come from ``baselines/hyperparams/<algo>.yml`` (rl-zoo3 format). Logs: CSV and
TensorBoard under ``OUT/logs``, evaluations on the test targets under ``OUT/eval``. The run is written
into ``OUT.partial`` and renamed to ``OUT`` when whole; re-running a finished command loads its agent,
re-running a stopped one trains again from the seed (bit for bit the run that was not stopped).
"""

from __future__ import annotations

import argparse

from .agents import ALGOS, train_agent
from .evaluate import SCENES


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--algo", required=True, choices=list(ALGOS))
    parser.add_argument("--scene", default="SoftSphere-v0", choices=list(SCENES))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--timesteps", type=int, default=None, help="override the YAML budget")
    parser.add_argument("--out", required=True)
    args = parser.parse_args(argv)
    import torch                                            # torch: the rl extra

    torch.set_num_threads(1)
    path = train_agent(args.algo, args.scene, args.seed, args.out, args.timesteps)
    print(f"saved {path}")


if __name__ == "__main__":
    main()
