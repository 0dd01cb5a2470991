"""Trainee scoring: replay a recorded device trajectory through a scene and score it against the
expert reference.

Trajectory schema (CSV with a header row, or ``.npz`` with one array per column plus
``format_version = 1``):

| column | unit | allowed |
|---|---|---|
| ``time_s`` | s | finite, >= 0, strictly increasing, at most 600 (``MAX_DURATION_S``) |
| ``insertion_deg`` | deg | within the scene's ``device.insertion_deg`` |
| ``lateral_deg`` | deg | within +- ``device.lateral_deg`` |
| ``normal_N`` | N | within [0, ``device.max_normal_force``] |
| ``sideways_N`` | N | within +- ``device.max_sideways_force`` |

Each row is a device command held until the next row (zero-order hold), sampled at the scene's
control period ``dt``; the replay lasts until the last row's time. Files over 64 MB are refused
before they are read, and every check runs before the replay. The target is the centre of the
scene's laryngoscopy family (the same for every trainee). Errors name the row (1 = first data row)
and the column.

Score (0-100), written out in every report::

    score = 100 (0.5 accuracy + 0.2 speed + 0.2 safety + 0.1 smoothness)
    accuracy   = clip(1 - final_error / rest_error, 0, 1)        rest_error: error with no force
    speed      = clip(expert_time / time_to_target, 0, 1)       0 if the target is never reached
    safety     = clip(1 - max(peak_force - safe_force, 0) / safe_force, 0, 1)
    smoothness = clip(expert_jerk / jerk, 0, 1)                 jerk: RMS third derivative of the force (N/s^3)

``time_to_target``: first time the shape error falls under the scene's tolerance.
"""

from __future__ import annotations

import csv
import json
import math
import zipfile
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ._artifact import atomic_write
from ._validation import check_choice, check_real
from .envs.config import make_config

COLUMNS = ("time_s", "insertion_deg", "lateral_deg", "normal_N", "sideways_N")
TRAJECTORY_VERSION = 1
MAX_DURATION_S = 600.0          # ten minutes: any laryngoscopy attempt; longer logs are refused up front
MAX_FILE_BYTES = 64 << 20
WEIGHTS = {"accuracy": 0.5, "speed": 0.2, "safety": 0.2, "smoothness": 0.1}
FORMULA = ("score = 100 (0.5 accuracy + 0.2 speed + 0.2 safety + 0.1 smoothness); accuracy = clip(1 - final_error / "
           "rest_error, 0, 1); speed = clip(expert_time / time_to_target, 0, 1) (0 if never reached); safety = "
           "clip(1 - max(peak_force - safe_force, 0) / safe_force, 0, 1); smoothness = clip(expert_jerk / jerk, 0, 1)")


@dataclass
class Replay:
    """A trajectory replayed through a scene: per-step series and the summary metrics."""

    time_s: np.ndarray
    error_mm: np.ndarray
    force_N: np.ndarray
    final_error_mm: float
    rest_error_mm: float
    time_to_target_s: float | None
    peak_force_N: float
    mean_force_N: float
    force_time_integral_Ns: float
    jerk_rms: float


def load_trajectory(path: str | Path) -> np.ndarray:
    """Read and validate the schema; returns an ``(n, 5)`` float array in ``COLUMNS`` order. Every
    problem is a ``ValueError`` naming the file (and the row and column where one applies)."""
    path = Path(path)
    name = repr(str(path))
    if not path.exists():
        raise ValueError(f"trajectory {name} does not exist")
    if not path.is_file():
        raise ValueError(f"trajectory {name} is not a file")
    if path.suffix not in (".npz", ".csv"):
        raise ValueError(f"trajectory {name}: unknown format {path.suffix!r}; use .csv or .npz")
    if path.stat().st_size > MAX_FILE_BYTES:
        raise ValueError(f"trajectory {name} has {path.stat().st_size:,} bytes; at most {MAX_FILE_BYTES:,} are read "
                         f"(a {MAX_DURATION_S:g} s trajectory needs far less)")
    try:
        table = _read_npz(path, name) if path.suffix == ".npz" else _read_csv(path, name)
    except (OSError, EOFError, zipfile.BadZipFile, UnicodeDecodeError, csv.Error) as exc:
        raise ValueError(f"trajectory {name} cannot be read as {path.suffix[1:].upper()}: {exc}") from None
    check_trajectory(table, f"trajectory {name}")
    return table


