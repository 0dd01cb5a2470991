"""Timing helpers for ``softenv bench``: repeated measurement, medians and spreads, machine facts and
the code's revision (for every report under ``results/``)."""

from __future__ import annotations

import os
import platform
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import gymnasium as gym
import numpy as np

import softenv

from .._blas import openblas_kernels


@dataclass
class Timing:
    """Per-call times (seconds) over repeats: median, interquartile range, p99."""

    samples: np.ndarray

    @property
    def median(self) -> float:
        return float(np.median(self.samples))

    @property
    def p25(self) -> float:
        return float(np.percentile(self.samples, 25))

    @property
    def p75(self) -> float:
        return float(np.percentile(self.samples, 75))

    @property
    def p99(self) -> float:
        return float(np.percentile(self.samples, 99))


def measure(fn: Callable[[], Any], *, number: int = 1000, repeats: int = 15, warmup: int = 1) -> Timing:
    """Time ``fn`` ``number`` times per repeat; return the per-call time of each repeat."""
    for _ in range(warmup):
        for _ in range(max(1, number // 10)):
            fn()
    samples = np.empty(repeats)
    for r in range(repeats):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        samples[r] = (time.perf_counter() - t0) / number
    return Timing(samples)


def measure_each(fn: Callable[[], Any], calls: int = 20000, warmup: int = 200) -> Timing:
    """Time every single call (for tail latencies such as p99)."""
    for _ in range(warmup):
        fn()
    samples = np.empty(calls)
    clock = time.perf_counter
    for i in range(calls):
        t0 = clock()
        fn()
        samples[i] = clock() - t0
    return Timing(samples)


@dataclass
class Row:
    """One benchmark line: a measured value against its target."""

    section: str
    metric: str
    value: float
    unit: str
    spread: str = ""
    target: str = ""
    ok: bool | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        return {"section": self.section, "metric": self.metric, "value": self.value, "unit": self.unit,
                "spread": self.spread, "target": self.target, "ok": self.ok, **self.extra}


def spread_us(t: Timing) -> str:
    return f"IQR {t.p25 * 1e6:.2f}-{t.p75 * 1e6:.2f} us"


def _cpuinfo() -> dict[str, str]:
    """The first processor's fields from /proc/cpuinfo (empty where there is none)."""
    fields: dict[str, str] = {}
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if not line.strip():
                    break
                key, _, value = line.partition(":")
                fields[key.strip()] = value.strip()
    except OSError:
        pass
    return fields


AVX512_FLAGS = ("avx512f", "avx512cd", "avx512bw", "avx512dq", "avx512vl")
AVX2_KERNELS = ("Haswell", "Zen")


def blas_advice() -> str | None:
    """A warning when OpenBLAS runs its AVX2 kernels on a CPU with AVX-512, else None.

    Batched decoding is a GEMM with an inner dimension of only k + 1 (11 FMAs per output value), so it
    is bound by the FMA rate, not by memory: on a Zen 5 core it takes 2.5x the time to write the output
    with OpenBLAS's AVX2 (Haswell) kernels, whose arithmetic alone takes 1.9x, and 1.6x with its
    AVX-512 (SkylakeX) kernels. Some machines pin ``OPENBLAS_CORETYPE=Haswell`` so that BLAS results
    are bitwise the same on every host; OpenBLAS 0.3.31 also falls back to Haswell on CPUs it does not
    recognise (OpenMathLib/OpenBLAS#6029).
    """
    kernels = openblas_kernels()
    flags = set(_cpuinfo().get("flags", "").split())
    if kernels not in AVX2_KERNELS or not flags.issuperset(AVX512_FLAGS):
        return None
    pinned = os.environ.get("OPENBLAS_CORETYPE")
    cause = f"OPENBLAS_CORETYPE={pinned} pins" if pinned else "OpenBLAS picked"
    fix = ("unset it (env -u OPENBLAS_CORETYPE) to let OpenBLAS choose, unless bitwise-identical BLAS results "
           "across hosts matter more" if pinned else "set OPENBLAS_CORETYPE=SkylakeX")
    return (f"{cause} its {kernels} (AVX2) kernels on this AVX-512 CPU; batched decoding is bound by the FMA "
            f"rate and takes about 1.5x as long with them on Zen 5; {fix}")


def machine_info() -> dict[str, Any]:
    """What the numbers were measured on."""
    cpu = _cpuinfo()

    return {"cpu": cpu.get("model name", platform.processor() or "unknown"),
            "cpu_family": cpu.get("cpu family", "unknown"), "logical_cores": os.cpu_count(),
            "python": platform.python_version(), "numpy": np.__version__, "gymnasium": gym.__version__,
            "platform": platform.platform(), "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS", "unset"),
            "openblas_kernels": openblas_kernels(), "OPENBLAS_CORETYPE": os.environ.get("OPENBLAS_CORETYPE", "unset")}


def gym_step_timing(env: Any, actions: list, steps: int, repeats: int = 5, seed: int = 0) -> Timing:
    """Seconds per ``env.step`` over pre-sampled ``actions`` (cycled), resetting when an episode ends."""
    env.reset(seed=seed)
    per_rep = max(1, steps // repeats)
    n = len(actions)
    samples = np.empty(repeats + 1)
    for r in range(repeats + 1):                     # the first repeat warms up and is dropped
        t0 = time.perf_counter()
        for i in range(per_rep):
            _, _, terminated, truncated, _ = env.step(actions[i % n])
            if terminated or truncated:
                env.reset()
        samples[r] = (time.perf_counter() - t0) / per_rep
    return Timing(samples[1:])


def cartpole_steps_per_second(steps: int = 100_000, seed: int = 0) -> Timing:
    """Gymnasium's CartPole-v1 through ``gym.make`` with pre-sampled actions: the in-process reference."""

    env = gym.make("CartPole-v1")
    actions = np.random.default_rng(seed).integers(0, 2, size=4096).tolist()
    timing = gym_step_timing(env, actions, steps, seed=seed)
    env.close()
    return timing


def paired_step_ratios(env: Any, reference: Any, actions: list, steps: int, pairs: int = 5) -> np.ndarray:
    """``env``'s step time over ``reference``'s, from ``pairs`` interleaved :func:`gym_step_timing` runs
    of ``steps`` steps each (the machine's drift hits both alike)."""
    return np.array([gym_step_timing(env, actions, steps).median / gym_step_timing(reference, actions, steps).median
                     for _ in range(pairs)])


CODE_PATHS = ("softenv", "baselines", "pyproject.toml")     # what a result's numbers depend on


def code_revision(root: Path | None = None) -> str:
    """The git commit the package runs from, ``+ uncommitted changes`` when its code differs from it
    (docs and results do not count), so that a report names the code that made it; outside a checkout
    (an installed wheel, or a tree that is not its own git root) the package version."""

    root = Path(softenv.__file__).resolve().parent.parent if root is None else root
    fallback = f"softenv {softenv.__version__} (not a git checkout)"

    def git(*args: str) -> str:
        done = subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, timeout=30)
        if done.returncode != 0:
            raise OSError(done.stderr.strip())
        return done.stdout.strip()

    try:
        if Path(git("rev-parse", "--show-toplevel")).resolve() != root.resolve():
            return fallback      # e.g. a venv inside some repository: that repository's commit is not ours
        head = git("rev-parse", "--short=12", "HEAD")
        changed = git("status", "--porcelain", "--", *CODE_PATHS)         # new files count: code may import them
    except (OSError, subprocess.SubprocessError):
        return fallback
    return f"git {head}" + (" + uncommitted changes" if changed else "")
