"""Learning curves: read from a training run, judged by the benchmark's stated convergence rule, and
compared across agents at equal environment steps.

The rule (issue 55), :data:`RULE` in words: each seed's trend is the least-squares line through its
evaluations over the last half of the budget; from it, the gain a further fifth of the budget would add,
and the gain training made so far (the line at the end minus the first evaluation). An agent's training
on a scene *converged* when the upper end of the 95 % interval over seeds of the further gain is below
5 % of the seeds' mean gain so far. Each seed is paired with itself, so seeds that level off far apart
(one stuck, one good) do not widen the tolerance; the trend reads five or more evaluations, not two; and
the verdict needs the plateau shown, not merely not refuted. With one seed there is no interval.

Equal steps: off-policy agents (SAC, TD3) train on 27-40 times fewer env steps than PPO, so a table of
their final scores compares budgets as much as methods. Each curve read at the smallest budget of the
agents on a scene compares them at the same experience.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from softenv.stats import bootstrap_ci

Curve = tuple[np.ndarray, np.ndarray]        # env steps, mean test-target return at each evaluation

TREND = 0.5                  # the last half of the budget: the stretch whose trend the rule reads
AHEAD = 0.2                  # a further fifth of the budget: the gain the rule projects
TOLERANCE = 0.05             # of the gain so far: the further gain a plateau may still show
def _share(fraction: float) -> str:
    return f"{100 * fraction:g} %"


RULE = (f"converged when, by each seed's least-squares trend over the last {_share(TREND)} of the budget, a further "
        f"{_share(AHEAD)} of the budget would add less than {_share(TOLERANCE)} of what training gained so far (the "
        "trend's end minus the first evaluation), at the upper end of the 95 % interval over seeds")
RISING = f"a seed is still rising when its own further gain is above {_share(TOLERANCE)} of its own gain so far"


def learning_curve(run_dir: Path) -> Curve | None:
    """An SB3 run's learning curve: test-target return against env steps (its EvalCallback's log)."""
    log = run_dir / "eval" / "evaluations.npz"
    if not log.exists():
        return None
    with np.load(log, allow_pickle=False) as data:
        return data["timesteps"], data["results"].mean(axis=1)


def value_at(curve: Curve, steps: float) -> tuple[float, int]:
    """The curve's last evaluation at or before ``steps`` env steps: (its return, its step count)."""
    at, values = curve
    i = int(np.searchsorted(at, steps, side="right")) - 1
    if i < 0:
        raise ValueError(f"steps={steps}: the curve's first evaluation is at {int(at[0])} env steps; ask at or after it")
    return float(values[i]), int(at[i])


def _trend(curve: Curve, end: float) -> tuple[float, float]:
    """One seed's (further gain, gain so far) by its line over the last :data:`TREND` of ``end`` env steps."""
    steps, values = curve
    window = (steps >= (1 - TREND) * end) & (steps <= end)
    if window.sum() < 2:
        return float("nan"), float("nan")
    slope, intercept = np.polyfit(steps[window] / end, values[window], 1)
    return float(slope * AHEAD), float(slope + intercept - values[0])


def convergence(runs: list[Curve]) -> dict[str, Any]:
    """The rule applied to one agent's curves on one scene (one curve a training seed): the mean final
    return with its interval over seeds, the mean further gain with its interval, the tolerance, how many
    seeds are still rising by their own gain, and the verdict (``converged`` is None with fewer than 2
    seeds or fewer than 2 evaluations in a seed's last half)."""
    if not runs:
        raise ValueError("runs=[]: give at least one learning curve")
    end = min(float(steps[-1]) for steps, _ in runs)
    finals = np.array([value_at(c, end)[0] for c in runs])
    ahead, gained = np.array([_trend(c, end) for c in runs]).T
    mean, low, high = bootstrap_ci(finals)
    judged = len(runs) >= 2 and bool(np.isfinite(ahead).all())
    ahead_mean, ahead_low, ahead_high = bootstrap_ci(ahead) if judged else (float(np.mean(ahead)), float("nan"), float("nan"))
    tolerance = TOLERANCE * abs(float(np.mean(gained)))
    return {"seeds": len(runs), "budget": int(end), "final": mean, "final_low": low, "final_high": high,
            "ahead": ahead_mean, "ahead_low": ahead_low, "ahead_high": ahead_high, "tolerance": tolerance,
            "still_rising": int(np.sum(ahead > TOLERANCE * np.abs(gained))),
            "converged": bool(ahead_high < tolerance) if judged else None}