def _read_npz(path: Path, name: str) -> np.ndarray:
    if not zipfile.is_zipfile(path):         # np.load would try it as a pickle and talk about that
        raise ValueError(f"trajectory {name} cannot be read as NPZ: not a zip archive")
    with np.load(path, allow_pickle=False) as data:
        if "format_version" not in data:
            raise ValueError(f"{name}: no format_version; this softenv reads format_version={TRAJECTORY_VERSION}")
        try:
            version = data["format_version"]
        except ValueError as exc:
            raise ValueError(f"{name}: format_version cannot be read without pickle: {exc}") from None
        if version.shape != () or version.dtype.kind not in "iu" or int(version) != TRAJECTORY_VERSION:
            raise ValueError(f"{name}: format_version={version.tolist()!r}; this softenv reads {TRAJECTORY_VERSION} "
                             "(one integer)")
        missing = [c for c in COLUMNS if c not in data]
        if missing:
            raise ValueError(f"{name}: missing columns {missing}; required: {list(COLUMNS)}")
        columns = {}
        for c in COLUMNS:
            try:
                column = data[c]
            except ValueError as exc:         # an object array (pickle) or a damaged member
                raise ValueError(f"{name}: column {c!r} cannot be read without pickle: {exc}") from None
            if column.ndim != 1 or column.dtype.kind not in "iuf":
                raise ValueError(f"{name}: column {c!r} must be a 1-D array of real numbers, got shape "
                                 f"{column.shape} and dtype {column.dtype}")
            columns[c] = column
    lengths = {c: len(v) for c, v in columns.items()}
    if len(set(lengths.values())) > 1:
        raise ValueError(f"{name}: columns have unequal lengths {lengths}")
    return np.stack([columns[c].astype(np.float64) for c in COLUMNS], axis=1)


def _read_csv(path: Path, name: str) -> np.ndarray:
    with open(path, newline="", encoding="utf-8") as fh:
        rows = [r for r in csv.reader(line for line in fh if not line.startswith("#"))]
    if not rows:
        raise ValueError(f"{name} is empty; expected a header {list(COLUMNS)}")
    header = [h.strip() for h in rows[0]]
    missing = [c for c in COLUMNS if c not in header]
    if missing:
        raise ValueError(f"{name}: missing columns {missing}; header has {header}, required {list(COLUMNS)}")
    index = [header.index(c) for c in COLUMNS]
    table = np.empty((len(rows) - 1, len(COLUMNS)))
    for i, row in enumerate(rows[1:], start=1):
        for j, (col, k) in enumerate(zip(COLUMNS, index)):
            try:
                table[i - 1, j] = float(row[k])
            except (ValueError, IndexError):
                raise ValueError(f"{name}: row {i}, column {col!r}: {row[k] if k < len(row) else ''!r} "
                                 "is not a number") from None
    return table


def check_trajectory(table: Any, source: str = "trajectory") -> np.ndarray:
    """The schema's rules on an in-memory table: ``(n, 5)`` real numbers in ``COLUMNS`` order, at
    least 2 rows, finite, times from 0 strictly increasing, lasting at most ``MAX_DURATION_S``."""
    table = np.asarray(table)
    if table.ndim != 2 or table.shape[1] != len(COLUMNS) or table.dtype.kind not in "iuf":
        raise ValueError(f"{source} must be a table of real numbers with {len(COLUMNS)} columns {list(COLUMNS)}, got "
                         f"shape {table.shape} and dtype {table.dtype}")
    if len(table) < 2:
        raise ValueError(f"{source}: needs at least 2 rows, has {len(table)}")
    bad = ~np.isfinite(table)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise ValueError(f"{source}: row {i + 1}, column {COLUMNS[j]!r} = {table[i, j]!r} is not finite")
    t = table[:, 0]
    if t[0] < 0 or (np.diff(t) <= 0).any():
        i = 0 if t[0] < 0 else int(np.argmax(np.diff(t) <= 0)) + 1
        raise ValueError(f"{source}: row {i + 1}, column 'time_s' = {t[i]!r}: times must be >= 0 and strictly "
                         "increasing")
    if t[-1] > MAX_DURATION_S:
        raise ValueError(f"{source}: row {len(t)}, column 'time_s' = {t[-1]:g}: a trajectory lasts at most "
                         f"{MAX_DURATION_S:g} s")
    return table.astype(np.float64, copy=False)


def check_ranges(table: np.ndarray, config: dict, source: str = "trajectory") -> None:
    dev = config["device"]
    limits = {"insertion_deg": dev["insertion_deg"], "lateral_deg": (-dev["lateral_deg"], dev["lateral_deg"]),
              "normal_N": (0.0, dev["max_normal_force"]),
              "sideways_N": (-dev["max_sideways_force"], dev["max_sideways_force"])}
    for j, col in enumerate(COLUMNS[1:], start=1):
        lo, hi = limits[col]
        out = (table[:, j] < lo) | (table[:, j] > hi)
        if out.any():
            i = int(np.argmax(out))
            raise ValueError(f"{source}: row {i + 1}, column {col!r} = {table[i, j]:g} is outside the device range "
                             f"[{lo:g}, {hi:g}]")


