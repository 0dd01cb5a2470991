"""Frames of SoftSphereHaptic-v0 from ``rgb_array`` for the README: a hand inserts the blade, presses
the tongue, sweeps it aside, then levers on the incisors (the error of technique).

    python scripts/laryngoscope_frames.py --out results
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gymnasium as gym
import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from softenv._artifact import save_figure, write_text
import softenv  # noqa: E402,F401  (registers the ids)
from softenv.bench.timing import code_revision  # noqa: E402
from softenv.render import displacement_colorbar  # noqa: E402

# (label, steps, action: insert, press, sweep, pitch rate) -- 20 ms per step
SCRIPT = [("insert", 10, [0.5, 0.0, 0.0, 0.0]), ("press", 12, [0.0, 0.9, 0.0, 0.0]),
          ("sweep", 15, [0.0, 0.0, 0.6, 0.0]), ("lever on the teeth", 25, [0.0, -0.6, 0.0, -0.8])]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", default="results")
    args = parser.parse_args()
    env = gym.make("softenv:SoftSphereHaptic-v0", render_mode="rgb_array", render={"size": 360})
    env.reset(seed=0)
    frames, captions = [], []
    for label, steps, action in SCRIPT:
        for _ in range(steps):
            _, _, _, _, info = env.step(np.array(action, np.float32))
        frames.append(env.render())
        captions.append(f"{label}: tongue {info['tongue_force_N']:.0f} N, incisors {info['incisor_force_N']:.0f} N, "
                        f"error {info['shape_error_mm']:.2f} mm")
    fig, axes = plt.subplots(len(frames), 1, figsize=(7.2, 3.6 * len(frames) + 0.9), dpi=100, layout="constrained")
    for ax, frame, caption in zip(axes, frames, captions):
        ax.imshow(frame)
        ax.set_title(caption, fontsize=9)
        ax.axis("off")
    displacement_colorbar(fig, axes, env.unwrapped.world.scene.tissue.radius, orientation="horizontal", shrink=0.6,
                          aspect=40, pad=0.01)
    fig.suptitle("SoftSphereHaptic-v0, render_mode=\"rgb_array\": left, the tongue (colour: displacement) and its\n"
                 "target (blue wireframe); right, the side view (blade, incisors, tongue)", fontsize=9)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    save_figure(fig, out / "laryngoscope_frames.png")
    write_text(out / "laryngoscope_frames.txt", "made by: python scripts/laryngoscope_frames.py --out "
                                                 f"{args.out} at {code_revision()}\n" + "\n".join(captions) + "\n")
    print(f"wrote {out / 'laryngoscope_frames.png'}")


if __name__ == "__main__":
    main()
