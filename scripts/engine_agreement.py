"""The laryngoscope's batched twin against single envs over many seeded episodes (issue 37, part 2);
writes ``results/engine_agreement.md`` and ``.json``.

For each laryngoscope scene (both ids and each airway grade) and baseline policy, ``--episodes`` test episodes (env ``i`` seeded ``1000 + i``)
run twice through ``baselines.evaluate``: once on the batched twin with ``--engine`` (all at once), once
on as many single envs (pymunk, Gymnasium's ``SyncVectorEnv``). Per metric (the episode's score and
errors, and the clinical metrics): how many episodes agree bit for bit, the largest difference, and the
two-sample Kolmogorov-Smirnov test's p-value of the two distributions (scipy). With the exact engines
every episode agrees bit for bit, so any policy (a trained agent included) scores the same on either.

    python scripts/engine_agreement.py [--episodes 1000] [--engine warp] [--policies zero random expert invert-poly2]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import ks_2samp

from softenv.baselines.benchmark import baseline_job
from softenv.baselines.evaluate import SCENES, device_kind
from softenv._artifact import write_text
from softenv.bench.timing import code_revision

# every benchmark scene on the laryngoscope: both ids and each airway grade (the env id SoftSphereAirway-v0
# is not a scene of its own: its grades are)
LARYNGOSCOPE = [s for s in SCENES if device_kind(s) == "laryngoscope"]


def compare(scene: str, name: str, episodes: int, engine: str) -> dict[str, dict[str, float | None]]:
    """Per metric: episodes equal bit for bit, the largest |difference| and the KS p-value."""
    batch = baseline_job(name, scene, episodes, device={"batch_engine": engine}).values
    single = baseline_job(name, scene, episodes, "sync").values
    out: dict[str, dict[str, float | None]] = {}
    for metric, x in batch.items():
        y = single[metric]
        same = (x == y) | (np.isnan(x) & np.isnan(y))
        finite = ~np.isnan(x) & ~np.isnan(y)
        diff = float(np.max(np.abs(x[finite] - y[finite]))) if finite.any() else 0.0
        p = float(ks_2samp(x[finite], y[finite]).pvalue) if finite.sum() > 1 else None
        out[metric] = {"equal": int(same.sum()), "max_diff": diff, "ks_p": p}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--engine", default="warp", choices=("warp", "pymunk"))
    parser.add_argument("--policies", nargs="+", default=["zero", "random", "expert", "invert-poly2"])
    parser.add_argument("--out", type=Path, default=Path("results"))
    args = parser.parse_args()
    start = time.time()
    table: dict[str, dict[str, dict[str, dict[str, Any]]]] = {}
    for scene in LARYNGOSCOPE:
        for name in args.policies:
            table.setdefault(scene, {})[name] = compare(scene, name, args.episodes, args.engine)
            print(f"{scene} {name}: done", flush=True)
    command = "python scripts/engine_agreement.py " + " ".join(sys.argv[1:])
    lines = [f"# The batched twin ({args.engine} engine) against single envs", "",
             f"Made by `{command.strip()}` at commit `{code_revision()}` in {time.time() - start:.0f} s: {args.episodes} "
             "seeded test episodes of "
             "each policy on each laryngoscope scene, on the batched twin and on as many single (pymunk) envs. "
             "Per metric: episodes equal bit for bit, the largest difference, and the two-sample "
             "Kolmogorov-Smirnov p-value of the two distributions.", "",
             "| scene | policy | metrics | equal episodes (fewest of any metric) | largest difference | smallest KS p-value |",
             "|---|---|---|---|---|---|"]
    for scene, policies in table.items():
        for name, metrics in policies.items():
            equal = min(r["equal"] for r in metrics.values())
            diff = max(r["max_diff"] for r in metrics.values())
            p = min(r["ks_p"] for r in metrics.values() if r["ks_p"] is not None)
            lines.append(f"| {scene} | {name} | {len(metrics)} | {equal} / {args.episodes} | {diff:.3g} | {p:.3g} |")
    lines += ["", "Metrics: " + ", ".join(next(iter(next(iter(table.values())).values()))) + ". Per metric in "
              "`engine_agreement.json`. A KS p-value is left out where a metric has fewer than two finite values "
              "(steps to success where no episode succeeded)."]
    write_text(args.out / "engine_agreement.md", "\n".join(lines) + "\n")
    write_text(args.out / "engine_agreement.json", json.dumps({"command": command, "commit": code_revision(),
                                                               "engine": args.engine,
                                                               "episodes": args.episodes, "table": table}, indent=1))


if __name__ == "__main__":
    main()