def at_equal_steps(curves: dict[str, list[Curve]]) -> tuple[int, dict[str, tuple[float, float, float]]]:
    """Every agent's curves (by agent) read at the smallest budget among them: that step count, and each
    agent's mean return there with its 95 % interval over seeds."""
    if not curves or not all(curves.values()):
        raise ValueError(f"curves={ {k: len(v) for k, v in curves.items()} }: give at least one curve for each agent")
    steps = min(int(c[0][-1]) for runs in curves.values() for c in runs)
    return steps, {agent: bootstrap_ci(np.array([value_at(c, steps)[0] for c in runs])) for agent, runs in curves.items()}


def convergence_report(curves: dict[tuple[str, str], list[Curve]],
                       trainings: dict[tuple[str, str], list[float | None]]) -> tuple[str, list[dict[str, Any]]]:
    """The report's table of every agent's curves on the scene it trained on (keys ``(scene, agent)``): the
    rule's verdict, and the return at the smallest budget of the agents on that scene, with the seeds' mean
    training wall time as their runs recorded it (``trainings``: a seed's seconds, None where its run did
    not record them). Also the rows as numbers for the JSON."""
    rows: list[dict[str, Any]] = []
    for scene in dict.fromkeys(scene for scene, _ in curves):
        agents = {agent: runs for (s, agent), runs in curves.items() if s == scene and runs}
        if not agents:
            continue
        steps, equal = at_equal_steps(agents)
        for agent, runs in agents.items():
            seconds = [s for s in trainings.get((scene, agent), []) if s is not None]
            rows.append({"scene": scene, "agent": agent, **convergence(runs), "equal_steps": steps,
                         "at_equal_steps": dict(zip(("mean", "ci_low", "ci_high"), equal[agent])),
                         "train_s_per_seed": float(np.mean(seconds)) if seconds else float("nan"),
                         "train_s_recorded": len(seconds)})
    verdict = {True: "yes", False: "no", None: "- (one seed, or under 2 evaluations in the last half)"}
    lines = [f"| scene | agent | seeds | budget (env steps) | final return | gain a further {_share(AHEAD)} would add | "
             f"tolerance ({_share(TOLERANCE)} of the gain so far) | seeds still rising | converged | "
             "return at equal steps | training minutes per seed |", "|" + "---|" * 11]
    for r in rows:
        eq = r["at_equal_steps"]
        lines.append(f"| {r['scene']} | {r['agent']} | {r['seeds']} | {r['budget']:,} | {r['final']:.1f} "
                     f"[{r['final_low']:.1f}, {r['final_high']:.1f}] | {r['ahead']:+.1f} [{r['ahead_low']:+.1f}, "
                     f"{r['ahead_high']:+.1f}] | {r['tolerance']:.1f} | {r['still_rising']} of {r['seeds']} | "
                     f"{verdict[r['converged']]} | {eq['mean']:.1f} [{eq['ci_low']:.1f}, {eq['ci_high']:.1f}] at "
                     f"{r['equal_steps']:,} | {_minutes(r)} |")
    return "\n".join(lines), rows


def _minutes(row: dict[str, Any]) -> str:
    """A row's mean training minutes per seed; the count when only some seeds' runs recorded theirs."""
    if not row["train_s_recorded"]:
        return "-"
    mean = f"{row['train_s_per_seed'] / 60:.1f}"
    return mean if row["train_s_recorded"] == row["seeds"] else f"{mean} ({row['train_s_recorded']} of {row['seeds']} seeds)"