def replay(table: np.ndarray, scene: dict[str, Any] | None = None) -> Replay:
    """Replay a validated trajectory through a reach scene whose target is the family centre.

    Each row is held until the next (zero-order hold) and sampled at the scene's ``dt``.
    """
    from .envs.scene import degrees_to_features
    from .envs.soft_sphere import SoftSphereEnv

    table = check_trajectory(table)
    config = make_config(**(scene or {}))
    check_ranges(table, config)
    dt = config["dynamics"]["dt"]
    times = (np.arange(max(1, int(math.floor(table[-1, 0] / dt + 1e-9)))) + 1) * dt
    rows = np.clip(np.searchsorted(table[:, 0], times - dt, side="right") - 1, 0, len(table) - 1)
    overrides = {**(scene or {}), "task": {**(scene or {}).get("task", {}), "kind": "reach", "horizon": len(times)}}
    env = SoftSphereEnv(**overrides)
    world = env.world
    features = degrees_to_features(table[rows, 1:], config["tissue"]["radius"])
    # ranges are checked above, so the clip only removes rounding at the box's faces
    actions = np.clip(world.device.normalised(features), -1.0, 1.0).astype(np.float32)
    centre = world.device.normalised((world.family.low + world.family.high) / 2)
    env.reset(seed=0, options={"target": centre})
    error, force = np.empty(len(times)), np.empty(len(times))
    for i, a in enumerate(actions):
        _, _, _, _, info = env.step(a)
        error[i], force[i] = info["shape_error_mm"], info["force_N"]
    ref = math.sqrt(max(float(np.sum((env._target_b[0] - world.b_rest) ** 2)), world.floor_sq) / world.n_vertices) * 1e3
    reached = np.flatnonzero(error < world.tolerance * ref)
    applied = world.device.features(actions.astype(np.float64))[:, 2:]
    jerk = np.diff(applied, n=3, axis=0) / dt ** 3 if len(applied) > 3 else np.zeros((1, 2))
    return Replay(times, error, force, float(error[-1]), ref, float(times[reached[0]]) if reached.size else None,
                  float(force.max()), float(force.mean()), float(force.sum() * dt),
                  float(np.sqrt(np.mean(np.sum(jerk * jerk, axis=1)))))


def expert_trajectory(scene: dict[str, Any] | None = None, duration_s: float = 5.0, style: str = "expert") -> np.ndarray:
    """A recorded-like trajectory of the laryngoscopy procedure toward the family centre.

    ``expert``: insert (first 30 %), press (to 60 %), sweep (to 80 %), hold; smooth (cosine ramps).
    ``too_forceful``: the same path pressing to the device's maximum with a 3 Hz tremor.
    ``wrong_direction``: presses too shallow, off to the other side, and sweeps toward -y.
    """
    check_real(duration_s, "duration_s", 0.1, MAX_DURATION_S)
    check_choice(style, "style", ("expert", "too_forceful", "wrong_direction"))
    config = make_config(**(scene or {}))
    task, dev = config["task"], config["device"]
    target = np.array([np.mean(task["target_insertion_deg"]), np.mean(task["target_lateral_deg"]),
                       np.mean(task["target_normal_force"]), np.mean(task["target_sideways_force"])])
    start_insertion = dev["insertion_deg"][0]
    if style == "wrong_direction":
        target = np.array([start_insertion + 0.3 * (target[0] - start_insertion), -target[1] - 8.0, target[2],
                           -target[3]])
    t = np.arange(0.0, duration_s + 1e-9, 0.02)
    ramp = lambda a, b: 0.5 - 0.5 * np.cos(np.pi * np.clip((t / duration_s - a) / (b - a), 0.0, 1.0))  # noqa: E731
    insertion = start_insertion + (target[0] - start_insertion) * ramp(0.0, 0.3)
    lateral = target[1] * ramp(0.0, 0.3)
    normal = target[2] * (0.1 + 0.9 * ramp(0.3, 0.6)) * (t > 0)
    sideways = target[3] * ramp(0.6, 0.8)
    if style == "too_forceful":
        normal = np.minimum(dev["max_normal_force"] * ramp(0.2, 0.3) * (1.0 + 0.15 * np.sin(2 * np.pi * 3.0 * t)),
                            dev["max_normal_force"])
    lateral = np.clip(lateral, -dev["lateral_deg"], dev["lateral_deg"])
    return np.stack([t, insertion, lateral, np.clip(normal, 0, dev["max_normal_force"]),
                     np.clip(sideways, -dev["max_sideways_force"], dev["max_sideways_force"])], axis=1)


def save_trajectory(table: np.ndarray, path: str | Path, note: str = "") -> None:
    """Write a trajectory as CSV (checked first; written atomically: a failed write leaves no short file)."""
    table = check_trajectory(table)

    def write(fh: Any) -> None:
        if note:
            fh.write(f"# {note}\n")
        writer = csv.writer(fh)
        writer.writerow(COLUMNS)
        for row in table:
            writer.writerow([f"{v:.6g}" for v in row])

    atomic_write(path, write, text=True)


