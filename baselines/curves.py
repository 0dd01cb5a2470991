"""Learning curves: read from a training run, judged by the benchmark's stated convergence rule, and
compared across agents at equal environment steps.

The rule (issue 55): an agent's training on a scene *converged* when its seeds' mean test return rose over
the last fifth of its budget by less than the half-width of the 95 % interval over seeds of its final
return (a bootstrap over the seeds' last evaluations). A curve still rising by more than the seeds
disagree is not converged, and its budget is too small; with one seed the rule cannot be applied.

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

TAIL = 0.2                   # the last fifth of the budget: the stretch the rule looks at


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


def convergence(runs: list[Curve], tail: float = TAIL) -> dict[str, Any]:
    """The rule applied to one agent's curves on one scene (one curve a training seed): the mean final
    return with its interval over seeds, the mean rise over the last ``tail`` of the budget, and whether
    the rise is below the interval's half-width (``converged`` is None with fewer than 2 seeds)."""
    if not runs:
        raise ValueError("runs=[]: give at least one learning curve")
    if not 0 < tail < 1:
        raise ValueError(f"tail={tail}: give a share of the budget in (0, 1)")
    end = min(float(steps[-1]) for steps, _ in runs)
    finals = np.array([value_at(c, end)[0] for c in runs])
    starts = np.array([value_at(c, (1 - tail) * end)[0] for c in runs])
    mean, low, high = bootstrap_ci(finals)
    rise = float(np.mean(finals - starts))
    half = (high - low) / 2
    return {"seeds": len(runs), "budget": int(end), "final": mean, "final_low": low, "final_high": high,
            "rise": rise, "half_width": half, "converged": None if len(runs) < 2 else bool(rise < half)}


def at_equal_steps(curves: dict[str, list[Curve]]) -> tuple[int, dict[str, tuple[float, float, float]]]:
    """Every agent's curves (by agent) read at the smallest budget among them: that step count, and each
    agent's mean return there with its 95 % interval over seeds."""
    if not curves or not all(curves.values()):
        raise ValueError(f"curves={ {k: len(v) for k, v in curves.items()} }: give at least one curve for each agent")
    steps = min(int(c[0][-1]) for runs in curves.values() for c in runs)
    return steps, {agent: bootstrap_ci(np.array([value_at(c, steps)[0] for c in runs])) for agent, runs in curves.items()}


def convergence_report(curves: dict[tuple[str, str], list[Curve]],
                       walls: dict[tuple[str, str], list[float]]) -> tuple[str, list[dict[str, Any]]]:
    """The report's table of every agent's curves on the scene it trained on (keys ``(scene, agent)``): the
    rule's verdict, and the return at the smallest budget of the agents on that scene, with each seed's job
    wall time (training and evaluation). Also the rows as numbers for the JSON."""
    rows: list[dict[str, Any]] = []
    for scene in dict.fromkeys(scene for scene, _ in curves):
        agents = {agent: runs for (s, agent), runs in curves.items() if s == scene and runs}
        if not agents:
            continue
        steps, equal = at_equal_steps(agents)
        for agent, runs in agents.items():
            seconds = walls.get((scene, agent), [])
            rows.append({"scene": scene, "agent": agent, **convergence(runs), "equal_steps": steps,
                         "at_equal_steps": dict(zip(("mean", "ci_low", "ci_high"), equal[agent])),
                         "wall_s_per_seed": float(np.mean(seconds)) if seconds else float("nan")})
    verdict = {True: "yes", False: "no: still rising", None: "- (one seed)"}
    lines = ["| scene | agent | seeds | budget (env steps) | final return | rise over the last 20 % | interval half-width | "
             "converged | return at equal steps | job wall per seed (s) |", "|" + "---|" * 10]
    for r in rows:
        eq = r["at_equal_steps"]
        lines.append(f"| {r['scene']} | {r['agent']} | {r['seeds']} | {r['budget']:,} | {r['final']:.1f} "
                     f"[{r['final_low']:.1f}, {r['final_high']:.1f}] | {r['rise']:+.1f} | {r['half_width']:.1f} | "
                     f"{verdict[r['converged']]} | {eq['mean']:.1f} [{eq['ci_low']:.1f}, {eq['ci_high']:.1f}] at "
                     f"{r['equal_steps']:,} | {r['wall_s_per_seed']:.0f} |")
    return "\n".join(lines), rows
