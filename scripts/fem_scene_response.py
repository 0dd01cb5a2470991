"""Choose the response of FE scenes: every response a scene can step with, fitted to the shipped FE
workspace data of SoftSphere-v0 as the scene fits it (the paper's regressors, clipped; "exact": the
cubic RBF interpolant of the FE solves, tabulated), its surface error against the held-out FE
solves, and the scene's step time against the analytic scene's.

    python scripts/fem_scene_response.py --out results

Writes ``results/fem_scene.md``.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
# the fits are timed from an empty cache (the table says so): a temporary one of its own, unless given
os.environ.setdefault("SOFTENV_CACHE_DIR", tempfile.mkdtemp(prefix="softenv-fem-scene-"))

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

from softenv._artifact import write_text  # noqa: E402
import softenv  # noqa: E402,F401  (registers the ids)
from softenv.bench.timing import code_revision, paired_step_ratios  # noqa: E402
from softenv.response import REGRESSORS  # noqa: E402

FEM = {"tissue": {"model": "fem"}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="results")
    parser.add_argument("--steps", type=int, default=20_000, help="env steps per timing repeat")
    args = parser.parse_args()
    analytic = gym.make("SoftSphere-v0")
    actions = [analytic.action_space.sample() for _ in range(4096)]
    lines = ["| response | held-out surface RMS, median (mm) | p99 (mm) | max (mm) | fit + build (s) | "
             "step time / analytic scene's (median of 5 interleaved pairs) |", "|---|---|---|---|---|---|"]
    for name in ["exact", *REGRESSORS]:
        t0 = time.perf_counter()
        env = gym.make("SoftSphere-v0", **FEM, response={"model": name})
        build = time.perf_counter() - t0
        err = env.unwrapped.world.scene.response_error()
        ratios = paired_step_ratios(env, analytic, actions, args.steps)
        lines.append(f"| {name} | {err['median_mm']:.4f} | {err['p99_mm']:.4f} | {err['max_mm']:.4f} | {build:.1f} | "
                     f"{np.median(ratios):.2f} ({min(ratios):.2f}-{max(ratios):.2f}) |")
        print(lines[-1], flush=True)
    scene = gym.make("SoftSphere-v0", **FEM).unwrapped.world.scene
    fe = scene.fe
    moved = np.sqrt(np.sum((fe.test.shapes - scene.mesh.vertices.ravel()) ** 2, axis=1) / scene.mesh.n_vertices) * 1e3
    text = "\n".join([
        "# The response of FE scenes", "",
        f"SoftSphere-v0 with `tissue={{\"model\": \"fem\"}}`: each regressor is fitted to the shipped FE workspace "
        f"data ({fe.train.n_samples} samples: {fe.request.n_contacts} contact points x {fe.request.n_loads} loads x "
        f"{fe.request.steps} load steps) on the scene's {scene.n_components} PCA components, clipped to the data's "
        f"b range, and compared with {fe.test.n_samples} held-out FE solves ({fe.request.n_test_contacts} other "
        f"contact points). Their surfaces move by {np.median(moved):.2f} mm RMS (median; max {moved.max():.2f} mm). "
        "The error includes the PCA truncation. Fit and build: first `gym.make` with an empty fit cache.", "",
        *lines, "",
        "`exact` (the default `response.model`) is the cubic RBF interpolant of the FE solves with a linear tail "
        "(softenv.response.rbf), tabulated on the scene's `response.table_nodes` as the analytic tissue is.", "",
        f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; this VM's speed swings "
        "(ratios, not absolute times, are comparable).", "",
        f"Made by `python {' '.join(sys.argv)}` at {code_revision()} ({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}).", ""])
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_text(out / "fem_scene.md", text)
    print(text)


if __name__ == "__main__":
    main()
