"""Write the example trainee logs as CSV.

    python scripts/make_example_trajectories.py --out softenv/training/examples

``device_logs/``: hand poses as a haptic device records them (softenv.training.trainee): the scripted
expert, and trainees who lever on the teeth, press too hard, hesitate with a tremor, and sweep the
wrong way. ``trajectories/``: force commands for the ideal device (softenv.training.scoring).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from softenv.training.logs import HAND_LOG, save_log
from softenv.training.scoring import expert_trajectory, save_trajectory
from softenv.training.trainee import degrade, expert_hand_log

STYLES = ("expert", "too_forceful", "wrong_direction")
DEVICE_LOGS = {"expert": {}, "levers_on_teeth": {"lever": 0.3}, "too_forceful": {"overshoot": 8.0},
               "hesitant_tremulous": {"hesitation": 0.8, "tremor": 0.6}, "wrong_direction": {"direction": 1.0}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", default="softenv/training/examples")   # shipped with the package
    args = parser.parse_args()
    made_by = f"made by: python scripts/make_example_trajectories.py --out {args.out}"
    for style in STYLES:
        path = Path(args.out) / "trajectories" / f"{style}.csv"
        save_trajectory(expert_trajectory(style=style), path, note=f"{made_by} (force commands, {style})")
        print(f"wrote {path}")
    expert = expert_hand_log()
    for name, errors in DEVICE_LOGS.items():
        path = Path(args.out) / "device_logs" / f"{name}.csv"
        save_log(degrade(expert, **errors), path, HAND_LOG, note=f"{made_by} (hand poses, {name}: {errors or 'no errors'})")
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
