"""The trainee score's validity argument on every airway grade, from synthetic trainees.

    python scripts/validity.py --out results/validity [--members 30] [--retest 40] [--grades 1 2 3 4]

The sources of evidence assessment research asks for (Messick 1989; Kane 2013; Cook & Hatala 2016,
*Advances in Simulation* 1:31), each computed on SoftSphereAirway-v0 at every grade (softenv.airway):

1. **Known groups.** ``--members`` synthetic trainees of each published profile (expert, intermediate,
   novice: softenv.training.profiles, the amounts found on each grade), each member's errors drawn around
   its profile's as the skills lab's pass marks draw them (softenv.skills.passmark.group_amounts). Each
   group's mean score with a 95 % bootstrap interval; Hedges' g between the groups with its bootstrap
   interval (pingouin).
2. **Internal structure.** Spearman correlations between the score's six parts over a population of
   graded skill (softenv.training.trainee.skill_population: every error, levering included), and the
   share of their variance the first principal component of the standardised parts carries.
3. **Test-retest reliability.** ``--retest`` trainees of that population, each scored in two sessions
   whose tremor (its phase and amplitude) and hesitation are drawn afresh (each amplitude times a factor
   in [0.75, 1.25], a stated choice for day-to-day variation) while the habits of technique (levering,
   overshoot, direction) stay the trainee's own: ICC(2,1), two-way random, absolute agreement (pingouin).
4. **Relations to other variables: difficulty.** Scores, forces and the expert group's time against grade, beside Davis et al.
   2023's manikin settings (normal, restricted neck extension, restricted jaw opening, both), point by
   point in direction and, where the study gives numbers, magnitude.
5. **Consequences.** The contrasting-groups pass mark on each grade (softenv.skills.passmark.crossing of
   the expert and novice groups), its false-pass and false-fail rates counted, and what grade 1's mark
   does on the other grades.

Writes ``validity.md``, ``validity.json`` and ``validity.png`` under ``--out``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np
import pandas as pd
import pingouin as pg

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from softenv._artifact import save_figure, write_text  # noqa: E402
from softenv.airway import GRADES, grade_table  # noqa: E402
from softenv.bench.timing import code_revision  # noqa: E402
from softenv.envs import airway_scene  # noqa: E402
from softenv.skills.passmark import crossing, group_amounts, profile_amounts  # noqa: E402
from softenv.training.hand import hand_limits, haptic_config  # noqa: E402
from softenv.training.scoring import HAND_WEIGHTS, replay_hand, score_hand_log  # noqa: E402
from softenv.training.trainee import FORCE_RATE, degrade, expert_hand_log, skill_population  # noqa: E402

GROUPS = ("expert", "intermediate", "novice")
PARTS = tuple(HAND_WEIGHTS)
LBF = 4.4482216152605                      # N per pound-force
# Davis et al. 2023 (Cureus 15:e41611): the rise from the normal setting to the most restricted one
DAVIS_2023 = {"incisor": {"students": (6.95, 1.29), "residents": (5.93, 0.98), "staff": (5.94, 0.70)},
              "tongue base": {"students": (0.37, 0.18), "residents": (0.46, 0.14), "staff": (0.73, 0.15)}}
# Yu et al. 2025 (BMC Med Educ, doi:10.1186/s12909-025-07413-2): intubation time (s, mean and SD) on the manikin
# scored most difficult, and the means on the other three
YU_2025 = {"hardest": (58.84, 22.63), "others": (42.67, 48.73, 50.22)}
DAY_TO_DAY = (0.75, 1.25)                  # a session's tremor and hesitation amplitude over the trainee's own


def members(grade: int, n: int, seed: int) -> list[dict[str, Any]]:
    """Every group's ``n`` members on ``grade``: scores, parts and forces."""
    scene = airway_scene(grade)
    config = haptic_config(scene)
    log = expert_hand_log(config)
    expert = replay_hand(log, config, "the expert's log")
    rows = []
    for g, group in enumerate(GROUPS):
        for amounts, tremor_seed in group_amounts(profile_amounts(group, scene), n, seed + 100 * grade + g):
            parts, trainee, _ = score_hand_log(degrade(log, config, seed=tremor_seed, **amounts), config, group, expert)
            rows.append({"grade": grade, "group": group, **{k: parts[k] for k in (*PARTS, "score")},
                         "peak_tongue_N": trainee.clinical["peak_tongue_force_N"],
                         "peak_incisor_N": trainee.clinical["peak_incisor_force_N"],
                         "peak_jaw_N": trainee.clinical["peak_jaw_force_N"],
                         "time_to_target_s": np.nan if trainee.time_to_target_s is None else trainee.time_to_target_s})
    return rows


