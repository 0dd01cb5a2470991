"""What does smoothing cost and buy? Randomized smoothing's bias against the exact step, on both devices.

    python scripts/smoothing_bias.py --out results/smoothing [--cases ...] [--episodes 2] [--samples 32]
        [--line-samples 128]

The objective is a planner's: an episode's summed shape error under the plan ``tanh(z)``, through the
differentiable torch twin (softenv.smoothing; docs/gradients.md). On training-target episodes, at each
``--temperatures`` (in ``z``'s units), it measures:

* the smoothed objective ``J_T`` against the exact ``J`` (its bias, in mm x steps and relative);
* the first-order estimate of ``grad J_T`` against the exact gradient (cosine, with its relative standard
  error);
* on the line through ``z`` along the exact gradient, ``J_T``'s slope by both estimators: where they part,
  ``J`` jumps on that line within a few ``T`` and the first-order estimate misses what the jumps
  contribute (on the whole plan, a thousand entries, the zeroth-order estimate's variance would need far
  more draws than a line does);
* how far each gradient leads downhill: the exact ``J`` along the unit direction opposite the exact and
  the first-order smoothed gradient, at steps :data:`STEPS` (in ``z``'s norm), the best decrease kept.
  From the scripted expert's plan the gradient planner stalls (results/gradient-planner): is that a flat
  gradient, or a narrow valley that smoothing would widen?

Plans: the ideal device from no force (``z = 0``); the laryngoscope from the expert's plan, and from that
plan moved by noise of spread 0.5 in ``z`` (it levers on the incisors: tests/test_gradient_planner.py).
Writes ``results.json``, ``README.md`` and ``smoothing.png`` into ``--out``; one BLAS and torch thread.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from pathlib import Path
from typing import Any, Callable

import gymnasium as gym
import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import torch  # noqa: E402

from softenv._artifact import save_figure, write_text  # noqa: E402
from softenv.baselines.anchors import scene_config  # noqa: E402
from softenv.baselines.evaluate import scene_kwargs  # noqa: E402
from softenv.baselines.gradient_planner import EDGE, TRAIN, planner_warm_start  # noqa: E402
from softenv.baselines.planner import warm_start_actions  # noqa: E402
from softenv.bench import rerun_single_threaded  # noqa: E402
from softenv.bench.timing import code_revision  # noqa: E402
from softenv.envs.world import World  # noqa: E402
from softenv.smoothing import SmoothedGradient, smoothed_gradient  # noqa: E402

CASES = {                    # name: (scene, noise on the warm start's z)
    "ideal, reach from no force": ("SoftSphere-v0", 0.0),
    "laryngoscope, the expert's plan": ("SoftSphereHaptic-v0", 0.0),
    "laryngoscope, levering on the incisors": ("SoftSphereHaptic-v0", 0.5),
}
STEPS = (1e-4, 1e-3, 1e-2, 1e-1, 1.0)     # line-search steps along a unit direction in z


class Episode:
    """One training-target episode's summed shape error as a function of plans ``z`` ``(samples, H, 4)``."""

    def __init__(self, scene: str, seed: int) -> None:
        self.scene, self.seed = scene, seed
        self.envs: dict[int, Any] = {}

    def __call__(self, z: torch.Tensor) -> torch.Tensor:
        samples = z.shape[0]
        if samples not in self.envs:
            env_id, kwargs = scene_kwargs(self.scene, make=TRAIN)
            self.envs[samples] = gym.make_vec(env_id, num_envs=samples, vectorization_mode="vector_entry_point",
                                              backend="torch", differentiable=True, **kwargs)
        env = self.envs[samples]
        env.reset(seed=[self.seed] * samples)
        return sum(env.step(torch.tanh(z[:, t]))[4]["shape_error_mm"] for t in range(z.shape[1]))


def start_plans(scene: str, noise: float, seeds: list[int]) -> np.ndarray:
    """Each episode's starting ``z`` ``(n, H, 4)``: the warm start's actions held off the bounds, moved by noise."""
    _, base = warm_start_actions(planner_warm_start(World(scene_config(scene))), scene, seeds, **TRAIN)
    z = np.arctanh(np.clip(base, -EDGE, EDGE))
    return z + noise * np.random.default_rng(0).standard_normal(z.shape)


def unit(v: torch.Tensor) -> torch.Tensor:
    return v / max(float(v.norm()), 1e-300)


def cosine(a: torch.Tensor, b: torch.Tensor) -> float:
    return float((unit(a) * unit(b)).sum())


def relative_stderr(got: SmoothedGradient) -> float:
    return float(got.gradient_stderr.norm() / max(float(got.gradient.norm()), 1e-300))


