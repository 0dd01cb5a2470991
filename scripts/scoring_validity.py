"""Does the trainee score rank skill? Populations of synthetic trainees at graded skill, scored.

    python scripts/scoring_validity.py --out results

The scripted expert's hand log (softenv.training.trainee.expert_hand_log) degraded by tremor, hesitation,
levering and overshoot at 5 levels x 20 trainees (softenv.training.trainee.skill_population), each replayed
through the laryngoscope and scored (softenv.training.scoring); then each error alone at its worst amount
and over its amounts, and a session that does nothing or goes to the target and back.
Writes results/scoring_validity.md: the score per level (mean, 95 % bootstrap interval), Spearman's
rank correlation between skill level and score (target >= 0.9), and which part each error lowers; and
results/scoring_validity.png: every trainee's score by skill level, and each error alone.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from softenv._artifact import save_figure, write_text  # noqa: E402
from softenv.training import profiles  # noqa: E402
from softenv.training.hand import haptic_config  # noqa: E402
from softenv.training.profiles import BISHOP_1992, BUCX_1992, PROFILES  # noqa: E402
from softenv.training.scoring import HAND_FORMULA, HAND_WEIGHTS, score_hand_log  # noqa: E402
from softenv.training.trainee import (LOWERS, WORST, degrade, expert_hand_log, skill_population, spearman,  # noqa: E402
                                      withdrawn)
from softenv.bench.timing import code_revision  # noqa: E402


def figure(skill: np.ndarray, scores: np.ndarray, levels: int, rho: float, alone: list[tuple[str, float]],
           expert: float, graded: dict[str, list[float]], published: list[tuple[str, float]],
           command: str) -> plt.Figure:
    """Left to right: every trainee's score by skill level (jittered), with the level's mean and 95 %
    interval; the expert's score against each error alone at its worst amount; each error alone over its
    amounts, and the part of the score it lowers; the profiles built to published measurements."""
    fig, (left, right, graph, study) = plt.subplots(1, 4, figsize=(18, 4.2), layout="constrained",
                                                    width_ratios=(3, 2, 2, 2))
    bars = study.barh([name for name, _ in published][::-1], [value for _, value in published][::-1], color="tab:blue")
    study.bar_label(bars, fmt="%.1f", fontsize=7, padding=2)
    study.set_xlim(0, 110)                  # room for the labels
    study.set_xlabel("score (0-100)")
    study.set_title("profiles built to published measurements", fontsize=9)
    for name, values in graded.items():
        graph.plot(SHARES, values, "o-", ms=4, label=f"{name}: {LOWERS[name]}")
    graph.set_xlabel("amount (share of the worst)")
    graph.set_ylabel("the part it lowers (0-1)")
    graph.set_ylim(0, 1.05)
    graph.set_title("each error alone, over its amounts", fontsize=9)
    graph.legend(loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=2, fontsize=7, frameon=False)
    jitter = np.random.default_rng(0).uniform(-0.15, 0.15, len(skill))
    left.scatter(skill + jitter, scores, s=10, alpha=0.5, color="tab:blue", label="one synthetic trainee")
    for level in range(levels):
        mean, lo, hi = bootstrap(scores[skill == level])
        left.errorbar(level + 0.3, mean, yerr=[[mean - lo], [hi - mean]], fmt="D", color="black", ms=5, capsize=3,
                      label="mean, 95 % interval" if level == 0 else None)
    left.set_xticks(range(levels), [f"{level}\n{'expert' if level == levels - 1 else ''}" for level in range(levels)])
    left.set_xlabel("skill level (0 = every error at its worst)")
    left.set_ylabel("score (0-100)")
    left.set_title(f"score by skill: Spearman {rho:.3f}", fontsize=9)
    left.legend(loc="lower right", fontsize=7)
    names = [name for name, _ in alone]
    bars = right.barh(names, [value for _, value in alone], color="tab:orange")
    right.bar_label(bars, fmt="%.1f", fontsize=7, padding=2)
    right.axvline(expert, color="black", lw=1, ls="--", label=f"the expert: {expert:.1f}")
    right.set_xlim(0, 110)
    right.set_xlabel("score (0-100)")
    right.set_title("each error alone, at its worst amount; no progress", fontsize=9)
    right.legend(loc="upper center", bbox_to_anchor=(0.5, -0.2), fontsize=7, frameon=False)   # off the bars
    fig.suptitle(f"Does the trainee score rank skill? -- {command}", fontsize=8)
    return fig


SHARES = (0.0, 0.25, 0.5, 0.75, 1.0)      # of each error's worst amount, for the graded study
UNITS = {"tremor": "mm", "hesitation": "s", "lever": "rad", "overshoot": "mm"}     # of each error's amount


def bootstrap(values: np.ndarray, seed: int = 0) -> tuple[float, float, float]:
    rng = np.random.default_rng(seed)
    means = values[rng.integers(0, len(values), (2000, len(values)))].mean(axis=1)
    return float(values.mean()), float(np.percentile(means, 2.5)), float(np.percentile(means, 97.5))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="results")
    parser.add_argument("--levels", type=int, default=5)
    parser.add_argument("--per-level", type=int, default=20)
    args = parser.parse_args()
    started = time.perf_counter()
    expert_log = expert_hand_log()
    parts, _, expert = score_hand_log(expert_log)
    population = skill_population(expert_log, args.levels, args.per_level)
    levels = np.array([level for level, _, _ in population])          # 0 = expert: the errors' level
    skill = args.levels - 1 - levels                                 # the highest level is the expert
    scores = np.array([score_hand_log(log, expert=expert)[0]["score"] for _, _, log in population])
    rho = spearman(skill, scores)
    rows = []
    for level in range(args.levels):
        mean, lo, hi = bootstrap(scores[levels == level])
        share = level / max(args.levels - 1, 1)
        rows.append(f"| {args.levels - 1 - level} | {share:.2f} | {mean:.1f} [{lo:.1f}, {hi:.1f}] | {scores[levels == level].min():.1f} |")
    runs = {name: [score_hand_log(degrade(expert_log, **{name: share * WORST.get(name, 1.0)}), expert=expert)
                   for share in SHARES] for name in LOWERS}
    graded = {name: [parts_[LOWERS[name]] for parts_, _, _ in results] for name, results in runs.items()}
    lever_share = [replay.clinical["lever_share"] for _, replay, _ in runs["lever"]]
    single, alone = [], []
    for name, part in LOWERS.items():
        amount = WORST.get(name, 1.0)
        p = score_hand_log(degrade(expert_log, **{name: amount}), expert=expert)[0]
        alone.append((f"{name} = {amount:g} {UNITS.get(name, '')}".rstrip(), p["score"]))
        single.append(f"| {name} = {amount:g} | {part} | {parts[part]:.3f} -> {p[part]:.3f} | {parts['score']:.1f} -> "
                      f"{p['score']:.1f} |")
    still = expert_log.copy()
    still[:, 1:] = 0.0                                              # the hand held at its start pose
    idle = [(label, score_hand_log(log, expert=expert)[0]) for label, log in
            (("does nothing", still), ("to the target and back", withdrawn(expert_log)))]
    alone += [(label, p["score"]) for label, p in idle]
    built = [(p, score_hand_log(p.log, expert=expert)[0])
             for p in (profiles.build(name, study, ratios, expert_log, expert) for name, study, *ratios in PROFILES)]
    published = [(p, part["score"]) for p, part in built]
    by_name = dict((p.name, score) for p, score in published)
    novices = [score for name, score in by_name.items() if name.startswith("novice")]
    in_order = by_name["expert"] > by_name["intermediate"] > max(novices)
    command = "python " + " ".join(sys.argv)
    md = ["# Does the trainee score rank skill?\n",
          f"Made by `{command}` at {code_revision()} in {time.perf_counter() - started:.0f} s ({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}).\n",
          f"{args.levels} skill levels x {args.per_level} synthetic trainees: the scripted expert's hand log on "
          "SoftSphereHaptic-v0 (family-centre target) degraded by every error at the level's share of its worst amount "
          f"({', '.join(f'{k} {v:g}' for k, v in WORST.items())}; tremor in mm, hesitation in s per pause, lever in "
          "rad, overshoot in mm), times a factor drawn from [0.5, 1.5] per trainee and error; replayed through the "
          "laryngoscope and tongue and scored by `softenv score`'s hand-log formula:\n",
          f"> {HAND_FORMULA}\n",
          "| skill level | share of the worst errors | score: mean [95 % interval] | lowest |", "|---|---|---|---|", *rows, "",
          f"Spearman's rank correlation between skill level ({args.levels - 1} = the expert, 0 = the worst errors) and "
          f"score: **{rho:.3f}** (target: >= 0.9).\n",
          "Each error alone at its worst amount, and the part of the score it should lower (weights "
          f"{HAND_WEIGHTS}):\n", "| error | part | part: expert -> trainee | score: expert -> trainee |", "|---|---|---|---|",
          *single, "",
          f"Each error alone over its amounts ({', '.join(f'{x:g}' for x in SHARES)} of its worst), and the part it "
          "lowers: every part falls as its error grows, never rises.\n",
          "| error | part | " + " | ".join(f"{x:g}" for x in SHARES) + " |", "|---|---|" + "---|" * len(SHARES),
          *[f"| {name} | {LOWERS[name]} | " + " | ".join(f"{v:.3f}" for v in values) + " |"
            for name, values in graded.items()],
          "| lever | lever share (clinical) | " + " | ".join(f"{v:.3f}" for v in lever_share) + " |", "",
          "The lever share is the share of the hand's moment about the incisal edge applied while the blade bears on "
          "the incisors (`softenv.devices.laryngoscope.clinical`): 0 while the hand presses down along the handle; once the hand stops "
          "pressing down and turns the blade, the flange comes to bear on the teeth, the fulcrum of the lever, and "
          "the share jumps to about 1, with the incisor force that empties the teeth part.\n",
          "Against published clinical data (`softenv.training.profiles`): each profile degrades the expert's log by "
          "hesitation, overshoot and tremor until its time to target, mean tongue force and hand path are the "
          "published group's ratios to its experts' (found by bisection; what it reached beside what was asked). "
          "The scene's procedure is a 5 s reach, so absolute times and paths do not carry over; ratios do.\n",
          "| profile | published | asked: time, mean force, path | reached | errors (hesitation s, overshoot mm, "
          "tremor mm) | accuracy, speed, safety, smoothness | score |", "|---|---|---|---|---|---|---|",
          *[f"| {p.name} | {p.study} | {', '.join(f'{x:.2f}' for x in p.asked)} | "
            f"{', '.join(f'{x:.2f}' for x in p.reached)} | "
            f"{', '.join(f'{k} {v:.3g}' for k, v in p.amounts.items()) or 'none'} | "
            f"{', '.join(f'{part[k]:.2f}' for k in ('accuracy', 'speed', 'safety', 'smoothness'))} | "
            f"{part['score']:.1f} |" for p, part in built], "",
          f"Ranked in the published order (expert above intermediate above every novice): "
          f"**{'yes' if in_order else 'no'}**. Where the asked ratio was not reached, the scene cannot express "
          f"it: the device's force limit ({haptic_config(None)['device']['max_normal_force']:g} N) caps how much "
          "more a novice can press. Where the score departs from the studies: they found peak force to separate "
          "the groups only weakly, but here pressing harder costs the most, since the target is a shape and a "
          f"deeper press overshoots it: the force-only profile loses {by_name['expert'] - by_name['novice (force)']:.1f} "
          f"points, the time-only one {by_name['expert'] - by_name['novice (time)']:.1f}. "
          f"The novice's peak tongue force is "
          f"{published[-1][0].peak_N:.1f} N against the expert's {expert.peak_force_N:.1f} N (Bishop et al. 1992: "
          f"{BISHOP_1992['novice']['peak_N']:g} vs {BISHOP_1992['experienced']['peak_N']:g} N), and the expert's "
          f"own peak and mean tongue force, {expert.peak_force_N:.1f} and {expert.clinical['mean_tongue_force_N']:.1f} "
          f"N, against Bucx et al. 1992's anaesthetists ({BUCX_1992['peak_N'][0]:g} +- {BUCX_1992['peak_N'][1]:g} N "
          f"and {BUCX_1992['mean_N'][0]:g} +- {BUCX_1992['mean_N'][1]:g} N). Not expressed: force on the incisors "
          "as the studies measured it, and success rates.\n",
          "No progress, no credit: a session that leaves the tongue as it found it scores about 0, whatever its "
          "safety, teeth and smoothness (every part but accuracy counts in proportion to accuracy):\n",
          "| session | accuracy | safety | teeth | score |", "|---|---|---|---|---|",
          *[f"| {label} | {p['accuracy']:.3f} | {p['safety']:.3f} | {p['teeth']:.3f} | {p['score']:.1f} |"
            for label, p in idle], "", "Figure: `scoring_validity.png`.", ""]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    save_figure(figure(skill, scores, args.levels, rho, alone, parts["score"], graded,
                       [(p.name, score) for p, score in published], command), out / "scoring_validity.png",
                dpi=110)
    write_text(out / "scoring_validity.md", "\n".join(md))
    print("\n".join(md))


if __name__ == "__main__":
    main()
