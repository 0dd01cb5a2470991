"""The laryngoscope's Warp kernel against the numba kernel it replaces (issue 62, part 1): the decision's
measurements. Writes ``results/warp-vs-numba/README.md`` and ``results.json``.

Both engines step the same devices on numpy arrays (``LaryngoscopeWarp``, ``LaryngoscopeKernel``), one
process, one CPU thread, repeats interleaved. Reported: env-steps/s at 1, 8, 64, 1,024 and 8,192 devices
and the ratio (the issue adopts Warp at 0.8x numba or better); whether every device's state after 60
control periods (pressing, levering on the incisors, random) is equal bit for bit; and what a fresh
process pays to build 8 devices and step them once: numba (no disk cache), Warp with an empty kernel
cache (it compiles) and with the cache it left.

    python scripts/warp_vs_numba.py [--quick]

Runs at the last commit that holds both kernels (the numba one was retired after it).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from softenv._artifact import write_text
from softenv.bench.timing import code_revision
from softenv.devices.laryngoscope.kernel import LaryngoscopeKernel
from softenv.devices.laryngoscope.part import laryngoscope_parts
from softenv.devices.laryngoscope.warp_kernel import LaryngoscopeWarp
from softenv.envs import HAPTIC_SCENES
from softenv.envs.config import scene_config
from softenv.envs.world import World

ENGINES = {"numba": LaryngoscopeKernel, "warp": LaryngoscopeWarp}
SIZES = (1, 8, 64, 1024, 8192)
FIRST_STEP = """
import sys, time
t0 = time.perf_counter()
import numpy as np
from softenv.devices.laryngoscope.part import laryngoscope_parts
from softenv.envs import HAPTIC_SCENES
from softenv.envs.config import scene_config
from softenv.envs.world import World
if sys.argv[1] == "warp":
    from softenv.devices.laryngoscope.warp_kernel import LaryngoscopeWarp as Engine
else:
    from softenv.devices.laryngoscope.kernel import LaryngoscopeKernel as Engine
world = World(scene_config(HAPTIC_SCENES["SoftSphereHaptic-v0"], {}))
engine = Engine(*laryngoscope_parts(world.scene, world.config), 8)
engine.control_step(np.zeros((8, 4)))
print(time.perf_counter() - t0)
"""


def parts():
    world = World(scene_config(HAPTIC_SCENES["SoftSphereHaptic-v0"], {}))
    return laryngoscope_parts(world.scene, world.config)


def actions(periods: int, n: int, seed: int = 0) -> np.ndarray:
    """Pressing into the tongue, then half the devices inserting and levering on the incisors, then random."""
    a = np.random.default_rng(seed).uniform(-1, 1, (periods, n, 4))
    third = periods // 3
    a[:third, :, 1] = np.abs(a[:third, :, 1])
    a[third:2 * third, : max(n // 2, 1)] = [1.0, 0.0, 0.0, 1.0]
    return a


def rates(seconds: float) -> dict[int, dict[str, float]]:
    """Env-steps/s of each engine at each size: 5 interleaved repeats of ``seconds`` each, medians."""
    out = {}
    for n in SIZES:
        acts = actions(48, n)
        engines = {name: cls(*parts(), n) for name, cls in ENGINES.items()}
        for e in engines.values():
            e.control_step(acts[0])                    # compiled (numba) or loaded (Warp) here
        samples: dict[str, list[float]] = {name: [] for name in engines}
        for _ in range(5):
            for name, e in engines.items():
                k, t0 = 0, time.perf_counter()
                while time.perf_counter() - t0 < seconds:
                    e.control_step(acts[k % len(acts)])
                    k += 1
                samples[name].append(k * n / (time.perf_counter() - t0))
        out[n] = {name: float(np.median(v)) for name, v in samples.items()}
        print(n, out[n], flush=True)
    return out


def agreement(n: int = 64, periods: int = 60) -> bool:
    """Whether every device's state after every period is the same on both engines, bit for bit."""
    engines = [cls(*parts(), n) for cls in ENGINES.values()]
    for a in actions(periods, n, seed=1):
        states = []
        for e in engines:
            e.control_step(a)
            states.append(e.state())
        for field in ("blade", "hand", "lateral", "contact", "hand_velocity"):
            if not np.array_equal(getattr(states[0], field), getattr(states[1], field)):
                return False
    return True


def first_steps() -> dict[str, float]:
    """Seconds a fresh process takes to import, build 8 devices and step them once."""
    def run(engine: str, cache: str) -> float:
        out = subprocess.run([sys.executable, "-c", FIRST_STEP, engine], env={**os.environ, "WARP_CACHE_PATH": cache},
                             capture_output=True, text=True, check=True).stdout
        return float(out.strip().splitlines()[-1])

    with tempfile.TemporaryDirectory() as cache:
        return {"numba (no disk cache)": run("numba", cache), "warp, empty kernel cache": run("warp", cache),
                "warp, the cache that run left": run("warp", cache)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="0.3 s a repeat, not 2 s")
    parser.add_argument("--out", type=Path, default=Path("results/warp-vs-numba"))
    args = parser.parse_args()
    command = "python scripts/warp_vs_numba.py" + (" --quick" if args.quick else "")
    measured = rates(0.3 if args.quick else 2.0)
    same = agreement()
    first = first_steps()
    ratios = {n: r["warp"] / r["numba"] for n, r in measured.items()}
    adopted = min(ratios.values()) >= 0.8 and same
    lines = ["# The laryngoscope's Warp kernel against the numba kernel", "",
             f"Made by `{command}` at commit `{code_revision()}`, one CPU thread.", "",
             "| devices | numba (env-steps/s) | Warp (env-steps/s) | Warp / numba |", "|---|---|---|---|"]
    lines += [f"| {n:,} | {r['numba']:,.0f} | {r['warp']:,.0f} | {ratios[n]:.2f} |" for n, r in measured.items()]
    lines += ["", f"Every device's state after each of 60 periods (64 devices pressing, levering on the incisors, "
              f"random): {'equal bit for bit' if same else 'NOT equal'} on the two engines.", "",
              "A fresh process importing, building 8 devices and stepping them once:", "",
              "| engine | seconds |", "|---|---|"]
    lines += [f"| {name} | {s:.2f} |" for name, s in first.items()]
    lines += ["", f"Decision (Warp at >= 0.8x numba at every size, and equal): "
              f"{'adopt Warp' if adopted else 'keep numba'} (lowest ratio {min(ratios.values()):.2f})."]
    write_text(args.out / "README.md", "\n".join(lines) + "\n")
    write_text(args.out / "results.json", json.dumps({
        "command": command, "commit": code_revision(), "rates": {str(n): r for n, r in measured.items()},
        "ratios": {str(n): r for n, r in ratios.items()}, "bit_for_bit": same, "first_step_s": first,
        "adopted": adopted}, indent=2) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