def measure(episode: Callable[[torch.Tensor], torch.Tensor], z: torch.Tensor, temperatures: list[float],
            samples: int, line_samples: int, seed: int) -> dict[str, Any]:
    exact = smoothed_gradient(episode, z, 0.0, 1)
    line = unit(exact.gradient)

    def along(steps: torch.Tensor) -> torch.Tensor:     # J at z moved by each step along the exact gradient
        return episode(z + steps.reshape(-1, *([1] * z.dim())) * line)

    rows = []
    for temperature in temperatures:
        first = smoothed_gradient(episode, z, temperature, samples, "first-order",
                                  torch.Generator().manual_seed(seed))
        bias = first.value - exact.value
        row = {"temperature": temperature, "smoothed": first.value, "smoothed_stderr": first.value_stderr,
               "bias": bias, "relative_bias": bias / exact.value,
               "first_vs_exact_cosine": cosine(first.gradient, exact.gradient),
               "first_relative_stderr": relative_stderr(first),
               "first_downhill": downhill(episode, z, first.gradient, exact.value)}
        for key in ("first", "zeroth"):
            slope = smoothed_gradient(along, torch.zeros(1, dtype=z.dtype), temperature, line_samples,
                                      f"{key}-order", torch.Generator().manual_seed(seed + 1))
            row[f"along_{key}"], row[f"along_{key}_stderr"] = float(slope.gradient[0]), float(slope.gradient_stderr[0])
        rows.append(row)
    return {"exact": exact.value, "exact_gradient_norm": float(exact.gradient.norm()),
            "exact_gradient_zero_fraction": float((exact.gradient == 0).double().mean()),
            "exact_downhill": downhill(episode, z, exact.gradient, exact.value), "temperatures": rows}


def downhill(episode: Callable[[torch.Tensor], torch.Tensor], z: torch.Tensor, gradient: torch.Tensor,
             value: float) -> dict[str, Any]:
    """The exact ``J`` along the unit direction opposite ``gradient`` at :data:`STEPS`, less ``value`` (``J(z)``):
    each step's change, and the best (most negative) with its step."""
    direction = -unit(gradient)
    with torch.no_grad():
        changes = [float(j) - value for j in episode(torch.stack([z + step * direction for step in STEPS]))]
    best = int(np.argmin(changes))
    return {"changes": changes, "best_change": changes[best], "best_step": STEPS[best]}


def main() -> None:
    rerun_single_threaded()
    torch.set_num_threads(1)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--cases", nargs="+", choices=list(CASES), default=list(CASES))
    parser.add_argument("--episodes", type=int, default=2)
    parser.add_argument("--samples", type=int, default=32)
    parser.add_argument("--line-samples", type=int, default=128)
    parser.add_argument("--temperatures", type=float, nargs="+", default=[0.01, 0.03, 0.1, 0.3])
    args = parser.parse_args()
    command = "python " + " ".join(shlex.quote(a) for a in sys.argv)
    started = time.perf_counter()
    seeds = list(range(args.episodes))
    cases: dict[str, Any] = {}
    for name in args.cases:
        scene, noise = CASES[name]
        plans = start_plans(scene, noise, seeds)
        cases[name] = {"scene": scene, "noise": noise, "episodes": []}
        for seed, plan in zip(seeds, plans):
            episode, z = Episode(scene, seed), torch.as_tensor(plan)
            row = measure(episode, z, args.temperatures, args.samples, args.line_samples, seed)
            cases[name]["episodes"].append({"seed": seed, **row})
            print(f"{name}, episode {seed}: done at {time.perf_counter() - started:.0f} s", flush=True)
    made = {"command": command, "commit": code_revision(), "minutes": (time.perf_counter() - started) / 60,
            "samples": args.samples, "line_samples": args.line_samples, "steps": list(STEPS)}
    args.out.mkdir(parents=True, exist_ok=True)
    figure(cases, args.temperatures, args.out / "smoothing.png")
    write_text(args.out / "results.json", json.dumps({"made_by": made, "cases": cases}, indent=1) + "\n")
    write_text(args.out / "README.md", report(cases, made))


