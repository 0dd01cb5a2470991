"""Results anyone can report on softenv, and the check that they were made under the protocol.

A result is one method on one benchmark scene, as a JSON file (``format_version`` 1):

| key | what |
|---|---|
| ``format``, ``format_version`` | ``"softenv-result"``, 1 |
| ``method``, ``kind`` | the method's name; ``baseline``, ``agent`` or ``submission`` |
| ``scene``, ``scene_hash`` | a benchmark scene (``softenv.evaluation.SCENES``) and the hash of its config |
| ``protocol``, ``split`` | the protocol's version and ``"test"`` |
| ``episodes``, ``seeds`` | the number of test episodes and their seeds (the protocol's first ``episodes``) |
| ``training_seeds`` | one label per run (training seed); ``[]`` for a method that does not train |
| ``error_sum``, ``normalized_score`` | per run, per episode: the summed shape error and the normalized score |
| ``anchors`` | the digest of the anchors the scores were scaled by, and the oracle (name, version, search) of their 100 |
| ``aggregates`` | ``mean``, ``ci_low``, ``ci_high``, ``iqm``, ``iqm_low``, ``iqm_high``, ``per_run`` as reported |
| ``softenv``, ``command``, ``hardware``, ``date`` | what made it |
| ``notes`` (optional) | a line for the reader (an agent's budget, say) |

:func:`check_result` accepts a file only if every field is there with its type; it is on the test
split, under this protocol, with the protocol's ``EPISODES`` episodes and seeds; its scene hashes as
the scene does now; its anchors are the shipped ones; its normalized scores are its error sums scaled
by those anchors; and its aggregates are what its scores give. Anything else is refused in one line
that names what differs.
"""

from __future__ import annotations

import datetime
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

import softenv

from . import stats
from ._artifact import save_figure, write_text
from .baselines.anchors import load_anchors, oracle_of, scene_config, scene_hash
from .baselines.evaluate import EPISODES, GRADED_SCENES, PROTOCOL_VERSION, SCENES, SPLIT, device_kind, episode_seeds, normalized_scores
from .bench.timing import machine_info
from .evaluation import Evaluation, score_aggregates

RESULT_FORMAT = "softenv-result"
RESULT_VERSION = 1
KINDS = ("baseline", "agent", "submission")
FIELDS: dict[str, type | tuple[type, ...]] = {
    "format": str, "format_version": int, "method": str, "kind": str, "scene": str, "scene_hash": str,
    "protocol": int, "split": str, "episodes": int, "seeds": list, "training_seeds": list, "error_sum": list,
    "normalized_score": list, "anchors": dict, "aggregates": dict, "softenv": str, "command": str,
    "hardware": dict, "date": str}
AGGREGATE_KEYS = ("mean", "ci_low", "ci_high", "iqm", "iqm_low", "iqm_high", "per_run")
TOLERANCE = 1e-6       # aggregates are recomputed from the scores: as JSON keeps them, to rounding


def result_record(evaluation: Evaluation, kind: str = "submission", command: str = "",
                  training_seeds: list[Any] | None = None) -> dict[str, Any]:
    """An evaluation as a result file's contents (see the module docstring)."""
    if kind not in KINDS:
        raise ValueError(f"kind={kind!r}; choose from {list(KINDS)}")
    runs = len(evaluation.normalized_score)
    labels = list(training_seeds) if training_seeds is not None else ([] if runs == 1 else list(range(runs)))
    if labels and len(labels) != runs:
        raise ValueError(f"training_seeds has {len(labels)} labels for {runs} runs")
    summary = evaluation.summary()
    return {"format": RESULT_FORMAT, "format_version": RESULT_VERSION, "method": evaluation.policy, "kind": kind,
            "scene": evaluation.scene, "scene_hash": evaluation.scene_hash, "protocol": evaluation.protocol,
            "split": evaluation.split, "episodes": len(evaluation.seeds), "seeds": list(evaluation.seeds),
            "training_seeds": labels, "error_sum": evaluation.error_sum.tolist(),
            "normalized_score": evaluation.normalized_score.tolist(),
            "anchors": {"digest": evaluation.anchors.digest(), "oracle": oracle_of(evaluation.scene)},
            "aggregates": {key: summary[key] for key in AGGREGATE_KEYS}, "softenv": softenv.__version__,
            "command": command or f"softenv.evaluation.evaluate_policy({evaluation.policy!r}, {evaluation.scene!r})",
            "hardware": machine_info(), "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")}