def score(trainee: Replay, expert: Replay, safe_force: float) -> dict[str, float]:
    parts = {
        "accuracy": float(np.clip(1.0 - trainee.final_error_mm / trainee.rest_error_mm, 0.0, 1.0)),
        "speed": 0.0 if trainee.time_to_target_s is None or expert.time_to_target_s is None
        else float(np.clip(expert.time_to_target_s / trainee.time_to_target_s, 0.0, 1.0)),
        "safety": float(np.clip(1.0 - max(trainee.peak_force_N - safe_force, 0.0) / safe_force, 0.0, 1.0)),
        "smoothness": float(np.clip(expert.jerk_rms / max(trainee.jerk_rms, 1e-12), 0.0, 1.0)),
    }
    parts["score"] = 100.0 * sum(WEIGHTS[k] * parts[k] for k in WEIGHTS)
    return parts


def score_file(path: str | Path, scene: dict[str, Any] | None = None, out_dir: str | Path | None = None) -> dict[str, Any]:
    """Score a trajectory file; with ``out_dir``, write ``<name>_score.json``, ``.md`` and ``.png``.
    Arguments and file are checked before any replay."""
    if out_dir is not None and Path(out_dir).exists() and not Path(out_dir).is_dir():
        raise ValueError(f"out directory {str(out_dir)!r} exists and is not a directory")
    config = make_config(**(scene or {}))
    table = load_trajectory(path)
    check_ranges(table, config, f"trajectory {str(path)!r}")
    trainee = replay(table, scene)
    expert = replay(expert_trajectory(scene), scene)
    parts = score(trainee, expert, config["reward"]["safe_force"])
    summary = {k: v for k, v in asdict(trainee).items() if not isinstance(v, np.ndarray)}
    report = {"trajectory": str(path), "scene": scene or {}, **parts, "metrics": summary,
              "expert": {k: v for k, v in asdict(expert).items() if not isinstance(v, np.ndarray)}, "formula": FORMULA}
    if out_dir is not None:
        out = Path(out_dir)
        stem = Path(path).stem
        atomic_write(out / f"{stem}_score.json", lambda fh: fh.write(json.dumps(report, indent=2)), text=True)
        atomic_write(out / f"{stem}_score.md", lambda fh: fh.write(_markdown(report)), text=True)
        _plot(trainee, expert, out / f"{stem}_score.png", f"{stem}: score {parts['score']:.0f}/100")
    return report


def _markdown(report: dict[str, Any]) -> str:
    m, e = report["metrics"], report["expert"]
    ttt = lambda v: "never" if v is None else f"{v:.2f} s"  # noqa: E731
    rows = [("final shape error", f"{m['final_error_mm']:.3f} mm", f"{e['final_error_mm']:.3f} mm"),
            ("time to target", ttt(m["time_to_target_s"]), ttt(e["time_to_target_s"])),
            ("peak force", f"{m['peak_force_N']:.1f} N", f"{e['peak_force_N']:.1f} N"),
            ("mean force", f"{m['mean_force_N']:.1f} N", f"{e['mean_force_N']:.1f} N"),
            ("force-time integral", f"{m['force_time_integral_Ns']:.1f} N s", f"{e['force_time_integral_Ns']:.1f} N s"),
            ("jerk (RMS)", f"{m['jerk_rms']:.3g} N/s^3", f"{e['jerk_rms']:.3g} N/s^3")]
    lines = [f"# Trainee score: {report['score']:.1f} / 100\n", f"Trajectory `{report['trajectory']}`.\n",
             "| metric | trainee | expert |", "|---|---|---|", *[f"| {a} | {b} | {c} |" for a, b, c in rows], "",
             "| part | value |", "|---|---|", *[f"| {k} | {report[k]:.3f} |" for k in WEIGHTS], "",
             f"Formula: {report['formula']}."]
    return "\n".join(lines) + "\n"


def _plot(trainee: Replay, expert: Replay, path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(6, 4.5), sharex=True)
    ax1.plot(trainee.time_s, trainee.error_mm, label="trainee")
    ax1.plot(expert.time_s, expert.error_mm, "--", label="expert")
    ax1.set_ylabel("shape error (mm)")
    ax1.legend(fontsize=7)
    ax2.plot(trainee.time_s, trainee.force_N, label="trainee")
    ax2.plot(expert.time_s, expert.force_N, "--", label="expert")
    ax2.set_ylabel("force (N)")
    ax2.set_xlabel("time (s)")
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    atomic_write(path, lambda fh: fig.savefig(fh, format="png", dpi=110))
    plt.close(fig)