def figure(cases: dict[str, Any], temperatures: list[float], path: Path) -> None:
    fig, (bias, cos, slope) = plt.subplots(1, 3, figsize=(15, 4.4))
    for c, (name, case) in enumerate(cases.items()):
        for k, episode in enumerate(case["episodes"]):
            rows, norm = episode["temperatures"], episode["exact_gradient_norm"]
            label, style = (name if k == 0 else None), ("o-" if k == 0 else "s--")
            bias.plot(temperatures, [100 * r["relative_bias"] for r in rows], style, color=f"C{c}", label=label)
            cos.plot(temperatures, [r["first_vs_exact_cosine"] for r in rows], style, color=f"C{c}")
            for key, shift, marker in (("first", 0.97, "o"), ("zeroth", 1.03, "^")):
                slope.errorbar([t * shift for t in temperatures], [r[f"along_{key}"] / norm for r in rows],
                               yerr=[r[f"along_{key}_stderr"] / norm for r in rows], fmt=marker,
                               ls="-" if key == "first" else ":", color=f"C{c}", capsize=2, ms=4)
    bias.set(xscale="log", yscale="symlog", xlabel="temperature T (spread of the noise on z)",
             ylabel="bias of J_T against J (%)", title="The smoothed objective against the exact one")
    bias.axhline(0, color="0.6", lw=0.8)
    bias.legend(fontsize=8, title="episode 0 solid, 1 dashed", title_fontsize=8)
    cos.set(xscale="log", ylim=(-0.3, 1.05), xlabel="temperature T",
            ylabel="cosine", title="First-order smoothed gradient vs exact")
    slope.set(xscale="log", xlabel="temperature T", ylabel="slope over the exact slope (gradient norm)",
              title="J_T's slope along the exact gradient:\nfirst-order (o, solid), zeroth-order (^, dotted)")
    slope.axhline(1, color="0.6", lw=0.8)
    slope.text(0.02, 0.02, "bars: one standard error", transform=slope.transAxes, fontsize=8)
    fig.suptitle("randomized smoothing against the exact step -- python scripts/smoothing_bias.py", fontsize=9)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


def report(cases: dict[str, Any], made: dict[str, Any]) -> str:
    steps = ", ".join(f"{step:g}" for step in made["steps"])
    lines = ["# Randomized smoothing against the exact step", "",
             f"Made by `{made['command']}` at {made['commit']} in {made['minutes']:.1f} min (one BLAS and torch "
             f"thread, a 2-core machine). The objective: an episode's summed shape error J (mm x steps) under the "
             f"plan tanh(z), on training-target episodes; J_T its Gaussian smoothing of spread T in z "
             f"(softenv.smoothing), estimated from {made['samples']} draws. The cosine compares the first-order "
             f"estimate of grad J_T with the exact gradient over every step and action entry; its relative standard "
             f"error is the norm of the entries' standard errors over the estimate's norm. Along: the slope of J_T "
             f"along the exact gradient's unit direction (1-D smoothing on that line), first-order and zeroth-order "
             f"from {made['line_samples']} draws ({made['line_samples'] // 2} antithetic pairs), each ± its standard "
             f"error, beside the exact slope (the gradient's norm): where the two estimates part, J jumps on that "
             f"line within a few T. Downhill: the exact J along the unit direction opposite a gradient, at steps "
             f"{steps} in z's norm; the best change and its step.", "",
             "| case | episode | exact J | exact gradient: norm, zero entries | downhill, exact gradient |",
             "|---|---|---|---|---|"]
    for name, case in cases.items():
        for e in case["episodes"]:
            lines.append(f"| {name} | {e['seed']} | {e['exact']:.2f} | {e['exact_gradient_norm']:.3g}, "
                         f"{100 * e['exact_gradient_zero_fraction']:.0f} % | {_downhill(e['exact_downhill'])} |")
    lines += ["", "| case | episode | T | J_T | bias | first-order vs exact (cosine) | first-order rel. stderr | "
              "along: first-order | along: zeroth-order | downhill, first-order smoothed gradient |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for name, case in cases.items():
        for e in case["episodes"]:
            for r in e["temperatures"]:
                lines.append(
                    f"| {name} | {e['seed']} | {r['temperature']:g} | "
                    f"{r['smoothed']:.2f} ± {r['smoothed_stderr']:.2f} | "
                    f"{r['bias']:+.2f} ({100 * r['relative_bias']:+.1f} %) | {r['first_vs_exact_cosine']:.3f} | "
                    f"{r['first_relative_stderr']:.3f} | {r['along_first']:.3g} ± {r['along_first_stderr']:.2g} | "
                    f"{r['along_zeroth']:.3g} ± {r['along_zeroth_stderr']:.2g} | {_downhill(r['first_downhill'])} |")
    lines += ["", "![smoothing](smoothing.png)", ""]
    return "\n".join(lines)


def _downhill(d: dict[str, Any]) -> str:
    return f"{d['best_change']:+.3f} at {d['best_step']:g}" if d["best_change"] < 0 else "none (J rises at every step)"


if __name__ == "__main__":
    main()
