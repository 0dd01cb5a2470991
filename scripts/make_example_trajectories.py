"""Write the three example trainee trajectories (expert, too forceful, wrong direction) as CSV.

    python scripts/make_example_trajectories.py --out examples/trajectories
"""

from __future__ import annotations

import argparse
from pathlib import Path

from softenv.scoring import expert_trajectory, save_trajectory

STYLES = ("expert", "too_forceful", "wrong_direction")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", default="examples/trajectories")
    args = parser.parse_args()
    for style in STYLES:
        path = Path(args.out) / f"{style}.csv"
        save_trajectory(expert_trajectory(style=style), path,
                        note=f"made by: python scripts/make_example_trajectories.py --out {args.out} ({style})")
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
