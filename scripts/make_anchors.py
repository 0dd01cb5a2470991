"""Make the shipped anchors: for every benchmark scene, each test episode's summed shape error under no
force (the score's 0) and under the planning oracle (its 100), into ``softenv/baselines/shipped_anchors/``
(package data; the format is :mod:`softenv.baselines.anchors`'). Run it from a clean commit: each file
names the commit and this command. It runs with one BLAS thread and an empty cache of its own, as the
tests and ``softenv compare`` do (a scene's shape model built with other BLAS threads differs in the last
bits). Nearly all of its time is the laryngoscope oracle's search (16 candidates x 120 iterations from
each of three starts, per episode): under two hours on 2 cores (``docs/results.md`` has the measured figure).

    python scripts/make_anchors.py [--scenes SCENE ...] [--episodes 100] [--jobs 2]
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import shutil
import sys
import tempfile
from pathlib import Path

from softenv._artifact import write_text
from softenv.baselines.anchors import anchors_file, anchors_record, compute_anchors
from softenv.baselines.evaluate import EPISODES, SCENES, episode_seeds
from softenv.bench import single_thread_environment, threads_pinned
from softenv.bench.timing import code_revision
from softenv.parallel import Job, run_jobs, usable_cores


def main() -> None:
    if not threads_pinned() or "SOFTENV_ANCHORS_CACHE" not in os.environ:
        cache = tempfile.mkdtemp(prefix="softenv-anchors-")
        env = {**single_thread_environment(), "SOFTENV_CACHE_DIR": cache, "SOFTENV_ANCHORS_CACHE": cache}
        os.execve(sys.executable, [sys.executable, *sys.argv], env)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", choices=list(SCENES), default=list(SCENES))
    parser.add_argument("--episodes", type=int, default=EPISODES)
    parser.add_argument("--jobs", type=int, default=usable_cores())
    parser.add_argument("--out", type=Path, default=None, help="another folder (default: the package's own)")
    args = parser.parse_args()
    seeds = episode_seeds(args.episodes)
    made_by = {"command": "python scripts/make_anchors.py " + " ".join(shlex.quote(a) for a in sys.argv[1:]),
               "commit": code_revision()}
    # the longest first (the laryngoscope's searches), so the workers finish together
    order = sorted(args.scenes, key=lambda s: "Haptic" not in s)
    results = run_jobs([Job(scene, compute_anchors, (scene, seeds)) for scene in order], n_jobs=args.jobs)
    for scene, result in zip(order, results):
        if not result.ok:
            raise SystemExit(f"{scene}: {result.error}")
        zero, oracle, _ = result.value
        path = anchors_file(scene) if args.out is None else args.out / anchors_file(scene).name
        write_text(path, json.dumps(anchors_record(scene, seeds, zero, oracle, made_by), indent=1) + "\n")
        print(f"wrote {path} ({result.wall_s:.0f} s)")
    shutil.rmtree(os.environ["SOFTENV_ANCHORS_CACHE"], ignore_errors=True)


if __name__ == "__main__":
    main()
