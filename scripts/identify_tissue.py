"""Tissue identification from device logs: sessions made with known tongue and coupling parameters, with
tremor and sensor noise, and what softenv.training.identify recovers from them.

    python scripts/identify_tissue.py --out results/identification [--seeds 2] [--iterations 150]

Each session is the scripted expert's hand log on SoftSphereHaptic-v0 (3 s) with a tremor of 0.5 mm drawn
afresh (softenv.training.trainee.degrade), replayed on the scene with the true factors (on the tongue's
stiffness and the coupling's stiffness; the coupling's damping stays 1 and is fitted too), the sensors
read with Gaussian noise: the tongue's force (0.3 N, a load cell's) and the blade's height (0.1 mm, a
tracked marker's). Two set-ups are fitted from the same sessions: the force alone, and the force with the
blade's height. Each fit starts from the scene's own values (factors 1). Reported: each parameter's
recovered against true value with its 95 % Laplace interval, how often the intervals hold the truth, the
errors' correlations and the pairs a set-up cannot separate.

The truth is made by the model that fits it (the same simulator, the same step): the noise and the
tremor are the only differences, so this shows what the sensors can determine and how well the
optimiser finds it, not how the model would fare on a real tongue.

Writes ``README.md`` and ``identification.json`` under ``--out``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from itertools import product
from pathlib import Path
from typing import Any

import numpy as np

from softenv._artifact import write_text
from softenv.bench.timing import code_revision
from softenv.training.hand import haptic_config
from softenv.training.identify import PARAMETERS, identify, log_actions, simulate_sessions
from softenv.training.trainee import degrade, expert_hand_log

TONGUE, COUPLING = (0.8, 1.0, 1.25), (0.8, 1.25)          # the true factors, every pair
NOISE = {"tongue_force_N": 0.3, "blade_z_mm": 0.1}
SETUPS = {"force alone": ("tongue_force_N",), "force and blade height": ("tongue_force_N", "blade_z_mm")}
TREMOR_MM, DURATION_S = 0.5, 3.0


def sessions(seeds: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Every session's replay actions ``(K, n, 4)`` and true factors (name -> ``(n,)``)."""
    config = haptic_config(None)
    log = expert_hand_log(config, duration_s=DURATION_S)
    actions, truth = [], {name: [] for name in PARAMETERS}
    pairs = [pair for _ in range(seeds) for pair in product(TONGUE, COUPLING)]
    for s, (tongue, coupling) in enumerate(pairs):
        actions.append(log_actions(degrade(log, config, tremor=TREMOR_MM, seed=s), config))
        for name, value in zip(PARAMETERS, (tongue, coupling, 1.0)):
            truth[name].append(value)
    return np.stack(actions, axis=1), {k: np.array(v) for k, v in truth.items()}


def fit(actions: np.ndarray, truth: dict[str, np.ndarray], channels: tuple[str, ...], iterations: int,
        seed: int) -> dict[str, Any]:
    config = haptic_config(None)
    noise = [NOISE[c] for c in channels]
    measured = simulate_sessions(actions, truth, config, channels=channels, noise=noise, seed=seed)
    started = time.perf_counter()
    result = identify(actions, measured, noise, config, channels=channels, iterations=iterations)
    out: dict[str, Any] = {"channels": list(channels), "noise": noise, "seconds": time.perf_counter() - started,
                           "loss": [result.losses[0], result.losses[-1]],
                           "normalised_rms": result.normalised_rms.tolist(),
                           "median_correlation": np.median(result.correlation, axis=0).tolist(),
                           "confounded": result.confounded(), "parameters": {}}
    for name in PARAMETERS:
        value, low, high, true = result.values[name], result.low[name], result.high[name], truth[name]
        out["parameters"][name] = {
            "true": true.tolist(), "recovered": value.tolist(), "low": low.tolist(), "high": high.tolist(),
            "relative_error_median": float(np.median(np.abs(value / true - 1.0))),
            "relative_error_max": float(np.max(np.abs(value / true - 1.0))),
            "coverage": float(np.mean((low <= true) & (true <= high))),
            "interval_ratio_median": float(np.median(high / low))}
    return out


