"""Generate the FE workspace data of a scene (the default: SoftSphere-v0's) and time it.

    python scripts/make_fem_data.py --out results/fem-data --jobs 2

Solves ``--contacts`` x ``--loads`` ramps of ``--steps`` load steps on the FE tongue over the scene's
device workspace, sampled on the scene's surface mesh (softenv.fem.data.fe_workspace_dataset), and
writes ``fem_workspace.npz`` (a ForceShapeData) and ``fem_workspace.md`` (sizes, time, command).
Ramps are cached one by one: a stopped run, started again, solves only what is missing.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import gymnasium as gym

import softenv  # noqa: F401  (registers the ids)
from softenv.fem.data import fe_workspace_dataset
from softenv.fem.tongue import FEParams


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="results/fem-data")
    parser.add_argument("--env-id", default="SoftSphere-v0")
    parser.add_argument("--contacts", type=int, default=64)
    parser.add_argument("--loads", type=int, default=4)
    parser.add_argument("--steps", type=int, default=4)
    parser.add_argument("--cells", type=int, default=8, help="hexahedra along the mapped cube's edge")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--executor", default="local", choices=["local", "ray"])
    args = parser.parse_args()
    scene = gym.make(args.env_id).unwrapped.world.scene
    params = FEParams(radius=scene.tissue.radius, patch_radius=scene.tissue.patch_radius, cells_per_side=args.cells)
    started = time.perf_counter()
    data = fe_workspace_dataset(scene.workspace, scene.mesh, params, n_contacts=args.contacts, n_loads=args.loads,
                                steps=args.steps, jobs=args.jobs, executor=args.executor)
    seconds = time.perf_counter() - started
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    data.save(out / "fem_workspace.npz")
    size = (out / "fem_workspace.npz").stat().st_size
    text = (f"# FE workspace data of {args.env_id}\n\n{args.contacts} contact points x {args.loads} loads = "
            f"{args.contacts * args.loads} ramps of {args.steps} load steps: {data.n_samples} samples on "
            f"{scene.mesh.n_vertices} vertices, FE tongue of {args.cells} cells a side (E = {params.E / 1e3:.1f} kPa, "
            f"nu = {params.nu}).\n\nSolved in {seconds:.0f} s over {args.jobs} {args.executor} workers; "
            f"`fem_workspace.npz` is {size / 1e6:.1f} MB.\n\nMade by `python {' '.join(sys.argv)}` "
            f"({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}).\n")
    (out / "fem_workspace.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