def retest(grade: int, n: int, seed: int) -> list[dict[str, Any]]:
    """``n`` trainees of graded skill on ``grade``, each in two sessions (see the module docstring)."""
    config = haptic_config(airway_scene(grade))
    log = expert_hand_log(config)
    expert = replay_hand(log, config, "the expert's log")
    population = skill_population(log, levels=5, per_level=max(1, n // 5), seed=seed + grade, config=config)
    rng = np.random.default_rng(seed + 1000 * grade)
    rows = []
    for trainee, (level, amounts, _) in enumerate(population):
        for session in (1, 2):
            drawn = {**amounts, "tremor": amounts["tremor"] * rng.uniform(*DAY_TO_DAY),
                     "hesitation": amounts["hesitation"] * rng.uniform(*DAY_TO_DAY)}
            parts, replay, _ = score_hand_log(degrade(log, config, seed=int(rng.integers(1 << 31)), **drawn), config,
                                              "a session", expert)
            rows.append({"grade": grade, "trainee": trainee, "level": level, "session": session,
                         **{k: parts[k] for k in (*PARTS, "score")},
                         "peak_incisor_N": replay.clinical["peak_incisor_force_N"]})
    return rows


def mean_interval(values: np.ndarray, seed: int) -> tuple[float, float, float]:
    lo, hi = pg.compute_bootci(values, func="mean", n_boot=2000, seed=seed, decimals=6)
    return float(np.mean(values)), float(lo), float(hi)


def hedges(a: np.ndarray, b: np.ndarray, seed: int) -> tuple[float, float, float]:
    g = float(pg.compute_effsize(a, b, eftype="hedges"))
    lo, hi = pg.compute_bootci(a, b, func="hedges", n_boot=2000, seed=seed, decimals=6)
    return g, float(lo), float(hi)


def analyse(known: pd.DataFrame, sessions: pd.DataFrame, seed: int) -> dict[str, Any]:
    grades = sorted(int(g) for g in known["grade"].unique())
    out: dict[str, Any] = {"known_groups": {}, "effect_sizes": {}, "pass_marks": {}, "difficulty": {}}
    for grade in grades:
        scores = {g: known[(known.grade == grade) & (known.group == g)]["score"].to_numpy() for g in GROUPS}
        out["known_groups"][grade] = {g: mean_interval(s, seed) for g, s in scores.items()}
        out["effect_sizes"][grade] = {f"{a} vs {b}": hedges(scores[a], scores[b], seed)
                                      for a, b in (("expert", "intermediate"), ("intermediate", "novice"),
                                                   ("expert", "novice"))}
        mark = crossing(scores["expert"], scores["novice"])
        out["pass_marks"][grade] = {"mark": mark, "false_pass": float(np.mean(scores["novice"] >= mark)),
                                    "false_fail": float(np.mean(scores["expert"] < mark)),
                                    "intermediate_pass": float(np.mean(scores["intermediate"] >= mark))}
        rows = known[known.grade == grade]
        out.setdefault("parts", {})[grade] = {g: {p: float(rows[rows.group == g][p].mean()) for p in PARTS}
                                              for g in GROUPS}
        pop = sessions[(sessions.grade == grade) & (sessions.session == 1)]
        out["difficulty"][grade] = {
            **{f"{g}_peak_tongue_N": float(rows[rows.group == g]["peak_tongue_N"].mean()) for g in GROUPS},
            **{f"{g}_peak_incisor_N": float(rows[rows.group == g]["peak_incisor_N"].mean()) for g in GROUPS},
            **{f"{g}_peak_jaw_N": float(rows[rows.group == g]["peak_jaw_N"].mean()) for g in GROUPS},
            **{f"{g}_time_to_target_s": float(rows[rows.group == g]["time_to_target_s"].mean()) for g in GROUPS},
            "population_peak_incisor_N": float(pop["peak_incisor_N"].mean()),
            "population_teeth_touched": float(np.mean(pop["peak_incisor_N"] > 0.0)),
            "population_score": float(pop["score"].mean())}
    first = out["pass_marks"][grades[0]]["mark"]
    for grade in grades:
        scores = {g: known[(known.grade == grade) & (known.group == g)]["score"].to_numpy() for g in GROUPS}
        out["pass_marks"][grade]["with_grade_1_mark"] = {
            "false_pass": float(np.mean(scores["novice"] >= first)), "false_fail": float(np.mean(scores["expert"] < first))}
    pop = sessions[sessions.session == 1]
    varying = [p for p in PARTS if pop[p].std() > 0]
    corr = pop[varying].corr(method="spearman")
    z = (pop[varying] - pop[varying].mean()) / pop[varying].std()
    eig = np.linalg.eigvalsh(np.cov(z.to_numpy(), rowvar=False))
    out["internal"] = {"parts": varying, "spearman": corr.round(6).to_numpy().tolist(),
                       "first_component_share": float(eig[-1] / eig.sum()),
                       "largest_off_diagonal": float(np.max(np.abs(corr.to_numpy() - np.eye(len(varying)))))}
    out["retest"] = {}
    for grade in ["all", *grades]:
        rows = sessions if grade == "all" else sessions[sessions.grade == grade]
        out["retest"][grade] = icc(rows)
    # the skill levels span expert to every error at its worst: within one level, the session's noise meets
    # only the spread of trainees of like skill (the harder test)
    out["retest_within_level"] = {int(level): icc(sessions[sessions.level == level])
                                  for level in sorted(sessions["level"].unique()) if level > 0}
    tongue = [out["difficulty"][g]["expert_peak_tongue_N"] for g in grades]
    times = [out["difficulty"][g]["expert_time_to_target_s"] for g in grades]
    out["spearman_grade"] = {
        "population_score": float(pg.corr(sessions[sessions.session == 1]["grade"], sessions[sessions.session == 1]["score"],
                                          method="spearman")["r"].iloc[0]),
        "expert_peak_tongue_N": float(pd.Series(grades).corr(pd.Series(tongue), method="spearman")),
        "expert_time_to_target_s": float(pd.Series(grades).corr(pd.Series(times), method="spearman"))}
    return out


def icc(rows: pd.DataFrame) -> dict[str, float]:
    """ICC(A,1) of the sessions' scores (Shrout & Fleiss's ICC(2,1)) with its 95 % interval (pingouin: 2 decimals)."""
    rows = rows.assign(unit=rows["grade"].astype(str) + "-" + rows["trainee"].astype(str))
    table = pg.intraclass_corr(rows, targets="unit", raters="session", ratings="score").set_index("Type")
    lo, hi = table.loc["ICC(A,1)", "CI95"]
    return {"icc": float(table.loc["ICC(A,1)", "ICC"]), "low": float(lo), "high": float(hi),
            "trainees": int(rows["unit"].nunique())}


def figure(known: pd.DataFrame, sessions: pd.DataFrame, result: dict[str, Any], command: str) -> plt.Figure:
    fig, (groups, parts, retest_ax, forces) = plt.subplots(1, 4, figsize=(19, 4.4), layout="constrained")
    grades = sorted(result["known_groups"])
    for i, g in enumerate(GROUPS):
        mean = [result["known_groups"][k][g][0] for k in grades]
        err = np.array([[m - result["known_groups"][k][g][1], result["known_groups"][k][g][2] - m]
                        for k, m in zip(grades, mean)]).T
        groups.errorbar(np.array(grades) + (i - 1) * 0.12, mean, yerr=err, fmt="o-", capsize=3, label=g)
    groups.plot(grades, [result["pass_marks"][k]["mark"] for k in grades], "k--", label="pass mark (contrasting groups)")
    groups.set_xticks(grades)
    groups.set_xlabel("airway grade")
    groups.set_ylabel("score (0-100): mean, 95 % interval")
    groups.set_title("known groups and pass marks by grade", fontsize=9)
    groups.legend(fontsize=7)
    names = result["internal"]["parts"]
    im = parts.imshow(np.array(result["internal"]["spearman"]), vmin=-1, vmax=1, cmap="coolwarm")
    parts.set_xticks(range(len(names)), names, rotation=45, fontsize=7)
    parts.set_yticks(range(len(names)), names, fontsize=7)
    fig.colorbar(im, ax=parts, shrink=0.8, label="Spearman")
    parts.set_title("internal structure: the parts' correlations", fontsize=9)
    wide = sessions.pivot_table(index=["grade", "trainee"], columns="session", values="score")
    retest_ax.scatter(wide[1], wide[2], s=10, alpha=0.6)
    retest_ax.plot([0, 100], [0, 100], "k:", lw=1)
    r = result["retest"]["all"]
    retest_ax.set_title(f"test-retest: ICC(2,1) {r['icc']:.2f} [{r['low']:.2f}, {r['high']:.2f}]", fontsize=9)
    retest_ax.set_xlabel("session 1 score")
    retest_ax.set_ylabel("session 2 score")
    d = result["difficulty"]
    forces.plot(grades, [d[k]["expert_peak_tongue_N"] for k in grades], "o-", label="expert group: peak tongue force")
    forces.plot(grades, [d[k]["novice_peak_tongue_N"] for k in grades], "s-", label="novice group: peak tongue force")
    forces.plot(grades, [d[k]["population_peak_incisor_N"] for k in grades], "^-",
                label="graded-skill population: peak incisor force")
    forces.plot(grades, [d[k]["expert_peak_jaw_N"] for k in grades], "v-", label="expert group: peak jaw force")
    forces.set_xticks(grades)
    forces.set_xlabel("airway grade")
    forces.set_ylabel("force (N)")
    forces.set_title("relations to difficulty", fontsize=9)
    forces.legend(fontsize=7)
    fig.suptitle(f"The trainee score's validity argument -- {command}", fontsize=8)
    return fig


def report(result: dict[str, Any], command: str, seconds: float, args: argparse.Namespace) -> str:
    grades = sorted(result["known_groups"])
    d, kg, es, pm = result["difficulty"], result["known_groups"], result["effect_sizes"], result["pass_marks"]
    first, last = grades[0], grades[-1]
    fmt = lambda t: f"{t[0]:.1f} [{t[1]:.1f}, {t[2]:.1f}]"  # noqa: E731
    fmt3 = lambda t: f"{t[0]:.2f} [{t[1]:.2f}, {t[2]:.2f}]"  # noqa: E731
    names = result["internal"]["parts"]
    corr = np.array(result["internal"]["spearman"])
    rt = result["retest"]
    rise = {k: d[last][f"{k}"] - d[first][f"{k}"] for k in ("expert_peak_tongue_N", "novice_peak_tongue_N",
                                                             "population_peak_incisor_N", "expert_peak_jaw_N",
                                                             "expert_time_to_target_s")}
    slower = d[last]["expert_time_to_target_s"] / d[first]["expert_time_to_target_s"]
    davis = lambda kind, who: DAVIS_2023[kind][who][0] * LBF  # noqa: E731
    lines = [
        "# The trainee score's validity argument across airway grades\n",
        f"Made by `{command}` at {code_revision()} in {seconds:.0f} s ({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}). "
        f"SoftSphereAirway-v0 at grades {', '.join(map(str, grades))} (`softenv.airway`); {args.members} synthetic members "
        f"per group and grade; {rt['all']['trainees']} trainees in two sessions each for test-retest. The frame: "
        "Messick's sources of evidence, Kane's argument (Cook & Hatala 2016, Advances in Simulation 1:31). Every "
        "trainee is synthetic: read each claim below as what the score does on the simulator's trainees, not yet on "
        "people (the last section).\n",
        grade_table(), "",
        "## 1. Known groups\n",
        "Each group's members draw their errors around the published profile's amounts on that grade "
        "(`softenv.skills.passmark.group_amounts`: each amount times a factor in [0.5, 1.5], plus a small tremor "
        "and hesitation anyone shows). Mean score with its 95 % bootstrap interval; Hedges' g between the groups "
        "with its 95 % bootstrap interval.\n",
        "| grade | expert | intermediate | novice | g: expert vs intermediate | g: intermediate vs novice | "
        "g: expert vs novice |", "|---|---|---|---|---|---|---|",
        *[f"| {k} | {fmt(kg[k]['expert'])} | {fmt(kg[k]['intermediate'])} | {fmt(kg[k]['novice'])} | "
          f"{fmt3(es[k]['expert vs intermediate'])} | {fmt3(es[k]['intermediate vs novice'])} | "
          f"{fmt3(es[k]['expert vs novice'])} |" for k in grades], "",
        "## 2. Internal structure\n",
        f"Spearman correlations between the parts over the graded-skill population's first sessions (every grade, "
        f"{len(names)} parts that vary: {', '.join(names)}). Parts that measure distinct things correlate weakly; "
        f"a part that copies another (|rho| near 1) adds nothing. Largest |rho| between two parts: "
        f"**{result['internal']['largest_off_diagonal']:.2f}**; the first principal component of the standardised "
        f"parts carries {result['internal']['first_component_share']:.0%} of their variance (one common factor, "
        "skill, and part-specific errors).\n",
        "| | " + " | ".join(names) + " |", "|---|" + "---|" * len(names),
        *[f"| {a} | " + " | ".join(f"{v:.2f}" for v in row) + " |" for a, row in zip(names, corr)], "",
        "## 3. Test-retest reliability\n",
        "The same trainee twice: tremor (phase and amplitude) and hesitation drawn afresh each session (amplitudes "
        f"times a factor in [{DAY_TO_DAY[0]:g}, {DAY_TO_DAY[1]:g}]), technique habits (levering, overshoot, direction) "
        "kept. ICC(2,1): two-way random effects, absolute agreement, single session (pingouin), with its 95 % "
        "interval.\n",
        "| grade | trainees | ICC(2,1) [95 %] |", "|---|---|---|",
        *[f"| {k} | {rt[k]['trainees']} | {rt[k]['icc']:.2f} [{rt[k]['low']:.2f}, {rt[k]['high']:.2f}] |"
          for k in [*grades, "all"]], "",
        "Across skill levels the trainees differ far more than a trainee's two sessions do. Within one level "
        "(trainees of like skill, every grade), the harder test:\n",
        "| skill level (errors at this share of their worst) | trainees | ICC(2,1) [95 %] |", "|---|---|---|",
        *[f"| {level / 4:.2f} | {r['trainees']} | {r['icc']:.2f} [{r['low']:.2f}, {r['high']:.2f}] |"
          for level, r in result["retest_within_level"].items()], "",
        "## 4. Relations to difficulty\n",
        "Means over each group's members (first sessions for the population; times over the members who reach "
        "the target). Peak forces in N.\n",
        "| grade | expert group: peak tongue | novice group: peak tongue (over the expert group's) | expert group: "
        "peak incisor | expert group: peak jaw (lower incisors) | expert group: time to target (s) | population: "
        "peak incisor | population: teeth touched | population: score | expert group: score |",
        "|---|---|---|---|---|---|---|---|---|---|",
        *[f"| {k} | {d[k]['expert_peak_tongue_N']:.1f} | {d[k]['novice_peak_tongue_N']:.1f} "
          f"({d[k]['novice_peak_tongue_N'] / d[k]['expert_peak_tongue_N']:.2f}) | "
          f"{d[k]['expert_peak_incisor_N']:.1f} | {d[k]['expert_peak_jaw_N']:.1f} | {d[k]['expert_time_to_target_s']:.2f} | "
          f"{d[k]['population_peak_incisor_N']:.1f} | "
          f"{d[k]['population_teeth_touched']:.0%} | {d[k]['population_score']:.1f} | {kg[k]['expert'][0]:.1f} |"
          for k in grades], "",
        f"Spearman's rho between grade and the population's score: {result['spearman_grade']['population_score']:.2f}; "
        f"between grade and the expert group's peak tongue force: {result['spearman_grade']['expert_peak_tongue_N']:.2f}; "
        f"between grade and the expert group's time to target: {result['spearman_grade']['expert_time_to_target_s']:.2f}.\n",
        f"Against Davis et al. 2023 (difficult-airway manikin, Miller 3; settings 1 normal, 2 restricted neck "
        "extension, 3 restricted jaw opening, 4 both; the rise from setting 1 to setting 4, mean (SE)), point by "
        f"point with grade {first} to grade {last} here:\n",
        "| measure | Davis et al. 2023: students, residents, staff | here | direction |", "|---|---|---|---|",
        f"| tongue(-base) force | +{davis('tongue base', 'students'):.1f}, +{davis('tongue base', 'residents'):.1f}, "
        f"+{davis('tongue base', 'staff'):.1f} N (0.37, 0.46, 0.73 lbf) | expert group +{rise['expert_peak_tongue_N']:.1f} N, "
        f"novice group +{rise['novice_peak_tongue_N']:.1f} N (the whole lift, not a tongue-base gauge) | "
        f"{'rises, as published' if rise['expert_peak_tongue_N'] > 0 else '**does not rise**'} |",
        f"| incisor force | +{davis('incisor', 'students'):.1f}, +{davis('incisor', 'residents'):.1f}, "
        f"+{davis('incisor', 'staff'):.1f} N (6.95, 5.93, 5.94 lbf) | expert group: upper incisors +"
        f"{d[last]['expert_peak_incisor_N'] - d[first]['expert_peak_incisor_N']:.1f} N, lower incisors (the jaw) "
        f"+{rise['expert_peak_jaw_N']:.1f} N; graded-skill population: upper +{rise['population_peak_incisor_N']:.1f} N | "
        f"{'rises on the lower incisors for every group, on the upper only for the trainees who lever' if rise['expert_peak_jaw_N'] > 0 and rise['population_peak_incisor_N'] > 0 else '**does not rise**'} |",
        "",
        f"Time, against Yu et al. 2025 (BMC Med Educ, doi:10.1186/s12909-025-07413-2; 19 trainees on four manikins): "
        f"intubation took longest on the manikin scored most difficult, {YU_2025['hardest'][0]:g} +/- "
        f"{YU_2025['hardest'][1]:g} s against {min(YU_2025['others']):g}-{max(YU_2025['others']):g} s on the other "
        f"three ({YU_2025['hardest'][0] / min(YU_2025['others']):.2f} times the quickest). Here the expert group's "
        f"time to target goes {d[first]['expert_time_to_target_s']:.2f} -> {d[last]['expert_time_to_target_s']:.2f} s "
        f"from grade {first} to grade {last} ({slower:.2f} times): "
        f"{'rises, as published' if rise['expert_time_to_target_s'] > 0 else '**does not rise**'}. Only the lift is "
        "timed (insertion to the target's shape; no tube is passed), and it rises because the expert's lift builds "
        f"force at a bounded rate ({FORCE_RATE:g} N/s, `softenv.training.trainee.FORCE_RATE`) and a harder grade needs "
        "more force.\n",
        f"From grade {first} to grade {last} the mean score "
        + "; ".join(f"of the {g} group goes {kg[first][g][0]:.1f} -> {kg[last][g][0]:.1f} "
                    f"({'falls' if kg[last][g][0] < kg[first][g][0] else 'does not fall'})" for g in GROUPS)
        + f"; of the graded-skill population {d[first]['population_score']:.1f} -> {d[last]['population_score']:.1f}. "
        "What moves them: speed, smoothness and view are measured against the grade's own expert, so they do not "
        "fall by themselves; safety is absolute (a harder airway needs more force, above the safe limit); the teeth "
        "sit closer over the blade, so levering costs the teeth part sooner; and each profile is rebuilt on each "
        "grade to the published ratios to that grade's expert, as far as the hand's workspace lets a novice press "
        "harder than that expert: its floor (a level blade above the tongue's centre, "
        f"{-1e3 * hand_limits(haptic_config(airway_scene(last)))['hand_z_m'][0]:g} mm below the start) stops the "
        "novice's overshoot on every grade, and on a harder airway the expert's own press lies nearer that floor, so "
        "the novice overshoots less (the ratio of peak tongue forces above); where the airway has lower incisors, "
        "they take a harder press than the expert's (the jaw, not the tongue, is squeezed), and the teeth part, not "
        "safety, pays for it. The parts, group by group (means):\n",
        "| grade | group | " + " | ".join(PARTS) + " |", "|---|---|" + "---|" * len(PARTS),
        *[f"| {k} | {g} | " + " | ".join(f"{result['parts'][k][g][p]:.2f}" for p in PARTS) + " |"
          for k in grades for g in GROUPS], "",
        "## 5. Consequences of a pass mark\n",
        "Contrasting groups on each grade (the expert and the novice group: where their fitted normal densities "
        "cross); the false-pass rate (novices at or above the mark) and false-fail rate (experts below it), counted; "
        "the intermediate group's pass rate; and grade 1's mark applied to every grade, as a lab that ignored the "
        "airway would.\n",
        "| grade | mark | false pass | false fail | intermediate pass | grade 1's mark: false pass | grade 1's mark: "
        "false fail |", "|---|---|---|---|---|---|---|",
        *[f"| {k} | {pm[k]['mark']:.1f} | {pm[k]['false_pass']:.0%} | {pm[k]['false_fail']:.0%} | "
          f"{pm[k]['intermediate_pass']:.0%} | {pm[k]['with_grade_1_mark']['false_pass']:.0%} | "
          f"{pm[k]['with_grade_1_mark']['false_fail']:.0%} |" for k in grades], "",
        "## What synthetic trainees cannot show\n",
        "- **The groups are made, not sampled.** Each profile degrades the scripted expert by the errors the "
        "score's parts were built to see; that the score separates them shows the parts respond to those errors "
        "(a check of the construction), not that real novices make them. A study would recruit laryngoscopists "
        "of known experience, record them on the device, and compare their scores.\n",
        "- **The spread within a group is a stated choice** (amounts times 0.5-1.5; day-to-day factors "
        f"{DAY_TO_DAY[0]:g}-{DAY_TO_DAY[1]:g}): effect sizes, ICC and false-pass rates scale with it. Real test-retest needs "
        "the same people on two days.\n",
        "- **The expert never loads the upper incisors.** Davis et al. found staff loading the incisors 26 N more "
        "at the most restricted setting. Here the expert's lift presses the lower incisors on the restricted mouth "
        "openings (the expert group's peak jaw force above), but its upper-incisor force is 0 on every grade: the "
        "view fixes the blade's pitch, and at the family's centre no press that reaches the view brings the flange up "
        "into the upper teeth (docs/airways.md). The rise on the upper teeth appears only in trainees who lever, "
        "whose teeth part falls; the lower incisors cost the teeth part only beyond the grade's expert's force.\n",
        "- **Relations to other variables** beyond difficulty (global rating scales, checklists, success and "
        "time on patients) need real trainees scored both ways.\n",
        "- **Consequences** here are rates among synthetic groups; the real ones (who is held back, who is "
        "passed and then struggles) need outcome data.\n",
        "Figure: `validity.png`.", ""]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="results/validity")
    parser.add_argument("--members", type=int, default=30, help="members per group and grade")
    parser.add_argument("--retest", type=int, default=40, help="trainees per grade in two sessions (a multiple of 5)")
    parser.add_argument("--grades", type=int, nargs="+", default=list(GRADES), choices=list(GRADES))
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    started = time.perf_counter()
    known = pd.DataFrame([row for grade in args.grades for row in members(grade, args.members, args.seed)])
    sessions = pd.DataFrame([row for grade in args.grades for row in retest(grade, args.retest, args.seed)])
    result = analyse(known, sessions, args.seed)
    command = "python " + " ".join(sys.argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    text = report(result, command, time.perf_counter() - started, args)
    write_text(out / "validity.json", json.dumps({"command": command, "commit": code_revision(), **result}, indent=1,
                                                 default=float) + "\n")
    save_figure(figure(known, sessions, result, command), out / "validity.png", dpi=110)
    write_text(out / "validity.md", text)
    print(text)


if __name__ == "__main__":
    main()
