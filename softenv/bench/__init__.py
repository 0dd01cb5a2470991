"""``softenv bench``: speed and memory targets, measured as medians with spreads, single-threaded,
next to Gymnasium's CartPole-v1 measured in the same process. Writes ``perf.md`` and ``perf.json``."""

from __future__ import annotations

import importlib
import importlib.util
import json
import os
import sys
import time
from pathlib import Path
from typing import Callable

from .._artifact import atomic_write_all
from ..parallel import THREAD_VARS
from .timing import Row, Timing, blas_advice, cartpole_steps_per_second, code_revision, machine_info

# section name -> (module, function); each function takes ``(quick, reference)`` -- the CartPole-v1
# step timing of this run -- and returns rows
SECTIONS: dict[str, tuple[str, str]] = {
    "tissue": ("softenv.bench.shape", "bench_tissue"),
    "decode": ("softenv.bench.shape", "bench_decode"),
    "fit": ("softenv.bench.shape", "bench_fit"),
    "response": ("softenv.bench.response", "bench_response"),
    "env": ("softenv.bench.env", "bench_env"),
    "sb3": ("softenv.bench.env", "bench_sb3"),
    "torch": ("softenv.bench.env", "bench_torch"),
    "gradients": ("softenv.bench.gradients", "bench_gradients"),   # the torch twin with differentiable=True
    "haptic": ("softenv.bench.haptic", "bench_haptic"),
    "bridge": ("softenv.bench.bridge", "bench_bridge"),
    "play": ("softenv.bench.play", "bench_play"),
    "gpu": ("softenv.bench.env", "bench_gpu"),                 # --device cuda: SoftSphere-v0's torch twin
    "gpu-haptic": ("softenv.bench.env", "bench_gpu_haptic"),   # --device cuda: the laryngoscope's torch twin
}
GPU_SECTIONS = ["gpu", "gpu-haptic"]
DEFAULT_SECTIONS = [name for name in SECTIONS if name not in GPU_SECTIONS]

# the reference's interquartile range, or its change from a run's start to its end, beyond this share of
# its median: the host's speed moved under the run (a busy or throttled VM), so its rates are not comparable
UNSTEADY = 0.10


def steadiness(start: Timing, end: Timing) -> str | None:
    """A warning when CartPole-v1's step time, timed at a run's ``start`` and ``end``, says the host's speed
    moved during the run (spread or drift beyond :data:`UNSTEADY`), else None. Ratios measured side by side
    (paired runs, fresh processes alternating) still hold on such a host; absolute rates and the targets
    stated in them do not compare with another run's."""
    spread = max((t.p75 - t.p25) / t.median for t in (start, end))
    drift = start.median / end.median - 1.0          # the end's rate over the start's, less one
    if spread <= UNSTEADY and abs(drift) <= UNSTEADY:
        return None
    return (f"this host's speed moved during the run: CartPole-v1's step time spread {spread:.0%} (interquartile "
            f"range over median) and its rate changed {drift:+.0%} from the run's start to its end (a steady host: "
            f"both within {UNSTEADY:.0%}); ratios measured side by side hold, but absolute rates and targets do not "
            "compare with another run's")


def single_thread_environment() -> dict[str, str]:
    """The current environment with BLAS/OpenMP pinned to one thread."""
    env = dict(os.environ)
    env.update({v: "1" for v in THREAD_VARS})
    return env


def cuda_available() -> bool:
    """Whether torch is installed and sees a CUDA device (``--device cuda`` is refused up front otherwise)."""
    if importlib.util.find_spec("torch") is None:
        return False
    import torch                              # the rl extra: only to ask for a GPU

    return bool(torch.cuda.is_available())


def threads_pinned() -> bool:
    return all(os.environ.get(v) == "1" for v in THREAD_VARS)


def rerun_single_threaded(argv: list[str] | None = None, **extra: str) -> None:
    """Replace this process by the same command with one BLAS/OpenMP thread (and ``extra`` variables),
    unless it already runs so: BLAS reads its thread count when numpy loads, which a script has done by
    the time it parses its arguments. ``argv``: run ``python -m softenv ARGV`` (a CLI command) rather than
    this script again."""
    if not threads_pinned():
        command = [sys.executable, *sys.argv] if argv is None else [sys.executable, "-m", "softenv", *argv]
        os.execve(sys.executable, command, {**single_thread_environment(), **extra})


