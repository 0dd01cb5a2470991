"""Benchmarks of the simulated laryngoscope: the 1 kHz haptic tick, the single env against real time
and CartPole-v1, the batched twin's throughput and memory per env, and the stiff and extreme cases
(substeps, worst incisor overlap, deepest penetration, energy without input)."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import tempfile
import time

import gymnasium as gym
import numpy as np

from ..devices.laryngoscope.state import COLLISION_SLOP
from ..envs import HAPTIC_SCENES
from ..envs.config import scene_config
from ..envs.world import World
from .env import state_bytes_per_env, twin_step_timing
from .timing import Row, Timing, gym_step_timing, measure, measure_each, spread_us

ENV_ID = "SoftSphereHaptic-v0"


def press_actions(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """Random actions that press rather than lift (``press >= 0``): the tongue in contact most of the time."""
    a = rng.uniform(-1, 1, shape).astype(np.float32)
    a[..., 1] = np.abs(a[..., 1])
    return a


def bench_haptic(quick: bool, reference: Timing) -> list[Row]:
    from ..haptics.loop import HapticLoop     # imports pymunk: only when this section runs

    rows: list[Row] = []
    loop = HapticLoop()
    start = loop.hand_pose
    state = {"tick": 0}

    def press_tick() -> None:                 # the hand presses 3 cm down over 1 s, then holds
        state["tick"] += 1
        loop.tick(start - [0.0, 0.03 * min(state["tick"], 1000) / 1000, 0.0, 0.0])

    t = measure_each(press_tick, calls=5000 if quick else 20000)
    rows.append(Row("haptic", "1 kHz haptic tick (HapticLoop.tick: physics substeps, tongue contact, force out)",
                    t.p99 * 1e6, "us (p99)", f"median {t.median * 1e6:.1f} us, {loop.device.n_substeps} substeps",
                    "p99 <= 100 us", t.p99 <= 100e-6))
    cart = 1.0 / reference.median
    rng = np.random.default_rng(0)
    steps = 1000 if quick else 5000
    action_sets = (("random actions", rng.uniform(-1, 1, (4096, 4)).astype(np.float32)),
                   ("pressing actions", press_actions(rng, (4096, 4))))
    for env_id in HAPTIC_SCENES:
        dt = gym.make(env_id).get_wrapper_attr("world").config["dynamics"]["dt"]
        for label, actions in action_sets:
            env = gym.make(env_id)
            t = gym_step_timing(env, list(actions), steps)
            realtime = dt / t.median
            rows.append(Row("haptic", f"{env_id}: single env, simulated s per wall s ({label}, resets included)",
                            realtime, "x real time", f"{1 / t.median:,.0f} steps/s = {1 / t.median / cart:.3f} x "
                            f"CartPole-v1; IQR {dt / t.p75:.0f}-{dt / t.p25:.0f}x", ">= 100x", realtime >= 100))
    env = gym.make(ENV_ID)
    r = measure(lambda: env.reset(), number=50 if quick else 200, repeats=5)
    rows.append(Row("haptic", f"{ENV_ID}: reset", r.median * 1e6, "us", spread_us(r)))
    rows += first_step_rows()
    rows += batch_rows(quick, cart, rng)
    for env_id in HAPTIC_SCENES:
        per_env = state_bytes_per_env(env_id, 256)
        rows.append(Row("haptic", f"{env_id}: batched twin state per env (default engine, numpy arrays: traced "
                        "allocations, 256 envs)", per_env / 1e3, "KB",
                        target="<= 200 KB", ok=per_env <= 200e3))
    rows += extreme_rows(quick)
    return rows


# a fresh process making, resetting and stepping a batch of 8 haptic envs; prints its wall seconds
FIRST_STEP = """
import time
t0 = time.perf_counter()
import gymnasium as gym
env = gym.make_vec("softenv:SoftSphereHaptic-v0", num_envs=8, vectorization_mode="vector_entry_point")
env.reset(seed=0)
env.step(env.action_space.sample())
print(time.perf_counter() - t0)
"""


def first_step_rows() -> list[Row]:
    """What a new process pays before its first batched step: with an empty kernel cache (cold: Warp
    compiles the laryngoscope's kernel) and again with the cache that run left (warm: it loads it)."""
    rows = []
    with tempfile.TemporaryDirectory() as cache:
        for label in ("cold", "warm"):
            out = subprocess.run([sys.executable, "-c", FIRST_STEP], env={**os.environ, "WARP_CACHE_PATH": cache},
                                 capture_output=True, text=True, check=True).stdout
            seconds = float(out.strip().splitlines()[-1])
            warm = label == "warm"
            rows.append(Row("haptic", f"{ENV_ID}: a fresh process's make_vec (8 envs), reset and first step, "
                            f"{label} kernel cache", seconds, "s", "imports included",
                            "< 2 s" if warm else "", seconds < 2.0 if warm else None))
    return rows


BATCH_SIZES = (1, 8, 64, 1024, 8192, 65536)
TARGET_OVER_CARTPOLE = 1.25      # issue 37: 250,000 env-steps/s at 1,024 envs where CartPole-v1 runs 200,000


def batch_rows(quick: bool, cart: float, rng: np.random.Generator) -> list[Row]:
    """The batched twin on its default engine (``device.batch_engine="auto"``: the Warp kernel) over batch
    sizes, the pymunk engine at 1,024 envs, and 8 single envs stepped one after another (as SB3's ``DummyVecEnv``
    steps them) against the batch of 8."""
    rows: list[Row] = []
    best = 0.0
    for n in BATCH_SIZES[:-1] if quick else BATCH_SIZES:
        t = twin_step_timing(ENV_ID, n, max(2, (2_000 if quick else 20_000) // n))
        rate = n / t.median
        spread = f"{rate / cart:.2f} x CartPole-v1; IQR {n / t.p75:,.0f}-{n / t.p25:,.0f}"
        if n == 1024:
            target, ok = f">= {TARGET_OVER_CARTPOLE}x CartPole-v1", rate >= TARGET_OVER_CARTPOLE * cart
        else:          # the curve never falls (within a tenth: the spread of a shared machine)
            target, ok = ">= 0.9x the best smaller batch", rate >= 0.9 * best
        rows.append(Row("haptic", f"{ENV_ID}: batched twin, {n} envs (warp engine, random actions)", rate,
                        "env-steps/s", spread, target, ok))
        best = max(best, rate)
        if n == 8:
            eight = 8 / single_envs_step_time(8, 200 if quick else 1000)
            rows.append(Row("haptic", f"{ENV_ID}: 8 single envs stepped in turn (as DummyVecEnv)", eight, "env-steps/s",
                            f"the batch of 8 above: {rate / eight:.1f}x", "batch of 8 >= 1x", rate >= eight))
    n = 1024
    t = twin_step_timing(ENV_ID, n, 4 if quick else 12, list(press_actions(rng, (8, n, 4))))
    rows.append(Row("haptic", f"{ENV_ID}: batched twin, {n} envs (warp engine, pressing actions)", n / t.median,
                    "env-steps/s", f"IQR {n / t.p75:,.0f}-{n / t.p25:,.0f}"))
    for engine in ("pymunk",):
        t = twin_step_timing(ENV_ID, n, 2 if quick else 6, device={"batch_engine": engine})
        rows.append(Row("haptic", f"{ENV_ID}: batched twin, {n} envs ({engine} engine, random actions)", n / t.median,
                        "env-steps/s", f"IQR {n / t.p75:,.0f}-{n / t.p25:,.0f}"))
    return rows


def single_envs_step_time(n: int, steps: int) -> float:
    """Seconds for ``n`` single envs to take one step each, in turn (median of 5 repeats of ``steps``)."""
    envs = [gym.make(ENV_ID) for _ in range(n)]
    for i, env in enumerate(envs):
        env.reset(seed=i)
    actions = np.random.default_rng(1).uniform(-1, 1, (64, n, 4)).astype(np.float32)
    samples = []
    for _ in range(5):
        t0 = time.perf_counter()
        for k in range(steps):
            for env, a in zip(envs, actions[k % 64]):
                _, _, terminated, truncated, _ = env.step(a)
                if terminated or truncated:
                    env.reset()
        samples.append((time.perf_counter() - t0) / steps)
    return float(np.median(samples))


EXTREMES: dict[str, dict] = {
    "default scene": {},
    "coupling 1e6 N/m, 10 g blade": {"device": {"coupling_stiffness": 1e6, "blade_mass": 0.01, "handle_mass": 0.0}},
    "tongue E = 1 kPa (softer than in vivo)": {"tissue": {"E": 1e3}},
    "tongue E = 10 MPa": {"tissue": {"E": 1e7}},
    "coupling 1e6 N/m, 10 g blade, E = 10 MPa": {"device": {"coupling_stiffness": 1e6, "blade_mass": 0.01,
                                                            "handle_mass": 0.0}, "tissue": {"E": 1e7}},
}
PUSHES = {"into the incisors": [0.0, -1.0, 0.0, -1.0], "into the tongue": [1.0, 1.0, 1.0, 1.0]}


def extreme_rows(quick: bool) -> list[Row]:
    """The hand at full speed into the incisors or the tongue (a whole 5 s episode, or 0.5 s where a
    control step takes thousands of substeps), then held still for 1 s (0.1 s): finite, no
    tunnelling, and no energy gained without input (a blade held against the saturated tongue's
    stiff barrier keeps a bounded ringing: peak energy within 0.1 % of its value at the hold; one held
    on the teeth is pushed out of their overlap by pymunk's contact, at most the incisor force times
    the collision slop)."""
    from ..devices.laryngoscope.part import laryngoscope_parts       # pymunk: only for this section
    from ..devices.laryngoscope.single import Laryngoscope  # pymunk

    rows = []
    for name, sections in EXTREMES.items():
        world = World(scene_config(HAPTIC_SCENES[ENV_ID], sections))
        params, contact = laryngoscope_parts(world.scene, world.config)
        for push, action in PUSHES.items():
            dev = Laryngoscope(params, contact)
            steps = 250 if dev.n_substeps < 100 else 25
            if quick:
                steps = min(steps, 25)
            overlap, depth, finite = 0.0, 0.0, True
            t0 = time.perf_counter()
            for _ in range(steps):
                dev.control_step(action)
                overlap = max(overlap, -dev.incisor_clearance())
                depth = max(depth, dev.penetration())
                finite &= all(math.isfinite(v) for v in dev.kinematics())
            energy, incisor = [dev.energy()[0]], 0.0
            for _ in range(50 if dev.n_substeps < 100 else 5):
                dev.control_step([0.0, 0.0, 0.0, 0.0])
                energy.append(dev.energy()[0])
                incisor = max(incisor, dev.incisor_force)
            growth = float(np.max(energy)) / max(energy[0], 1e-300) - 1.0
            allowed = 1e-3 + incisor * COLLISION_SLOP / max(energy[0], 1e-300)
            ok = finite and overlap < 1e-3 and depth < 0.83 * dev.c.R and growth <= allowed
            rows.append(Row("haptic extremes", f"{name}, hand at full speed {push} for {steps * params.dt:.2f} s",
                            dev.n_substeps, "substeps/step",
                            f"incisor overlap {overlap * 1e3:.3f} mm, deepest {depth / dev.c.R:.3f} R, energy held "
                            f"still peaks at (1 {growth:+.1e}) E0, finite {finite}, {time.perf_counter() - t0:.1f} s",
                            "finite, overlap < 1 mm, < 0.83 R, held energy <= 1.001 E0 + F_incisor x slop", ok))
    return rows
