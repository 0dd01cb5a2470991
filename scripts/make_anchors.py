"""Make the shipped anchors: for every benchmark scene, each test episode's summed shape error under no
force (the score's 0) and under the planning oracle (its 100), into ``softenv/baselines/shipped_anchors/``
(package data; the format is :mod:`softenv.baselines.anchors`'). Run it from a clean commit: each file
names the commit and this command. It runs with one BLAS thread and an empty cache of its own, as the
tests and ``softenv compare`` do (a scene's shape model built with other BLAS threads differs in the last
bits). Nearly all of its time is the laryngoscope oracle's search (16 candidates x 120 iterations from
each of three starts, per episode): under two hours on 2 cores (``docs/results.md`` has the measured figure).
It runs as jobs of ``CHUNK`` episodes (an episode's plan does not depend on the episodes planned beside
it); with ``--runs DIR`` each finished job is kept there (:mod:`softenv.baselines.run_store`, checked
against the code that made it), and a run stopped and started again picks up where it stopped.

    python scripts/make_anchors.py [--scenes SCENE ...] [--episodes 100] [--jobs 2] [--runs DIR]
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

import numpy as np

from softenv._artifact import write_text
from softenv.baselines.anchors import anchors_file, anchors_record, compute_anchors
from softenv.baselines.evaluate import EPISODES, SCENES, episode_seeds
from softenv.baselines.run_store import RunStore
from softenv.bench import single_thread_environment, threads_pinned
from softenv.bench.timing import code_revision
from softenv.parallel import Job, JobResult, run_jobs, usable_cores

CHUNK = 10          # episodes a job: a job is about 5 minutes of a laryngoscope scene's oracle on one core


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
    parser.add_argument("--runs", type=Path, default=None, help="keep each finished job here, to resume a stopped run")
    args = parser.parse_args()
    seeds = episode_seeds(args.episodes)
    made_by = {"command": "python scripts/make_anchors.py " + " ".join(shlex.quote(a) for a in sys.argv[1:]),
               "commit": code_revision()}
    # the longest first (the laryngoscope's searches), so the workers finish together
    order = sorted(args.scenes, key=lambda s: "Haptic" not in s)
    jobs = [Job(f"{scene}/{start:03d}", compute_anchors, (scene, seeds[start:start + CHUNK]))
            for scene in order for start in range(0, len(seeds), CHUNK)]
    store = None if args.runs is None else RunStore(args.runs)
    done: dict[str, JobResult] = {}
    for job in jobs if store is not None else ():
        stored, why = store.load(job)
        if stored is not None:
            done[job.key] = stored
        elif why != "absent":
            print(f"{job.key}: its entry in {store.dir} is not used ({why}); the job runs again")
    if done:
        print(f"resuming: {len(done)} of {len(jobs)} jobs were finished by an earlier run ({store.dir})")
    todo = {job.key: job for job in jobs if job.key not in done}

    def keep(result: JobResult) -> None:
        if store is not None:
            store.save(todo[result.key], result)

    for result in run_jobs(list(todo.values()), n_jobs=args.jobs, on_result=keep):
        if not result.ok:
            raise SystemExit(f"{result.key}: {result.error}")
        done[result.key] = result
    for scene in order:
        parts = [done[job.key].value for job in jobs if job.args[0] == scene]
        zero, oracle = np.concatenate([z for z, _, _ in parts]), np.concatenate([o for _, o, _ in parts])
        path = anchors_file(scene) if args.out is None else args.out / anchors_file(scene).name
        write_text(path, json.dumps(anchors_record(scene, seeds, zero, oracle, made_by), indent=1) + "\n")
        print(f"wrote {path} ({sum(done[job.key].wall_s for job in jobs if job.args[0] == scene):.0f} s of jobs)")
    shutil.rmtree(os.environ["SOFTENV_ANCHORS_CACHE"], ignore_errors=True)


if __name__ == "__main__":
    main()
