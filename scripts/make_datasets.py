"""Make the Minari datasets (``softenv.baselines.minari_datasets``) and write what they hold into
``results/datasets.md`` and ``.json``: episodes, steps, size on disk, the commit that made each and in
how long, the reference returns, each demonstrator's mean return and Minari-normalized score, and its
clinical metrics. Run it from a clean commit (the files name it); one BLAS thread, as ``softenv
compare`` runs. A dataset already in Minari's local store with the episodes asked for is read, not
made again: the table is then the store's catalogue, each row naming the commit that made it.

    python scripts/make_datasets.py [--scenes SCENE ...] [--kinds KIND ...] [--episodes 100] [--runs runs]
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path

import minari
import numpy as np

from softenv._artifact import write_text
from softenv.baselines.minari_datasets import DATASET_SCENES, KINDS, load_or_make, size_bytes, softenv_metadata
from softenv.bench import rerun_single_threaded
from softenv.bench.timing import code_revision

CLINICAL = ("peak_tongue_force_N", "peak_incisor_force_N", "hand_path_m", "glottic_view_pct")


def main() -> None:
    rerun_single_threaded()
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", choices=list(DATASET_SCENES), default=list(DATASET_SCENES))
    parser.add_argument("--kinds", nargs="+", choices=list(KINDS), default=list(KINDS))
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--runs", type=Path, default=Path("runs"), help="where the ppo dataset's agent trains")
    parser.add_argument("--out", type=Path, default=Path("results"))
    args = parser.parse_args()
    rows = []
    for scene in args.scenes:
        for kind in args.kinds:
            dataset = load_or_make(scene, kind, args.episodes, args.runs, echo=print)
            meta, raw = softenv_metadata(dataset), dataset.storage.metadata
            returns = np.array(meta["returns"])
            rows.append({"dataset": dataset.spec.dataset_id, "scene": scene, "kind": kind,
                         "demonstrator": meta["demonstrator"], "episodes": dataset.total_episodes,
                         "steps": dataset.total_steps, "megabytes": size_bytes(dataset) / 1e6,
                         "made_at": meta.get("commit", "?"), "seconds": meta.get("seconds", float("nan")),
                         "ref_min_score": raw["ref_min_score"], "ref_max_score": raw["ref_max_score"],
                         "mean_return": float(returns.mean()),
                         "normalized": float(minari.get_normalized_score(dataset, returns).mean()),
                         **{key: float(np.mean(meta["clinical"][key])) for key in CLINICAL}})
            print(f"{rows[-1]['dataset']}: {rows[-1]['megabytes']:.1f} MB, normalized {rows[-1]['normalized']:.2f}")
    made_by = {"command": "python scripts/make_datasets.py " + " ".join(shlex.quote(a) for a in sys.argv[1:]),
               "commit": code_revision(), "minari": minari.__version__}
    write_text(args.out / "datasets.json", json.dumps({"made_by": made_by, "datasets": rows}, indent=1) + "\n")
    lines = ["# Minari datasets", "", f"Made by `{made_by['command']}` at commit `{made_by['commit']}` "
             f"(Minari {made_by['minari']}). Each episode seeded by its index on the scene's training targets; "
             "normalized: `minari.get_normalized_score` of the mean return (0: no force, 1: the trajectory oracle, "
             "on the protocol's test episodes).", "",
             "| dataset | demonstrator | episodes | steps | MB | made at | made in (s) | mean return | normalized | "
             "peak tongue N | peak incisor N | hand path m | glottic view % |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| `{r['dataset']}` | {r['demonstrator']} | {r['episodes']} | {r['steps']:,} | {r['megabytes']:.1f} "
                     f"| {r['made_at']} | {r['seconds']:.0f} | {r['mean_return']:.1f} | {r['normalized']:.2f} | "
                     f"{r['peak_tongue_force_N']:.1f} | {r['peak_incisor_force_N']:.1f} | {r['hand_path_m']:.3f} | "
                     f"{r['glottic_view_pct']:.0f} |")
    refs = {r["scene"]: (r["ref_min_score"], r["ref_max_score"]) for r in rows}
    lines += ["", "Reference returns (mean over the protocol's test episodes): "
              + "; ".join(f"{scene}: {lo:.1f} (no force), {hi:.1f} (oracle)" for scene, (lo, hi) in refs.items()), ""]
    write_text(args.out / "datasets.md", "\n".join(lines))
    print(f"wrote {args.out / 'datasets.md'} and .json")


if __name__ == "__main__":
    main()
