"""Generate the FE data a tissue.model="fem" scene reads, and time it (the shipped file is made by the
default command):

    python scripts/make_fem_data.py --jobs 2

For the scene of ``--env-id`` with ``tissue={"model": "fem"}`` (its workspace sample, held-out solves
and contact curve, softenv.fem.data.fe_scene_data), writes ``<out>/<env-id>.npz`` (default out:
softenv/fem/shipped, where scenes find it by its header) and ``<report>`` (sizes, time, array digest,
command). Ramps are cached one by one: a stopped run, started again, solves only what is missing;
``--fresh`` uses an empty cache, to time (and check the bits of) a regeneration from nothing;
``--check`` writes the data to a temporary folder instead and compares it with the shipped file:

    python scripts/make_fem_data.py --jobs 2 --fresh --check     # results/fem-data.md, the shipped file kept
"""

from __future__ import annotations

import argparse
import hashlib
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def array_digest(path: Path) -> str:
    """sha256 over the file's arrays (names and bytes): equal for bitwise-equal data."""
    digest = hashlib.sha256()
    with np.load(path, allow_pickle=False) as data:
        for name in sorted(n for n in data.files if n != "__meta__"):
            digest.update(name.encode() + np.ascontiguousarray(data[name]).tobytes())
    return digest.hexdigest()


def largest_difference(path: Path, other: Path) -> float:
    """The largest difference between two files' arrays, each array's over its own largest magnitude in the
    first file (0.0: equal bit for bit); a different set of arrays, shape or dtype raises ValueError, naming it."""
    with np.load(path, allow_pickle=False) as a, np.load(other, allow_pickle=False) as b:
        names = sorted(n for n in a.files if n != "__meta__")
        if names != sorted(n for n in b.files if n != "__meta__"):
            raise ValueError(f"{other} holds arrays {sorted(b.files)}, {path} {sorted(a.files)}")
        worst = 0.0
        for name in names:
            x, y = a[name], b[name]
            if x.shape != y.shape or x.dtype != y.dtype:
                raise ValueError(f"{name}: {other} has {y.dtype}{list(y.shape)}, {path} {x.dtype}{list(x.shape)}")
            difference = float(np.abs(x.astype(np.float64) - y).max()) if x.size else 0.0
            if difference:
                worst = max(worst, difference / float(np.abs(x).max()))
    return worst


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env-id", default="SoftSphere-v0")
    parser.add_argument("--out", default="softenv/fem/shipped")
    parser.add_argument("--report", default="results/fem-data.md")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--executor", default="local", choices=["local", "ray"])
    parser.add_argument("--fresh", action="store_true", help="solve every ramp again (an empty cache)")
    parser.add_argument("--check", action="store_true",
                        help="write to a temporary folder and compare with the file in --out (which is kept)")
    args = parser.parse_args()
    if args.fresh:
        os.environ["SOFTENV_CACHE_DIR"] = tempfile.mkdtemp(prefix="softenv-fem-")   # before softenv reads it

    from softenv._artifact import atomic_write
    from softenv.bench.timing import code_revision
    from softenv.envs import ENV_SCENES, HAPTIC_SCENES
    from softenv.envs.config import scene_config
    from softenv.envs.scene import fe_request
    from softenv.fem.data import fe_scene_data
    from softenv.parallel import Interrupted

    revision = code_revision()            # before the data is written: the shipped file is tracked
    config = scene_config({**ENV_SCENES, **HAPTIC_SCENES}[args.env_id], {"tissue": {"model": "fem"}})
    request = fe_request(config)
    started = time.perf_counter()
    try:
        data = fe_scene_data(request, jobs=args.jobs, executor=args.executor)
    except Interrupted as stop:
        print(f"make_fem_data: stopped by {stop}; every ramp solved so far is cached; run the same command to resume",
              file=sys.stderr)
        raise SystemExit(stop.exit_status) from None
    seconds = time.perf_counter() - started
    shipped = Path(args.out) / f"{args.env_id}.npz"
    path = Path(tempfile.mkdtemp(prefix="softenv-fem-check-")) / shipped.name if args.check else shipped
    data.save(path)
    size = path.stat().st_size
    if args.check:
        difference = largest_difference(shipped, path)
        against = (f"Against the shipped `{shipped}` (array sha256 `{array_digest(shipped)}`): "
                   + ("equal bit for bit." if difference == 0.0 else
                      f"the largest difference is {difference:.1e} of its array's largest value; the shipped file is "
                      "kept.") + "\n\n")
    else:
        against = ""
    fe = request.fe
    text = (f"# FE data of {args.env_id} with tissue.model='fem'\n\n"
            f"FE tongue: {fe.cells_per_side} cells a side, E = {fe.E / 1e3:.1f} kPa, nu = {fe.nu}, radius "
            f"{fe.radius * 1e3:g} mm, patch {fe.patch_radius * 1e3:g} mm, base cap {fe.cap_deg:g} deg.\n\n"
            f"- workspace sample: {request.n_contacts} contact points x {request.n_loads} loads = "
            f"{request.n_contacts * request.n_loads} ramps of {request.steps} load steps: {data.train.n_samples} samples "
            f"on {data.train.mesh.n_vertices} vertices\n"
            f"- held-out solves: {request.n_test_contacts} other contact points x {request.n_loads} loads = "
            f"{data.test.n_samples} samples\n"
            f"- contact curve: {request.curve_steps} load steps to {request.high[2]:g} N at the top: indentation "
            f"{data.curve_depths[-1] * 1e3:.2f} mm; lateral compliance {data.lateral_compliance * 1e3:.3f} mm/N\n\n"
            f"Solved in {seconds:.0f} s over {args.jobs} {args.executor} workers"
            f"{' from an empty cache' if args.fresh else ''} on {os.cpu_count()} cores; "
            f"{'the regenerated file' if args.check else f'`{path}`'} is "
            f"{size / 1e6:.1f} MB; array sha256 `{array_digest(path)}`.\n\n{against}"
            f"Made by `python {' '.join(sys.argv)}` at {revision} ({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}).\n")
    atomic_write(Path(args.report), lambda fh: fh.write(text), text=True)
    if args.check:
        shutil.rmtree(path.parent)
    print(text)


if __name__ == "__main__":
    main()