def report(result: dict[str, Any], command: str, seconds: float, sessions_n: int) -> str:
    lines = ["# Tissue identification from device logs\n",
             f"Made by `{command}` at {code_revision()} in {seconds / 60:.1f} min. {sessions_n} sessions on "
             f"SoftSphereHaptic-v0: the scripted expert's {DURATION_S:g} s hand log with a {TREMOR_MM:g} mm tremor "
             f"drawn afresh, true factors on the tongue's stiffness {list(TONGUE)} and on the coupling's stiffness "
             f"{list(COUPLING)} (every pair), the coupling's damping 1; sensor noise "
             f"{NOISE['tongue_force_N']:g} N on the tongue's force and {NOISE['blade_z_mm']:g} mm on the blade's "
             "height. Each fit (`softenv.training.identify.identify`) starts from the scene's values and fits all "
             "three factors. The truth comes from the model that fits it (only noise and tremor differ): this "
             "shows what the sensors determine, not how the model fares on a real tongue.\n",
             "| set-up | parameter | median relative error | largest | 95 % intervals holding the truth | "
             "median interval (high / low) |", "|---|---|---|---|---|---|"]
    for setup, r in result["setups"].items():
        for name, p in r["parameters"].items():
            lines.append(f"| {setup} | {name} | {100 * p['relative_error_median']:.2f} % | "
                         f"{100 * p['relative_error_max']:.2f} % | {100 * p['coverage']:.0f} % | "
                         f"{p['interval_ratio_median']:.3g} |")
    lines.append("")
    for setup, r in result["setups"].items():
        pairs = "; ".join(f"{a} and {b} (correlation {rho:.3f})" for a, b, rho in r["confounded"]) or "none"
        corr = np.array(r["median_correlation"])
        lines += [f"**{setup}** ({r['seconds']:.0f} s; the residuals' RMS over the noise, median "
                  f"{np.median(r['normalised_rms']):.2f}). Pairs it cannot separate (|correlation| > 0.95 in the "
                  f"median session): {pairs}. The errors' median correlations:\n",
                  "| | " + " | ".join(PARAMETERS) + " |", "|---|" + "---|" * len(PARAMETERS),
                  *[f"| {a} | " + " | ".join(f"{corr[i, j]:.3f}" for j in range(len(PARAMETERS))) + " |"
                    for i, a in enumerate(PARAMETERS)], ""]
    lines += ["Per session (true, then recovered with its 95 % interval):\n",
              "| session | set-up | " + " | ".join(PARAMETERS) + " |", "|---|---|" + "---|" * len(PARAMETERS)]
    for setup, r in result["setups"].items():
        params = r["parameters"]
        for i in range(sessions_n):
            cells = [f"{p['true'][i]:g}: {p['recovered'][i]:.3f} [{p['low'][i]:.3g}, {p['high'][i]:.3g}]"
                     for p in params.values()]
            lines.append(f"| {i} | {setup} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="results/identification")
    parser.add_argument("--seeds", type=int, default=2, help="tremor draws per pair of true factors")
    parser.add_argument("--iterations", type=int, default=150)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    started = time.perf_counter()
    actions, truth = sessions(args.seeds)
    result = {"command": "python " + " ".join(sys.argv), "commit": code_revision(),
              "setups": {name: fit(actions, truth, channels, args.iterations, args.seed)
                         for name, channels in SETUPS.items()}}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    text = report(result, result["command"], time.perf_counter() - started, actions.shape[1])
    write_text(out / "identification.json", json.dumps(result, indent=1, default=float) + "\n")
    write_text(out / "README.md", text)
    print(text)


if __name__ == "__main__":
    main()