def save_result(record: dict[str, Any], path: str | Path) -> Path:
    """Write a result file (checked first: a file :func:`check_result` would refuse is not written)."""
    check_result(record)
    return write_text(path, json.dumps(record, indent=1) + "\n")


def read_result(path: str | Path) -> dict[str, Any]:
    """A result file's contents (``ValueError`` naming the file if it is not JSON)."""
    try:
        record = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"result {str(path)!r} is not readable JSON: {exc}") from None
    if not isinstance(record, dict):
        raise ValueError(f"result {str(path)!r} holds a {type(record).__name__}, not a JSON object")
    return record


def _matrix(record: dict[str, Any], key: str, runs: int, episodes: int) -> np.ndarray:
    try:
        m = np.array(record[key], dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{key} must be a list of runs, each a list of {episodes} numbers") from None
    if m.shape != (runs, episodes) or not np.isfinite(m).all():
        raise ValueError(f"{key} has shape {m.shape} (finite: {bool(np.isfinite(m).all())}); expected {runs} run(s) "
                         f"x {episodes} episodes, all finite")
    return m


def check_result(record: dict[str, Any]) -> dict[str, Any]:
    """Refuse (``ValueError``, one line naming what differs) a result not made under the protocol, on
    another scene or other anchors, or whose numbers do not follow from its scores; else return the
    aggregates recomputed from them."""
    missing = [key for key in FIELDS if key not in record]
    if missing:
        raise ValueError(f"missing fields: {', '.join(missing)}")
    wrong = [f"{key} ({type(record[key]).__name__}, expected {getattr(kind, '__name__', kind)})"
             for key, kind in FIELDS.items() if not isinstance(record[key], kind) or isinstance(record[key], bool)]
    if wrong:
        raise ValueError(f"fields of the wrong type: {', '.join(wrong)}")
    if record["format"] != RESULT_FORMAT or record["format_version"] != RESULT_VERSION:
        raise ValueError(f"format {record['format']!r} version {record['format_version']}; this softenv reads "
                         f"{RESULT_FORMAT!r} version {RESULT_VERSION}")
    if record["kind"] not in KINDS:
        raise ValueError(f"kind {record['kind']!r}; one of {list(KINDS)}")
    if record["split"] != SPLIT:
        raise ValueError(f"split {record['split']!r}: results are made on the {SPLIT!r} targets, never the ones "
                         "agents train on")
    if record["protocol"] != PROTOCOL_VERSION:
        raise ValueError(f"protocol version {record['protocol']}; this softenv's is {PROTOCOL_VERSION}")
    scene = record["scene"]
    if scene not in SCENES:
        raise ValueError(f"scene {scene!r} is not a benchmark scene; valid scenes: {list(SCENES)}")
    expected_hash = scene_hash(scene_config(scene))
    if record["scene_hash"] != expected_hash:
        raise ValueError(f"scene_hash {record['scene_hash']!r} is not {scene}'s ({expected_hash!r}): made on "
                         "another scene config")
    episodes = record["episodes"]
    if episodes != EPISODES or record["seeds"] != episode_seeds(EPISODES):
        raise ValueError(f"episodes {episodes} with seeds {_span(record['seeds'])}; the protocol's are {EPISODES} "
                         f"episodes seeded {_span(episode_seeds(EPISODES))}")
    runs = len(record["normalized_score"])
    labels = record["training_seeds"]
    if runs < 1 or (labels and len(labels) != runs) or (not labels and runs != 1):
        raise ValueError(f"{runs} run(s) of scores for {len(labels)} training_seeds labels; one label per run "
                         "(none for a single run of a method that does not train)")
    error_sum = _matrix(record, "error_sum", runs, episodes)
    scores = _matrix(record, "normalized_score", runs, episodes)
    anchors = load_anchors(scene, episode_seeds(EPISODES), echo=lambda line: None)
    if record["anchors"].get("digest") != anchors.digest():
        raise ValueError(f"anchors digest {record['anchors'].get('digest')!r} is not {scene}'s shipped anchors' "
                         f"({anchors.digest()!r}): scaled by another scene's or another oracle's anchors")
    rescaled = normalized_scores(error_sum, anchors.zero, anchors.oracle)
    off = np.abs(rescaled - scores) > TOLERANCE * np.maximum(1.0, np.abs(rescaled))
    if off.any():
        run, episode = map(int, np.argwhere(off)[0])
        raise ValueError(f"normalized_score of run {run}, episode {episode} is {scores[run, episode]!r}; its error sum "
                         f"with the shipped anchors gives {rescaled[run, episode]!r} ({int(off.sum())} such entries)")
    recomputed = score_aggregates(scores)
    reported = record["aggregates"]
    for key in AGGREGATE_KEYS:
        if key not in reported:
            raise ValueError(f"aggregates lack {key!r}")
        if not _close(reported[key], recomputed[key]):
            raise ValueError(f"aggregates[{key!r}] = {reported[key]!r}, but the scores give {recomputed[key]!r}")
    return recomputed


def _close(a: Any, b: Any) -> bool:
    if isinstance(b, list):
        return isinstance(a, list) and len(a) == len(b) and all(_close(x, y) for x, y in zip(a, b))
    return isinstance(a, (int, float)) and not isinstance(a, bool) and math.isclose(a, b, rel_tol=TOLERANCE,
                                                                                     abs_tol=TOLERANCE)


def _span(seeds: Any) -> str:
    if not isinstance(seeds, list) or not seeds:
        return repr(seeds)
    return f"{seeds[0]}..{seeds[-1]}" if len(seeds) > 2 else repr(seeds)


def load_results(folder: str | Path) -> list[dict[str, Any]]:
    """Every result file in ``folder`` (``*.json``), each checked (a refused one raises, naming it)."""
    out = []
    for path in sorted(Path(folder).glob("*.json")):
        record = read_result(path)
        try:
            check_result(record)
        except ValueError as exc:
            raise ValueError(f"{path.name}: {exc}") from None
        out.append(record)
    return out


def table(records: list[dict[str, Any]], highlight: str | None = None) -> str:
    """A Markdown leaderboard: per scene, the methods by mean normalized score, with their intervals."""
    lines = []
    for scene in [s for s in SCENES if any(r["scene"] == s for r in records)]:
        rows = sorted((r for r in records if r["scene"] == scene), key=lambda r: -r["aggregates"]["mean"])
        lines += [f"### {scene}", "", "| rank | method | kind | normalized score [95 % CI] | IQM [95 % CI] | runs | by run | notes |",
                  "|---|---|---|---|---|---|---|---|"]
        for rank, r in enumerate(rows, 1):
            a = r["aggregates"]
            name = f"**{r['method']}**" if r["method"] == highlight else r["method"]
            by_run = ", ".join(f"{v:.1f}" for v in a["per_run"]) if len(a["per_run"]) > 1 else ""
            lines.append(f"| {rank} | {name} | {r['kind']} | {a['mean']:.1f} [{a['ci_low']:.1f}, {a['ci_high']:.1f}] | "
                         f"{a['iqm']:.1f} [{a['iqm_low']:.1f}, {a['iqm_high']:.1f}] | {len(a['per_run'])} | {by_run} | "
                         f"{r.get('notes', '')} |")
        lines.append("")
    return "\n".join(lines)


# -- across scenes (rliable's aggregates) ----------------------------------------------------------------

def scene_groups() -> dict[str, list[str]]:
    """The benchmark's scenes by device: methods are compared across the scenes of one device; the graded
    airways form a group of their own (a method is aggregated over every grade, or not at all)."""
    groups: dict[str, list[str]] = {}
    graded = set(GRADED_SCENES.values())
    for scene in SCENES:
        groups.setdefault("graded airways" if scene in graded else device_kind(scene), []).append(scene)
    return groups


def across_scenes(records: list[dict[str, Any]], scenes: list[str]) -> dict[str, list[np.ndarray]]:
    """Each method with a result on every one of ``scenes``, with the same number of runs on each: per
    scene its ``(runs, episodes)`` normalized scores (:func:`softenv.stats.with_resamples`' input: runs
    and the episodes within them resampled within each scene)."""
    by_method: dict[str, dict[str, list[list[float]]]] = {}
    for r in records:
        if r["scene"] in scenes:
            by_method.setdefault(r["method"], {})[r["scene"]] = r["normalized_score"]
    out = {}
    for method, runs in by_method.items():
        if set(runs) == set(scenes) and len({len(v) for v in runs.values()}) == 1:
            out[method] = [np.array(runs[s], dtype=np.float64) for s in scenes]
    return out


def aggregates_table(records: list[dict[str, Any]], resamples: int = stats.RESAMPLES) -> str:
    """Markdown: per device, every method with results on all its scenes, by IQM across scenes (of each
    run's mean score on each scene), with the mean, the optimality gap (each with its stratified-bootstrap
    95 % interval: runs, then their episodes, resampled within each scene) and the probability that the
    top method improves on it (with its interval)."""
    lines = []
    for device, scenes in scene_groups().items():
        matrices = across_scenes(records, scenes)
        if not matrices:
            continue
        estimates = {m: stats.interval_estimates(x, resamples=resamples) for m, x in matrices.items()}
        ranked = sorted(matrices, key=lambda m: -estimates[m]["iqm"][0])
        top = ranked[0]
        lines += [f"### {device}: {len(scenes)} scene(s) ({', '.join(scenes)})", "",
                  f"| method | runs | IQM [95 % CI] | mean [95 % CI] | optimality gap [95 % CI] | P({top} > method) [95 % CI] |",
                  "|---|---|---|---|---|---|"]
        for m in ranked:
            e = estimates[m]
            cells = [f"{e[k][0]:.1f} [{e[k][1]:.1f}, {e[k][2]:.1f}]" for k in ("iqm", "mean", "optimality_gap")]
            poi = "" if m == top else "{:.2f} [{:.2f}, {:.2f}]".format(
                *stats.improvement_interval(matrices[top], matrices[m], resamples=resamples))
            lines.append(f"| {m} | {len(matrices[m][0])} | {' | '.join(cells)} | {poi} |")
        lines.append("")
    return "\n".join(lines)


def aggregates_figure(records: list[dict[str, Any]], path: str | Path, resamples: int = stats.RESAMPLES) -> Path:
    """Per device, a row of three panels: each method's IQM and optimality gap across scenes (of its runs'
    mean scores) with their stratified-bootstrap 95 % intervals, and its performance profile over episode
    scores (the share of every run's episodes above each score, averaged over scenes; pointwise 95 % bands,
    episodes resampled within each scene). Methods on fewer than all of a device's scenes are left out."""
    import matplotlib                                        # the viz extra

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt                          # the viz extra

    groups = {d: (scenes, across_scenes(records, scenes)) for d, scenes in scene_groups().items()}
    groups = {d: g for d, g in groups.items() if g[1]}
    if not groups:
        raise ValueError("no method has results on every scene of a device: nothing to aggregate")
    fig, axes = plt.subplots(len(groups), 3, figsize=(15, 4.2 * len(groups)), squeeze=False,
                             gridspec_kw={"width_ratios": [1, 1, 1.3]})
    taus = np.arange(1.0, 106.0)          # from 1: a score of 0 with rounding noise is not "above 0"
    for row, (device, (scenes, matrices)) in zip(axes, groups.items()):
        estimates = {m: stats.interval_estimates(x, resamples=resamples) for m, x in matrices.items()}
        ranked = sorted(matrices, key=lambda m: estimates[m]["iqm"][0])
        for ax, key, label in ((row[0], "iqm", "IQM of normalized score"), (row[1], "optimality_gap", "optimality gap")):
            point = np.array([estimates[m][key][0] for m in ranked])
            low = np.array([estimates[m][key][1] for m in ranked])
            high = np.array([estimates[m][key][2] for m in ranked])
            ax.errorbar(point, np.arange(len(ranked)), xerr=[point - low, high - point], fmt="o", color="#333333",
                        ecolor="#8a8a8a", capsize=3)
            ax.set_yticks(np.arange(len(ranked)), ranked, fontsize=8)
            ax.set_xlabel(f"{label} (bars: 95 % stratified-bootstrap interval)", fontsize=8)
            ax.grid(axis="x", alpha=0.3)
        row[0].set_title(f"{device}: across {len(scenes)} scene(s)", fontsize=10, loc="left")
        colours = plt.get_cmap("tab20")(np.linspace(0.0, 1.0, 20))
        for i, m in enumerate(ranked[::-1]):
            # every episode of every run, per scene: a method of one run still has a distribution
            episodes = np.stack([scores.ravel() for scores in matrices[m]], axis=1)
            profile, low, high = stats.profile_intervals(episodes, taus, resamples=resamples)
            row[2].plot(taus, profile, label=m, lw=1.3, color=colours[(2 * i) % 20 + (2 * i) // 20 % 2],
                        ls=("-", "--", ":")[i % 3])
            row[2].fill_between(taus, low, high, color=colours[(2 * i) % 20 + (2 * i) // 20 % 2], alpha=0.15, lw=0)
        row[2].set_xlabel("normalized score tau (0 = no force, 100 = the planning oracle)", fontsize=8)
        row[2].set_ylabel("share of episodes above tau (mean over scenes)", fontsize=8)
        row[2].legend(fontsize=6, ncol=2, loc="lower left")
        row[2].set_title("performance profiles of episode scores (bands: 95 %, episodes resampled)", fontsize=9,
                         loc="left")
    fig.tight_layout()
    try:
        return save_figure(fig, path, dpi=110)
    finally:
        plt.close(fig)
