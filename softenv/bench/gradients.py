"""Benchmark of gradients through the torch twin (``differentiable=True``): a whole episode's backward pass
against its forward step, and the memory autograd's graph holds, on both device kinds. Each case runs in
a fresh process, so that its resident memory is its own."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys

from .timing import Row, Timing

EPISODE = """
import ctypes, json, sys, time
import gymnasium as gym
import torch
import softenv

torch.set_num_threads(1)
env_id, n, steps = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])


def resident() -> int:
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) * 1024 for line in status if line.startswith("VmRSS"))


def make(differentiable):
    env = gym.make_vec(f"softenv:{env_id}", num_envs=n, vectorization_mode="vector_entry_point", backend="torch",
                       differentiable=differentiable, check_actions=False, task={"horizon": steps})
    env.reset(seed=0)
    return env


actions = torch.zeros(steps, n, 4, dtype=torch.float64)
actions[:, :, 1] = 0.5                  # the laryngoscope presses the tongue; the ideal device a mid force
plain, taped = make(False), make(True)
for a in actions[:2]:                    # first calls (kernel loads, allocator) out of the timing
    plain.step(a)
    taped.step(a.clone().requires_grad_(True))[1].sum().backward()
    taped.unwrapped.detach()             # the next step's graph must not reach back into this freed one
plain.reset(seed=0)
taped.reset(seed=0)
start = time.perf_counter()
for a in actions:
    plain.step(a)
forward = time.perf_counter() - start
a = actions.clone().requires_grad_(True)
ctypes.CDLL("libc.so.6").malloc_trim(0)  # what earlier steps freed goes back to the system, not into the graph's count
before, start = resident(), time.perf_counter()
total = sum(taped.step(x)[1].sum() for x in a)
taped_forward, held = time.perf_counter() - start, resident() - before
start = time.perf_counter()
total.backward()
backward = time.perf_counter() - start
print(json.dumps({"forward": forward, "taped_forward": taped_forward, "backward": backward, "held": held}))
"""

CASES = {  # id -> (envs, steps) full, (envs, steps) quick
    "SoftSphere-v0": ((1024, 250), (256, 50)),
    "SoftSphereHaptic-v0": ((1024, 250), (64, 50)),
}


def bench_gradients(quick: bool, reference: Timing) -> list[Row]:
    """For each device kind: an episode's backward pass over its plain forward step (issue 57's goal: at
    most 3x on the ideal device), the taped forward over the plain one, and the resident memory the graph
    holds at the episode's end."""
    if importlib.util.find_spec("torch") is None:
        return [Row("gradients", "gradients: skipped (torch is not installed)", float("nan"), "",
                    target="install softenv[rl]", ok=None)]
    rows = []
    for env_id, (full, small) in CASES.items():
        if env_id != "SoftSphere-v0" and importlib.util.find_spec("warp") is None:
            rows.append(Row("gradients", f"{env_id}: skipped (warp-lang is not installed)", float("nan"), "",
                            target="install softenv[device]", ok=None))
            continue
        n, steps = small if quick else full
        out = subprocess.run([sys.executable, "-c", EPISODE, env_id, str(n), str(steps)], capture_output=True,
                             text=True, check=True).stdout
        m = json.loads(out.strip().splitlines()[-1])
        ratio = m["backward"] / m["forward"]
        ideal = env_id == "SoftSphere-v0"
        rows.append(Row("gradients", f"{env_id}: an episode's backward pass over its forward step, {n:,} envs x "
                        f"{steps} steps", ratio, "x the forward step",
                        f"forward {m['forward']:.2f} s without the graph, {m['taped_forward']:.2f} s recording it "
                        f"({m['taped_forward'] / m['forward']:.2f}x); backward {m['backward']:.2f} s",
                        "<= 3x" if ideal else "", ratio <= 3.0 if ideal else None))
        rows.append(Row("gradients", f"{env_id}: resident memory of an episode's autograd graph, {n:,} envs x {steps} "
                        "steps", m["held"] / 1e6, "MB",
                        f"{m['held'] / (n * steps) / 1e3:.2f} KB an env-step"))
    return rows