def run(quick: bool, out_dir: Path, only: list[str] | None = None, command: str = "softenv bench",
        echo: Callable[[str], None] = print, device: str = "cpu") -> list[Row]:
    """Run the selected sections (all but the GPU ones by default), print the table, write the reports
    (``perf.*``; ``device="cuda"`` runs the GPU sections, all or those in ``only``, and writes ``perf-gpu.*``)."""
    if device not in ("cpu", "cuda"):
        raise ValueError(f"device={device!r} must be 'cpu' or 'cuda'")
    if device == "cuda" and only and not set(only) <= set(GPU_SECTIONS):
        raise ValueError(f"--only {' '.join(only)}: --device cuda runs the GPU sections only ({', '.join(GPU_SECTIONS)})")
    names = (only or GPU_SECTIONS) if device == "cuda" else (only or DEFAULT_SECTIONS)
    unknown = [n for n in names if n not in SECTIONS]
    if unknown:
        raise ValueError(f"unknown bench section(s) {unknown}; choose from {list(SECTIONS)}")
    started = time.perf_counter()
    reference_steps = 40_000 if quick else 200_000
    reference = cartpole_steps_per_second(reference_steps)
    rows = [reference_row(reference, "")]
    for name in names:
        module, func = SECTIONS[name]
        echo(f"bench: {name} ...")
        section: Callable[..., list[Row]] = getattr(importlib.import_module(module), func)
        try:
            rows += section(quick, reference)
        except ImportError as exc:  # an optional extra is missing: say so instead of failing the run
            rows.append(Row(name, f"skipped: {exc}", float("nan"), "", target="install softenv[all]", ok=None))
    # timed again at the end: a host whose speed moved during the run is named in the report
    closing = cartpole_steps_per_second(reference_steps)
    rows.append(reference_row(closing, ", at the end of the run"))
    elapsed = time.perf_counter() - started
    table = format_table(rows)
    echo(table)
    warnings = {"blas_advice": blas_advice(), "unsteady_host": steadiness(reference, closing)}
    for text in filter(None, warnings.values()):
        echo(f"warning: {text}")
    write_report(rows, out_dir, command, quick, elapsed, table, warnings, "perf-gpu" if device == "cuda" else "perf")
    return rows


def reference_row(reference: Timing, when: str) -> Row:
    return Row("reference", f"Gymnasium CartPole-v1 step via gym.make (pre-sampled actions){when}",
               1.0 / reference.median, "steps/s", f"IQR {1 / reference.p75:,.0f}-{1 / reference.p25:,.0f}")


def format_table(rows: list[Row]) -> str:
    lines = ["| section | metric | median | spread | target | met |", "|---|---|---|---|---|---|"]
    for r in rows:
        value = f"{r.value:,.3g}" if abs(r.value) < 1000 else f"{r.value:,.0f}"
        met = "" if r.ok is None else ("yes" if r.ok else "**no**")
        lines.append(f"| {r.section} | {r.metric} | {value} {r.unit} | {r.spread} | {r.target} | {met} |")
    return "\n".join(lines)


def write_report(rows: list[Row], out_dir: Path, command: str, quick: bool, elapsed: float, table: str,
                 warnings: dict[str, str | None] | None = None, name: str = "perf") -> None:
    """``perf.md`` and ``perf.json`` (or ``name``'s); ``warnings``: each kind's text, or None where none
    applies (written to the JSON under its kind, and above the table)."""
    warnings = warnings or {}
    out_dir.mkdir(parents=True, exist_ok=True)
    machine = machine_info()
    stem = f"{name}_quick" if quick else name
    code = code_revision()
    payload = {"command": command, "code": code, "quick": quick, "elapsed_s": elapsed, "machine": machine,
               **warnings, "rows": [r.as_dict() for r in rows]}
    text = [f"# softenv performance{' (quick)' if quick else ''}", "",
            f"Made by `{command}` at {code} in {elapsed:.0f} s. Single thread (BLAS/OpenMP pinned to 1); every time is the "
            "median over repeats, with its interquartile range; CartPole-v1 was measured in the same process.", "",
            "Machine: " + ", ".join(f"{k} {v}" for k, v in machine.items()), "",
            *(line for text in warnings.values() if text for line in (f"Warning: {text}.", "")), table, ""]
    # both files or neither: a failed write leaves the old report whole
    atomic_write_all([(out_dir / f"{stem}.json", lambda fh: fh.write(json.dumps(payload, indent=2, default=float) + "\n"),
                       True), (out_dir / f"{stem}.md", lambda fh: fh.write("\n".join(text)), True)])


def command_line(argv: list[str]) -> str:
    """``softenv ARGV`` as a reader must type it to reproduce this run, with this run's OpenBLAS kernel
    setting: it changes the last bits of every product and, on AVX-512 CPUs, batched-decode times."""
    coretype = os.environ.get("OPENBLAS_CORETYPE")
    prefix = f"OPENBLAS_CORETYPE={coretype} " if coretype else "env -u OPENBLAS_CORETYPE "
    return prefix + " ".join(["softenv", *argv])


