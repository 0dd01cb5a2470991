"""Recorded trajectories: the two log schemas trainee scoring reads, their files, and their checks.

A log is a table with a ``time_s`` column and one row per sample, stored as CSV (a header row;
lines starting with ``#`` are comments) or NPZ (one 1-D array per column, plus an integer
``format_version``; read with ``allow_pickle=False``). Which schema a file holds follows from its
columns. Files over 64 MB are refused before they are read; every problem is a ``ValueError``
naming the file, and the row (1 = first data row) and column where one applies.

**Force commands** (``FORCE_LOG``, format_version 1): what the ideal device is told.

| column | unit | allowed |
|---|---|---|
| ``time_s`` | s | finite, >= 0, strictly increasing, at most 600 (``MAX_DURATION_S``) |
| ``insertion_deg`` | deg | within the scene's ``device.insertion_deg`` |
| ``lateral_deg`` | deg | within +- ``device.lateral_deg`` |
| ``normal_N`` | N | within [0, ``device.max_normal_force``] |
| ``sideways_N`` | N | within +- ``device.max_sideways_force`` |

Each row is held until the next (zero-order hold).

**Hand poses** (``HAND_LOG``, format_version 1): what a haptic device records of the hand holding
the laryngoscope (the grip), in the sagittal frame of :mod:`softenv.devices.laryngoscope` (``x``
toward the patient's front, out of the mouth; ``z`` up; pitch counter-clockwise, tip down).

| column | unit | allowed |
|---|---|---|
| ``time_s`` | s | as above |
| ``hand_x_m`` | m | relative to the first row; within [-0.025, 0.05] (in 2.5 cm, out 5 cm) |
| ``hand_z_m`` | m | relative to the first row; within [-(radius + 0.005), 0.04] |
| ``hand_pitch_rad`` | rad | relative to the first row; within [-0.5, 0.5] |
| ``hand_y_m`` | m | relative to the first row; within +- the tongue's radius |

Poses are relative to the first row, which is the device's start pose (so a device's own origin
does not matter), and are interpolated linearly between rows (a device samples a continuous path).
Resampled at the scene's control period, the hand must not move faster than the device lets it:
``device.max_hand_speed`` along and across the blade, ``max_pitch_rate``, ``max_sweep_speed``.
"""

from __future__ import annotations

import csv
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._artifact import atomic_write

LOG_VERSION = 1
MAX_DURATION_S = 600.0          # ten minutes: any laryngoscopy attempt; longer logs are refused up front
MAX_FILE_BYTES = 64 << 20


@dataclass(frozen=True)
class Schema:
    """A log's columns (``time_s`` first)."""

    name: str
    columns: tuple[str, ...]


FORCE_LOG = Schema("force commands", ("time_s", "insertion_deg", "lateral_deg", "normal_N", "sideways_N"))
HAND_LOG = Schema("hand poses", ("time_s", "hand_x_m", "hand_z_m", "hand_pitch_rad", "hand_y_m"))
SCHEMAS = (FORCE_LOG, HAND_LOG)


def read_log(path: str | Path, schema: Schema | None = None) -> tuple[Schema, np.ndarray]:
    """Read and check a log file; returns its schema (``schema``, or the one its columns name) and an
    ``(n, 5)`` float table in the schema's column order."""
    path = Path(path)
    name = f"trajectory {str(path)!r}"
    if not path.exists():
        raise ValueError(f"{name} does not exist")
    if not path.is_file():
        raise ValueError(f"{name} is not a file")
    if path.suffix not in (".npz", ".csv"):
        raise ValueError(f"{name}: unknown format {path.suffix!r}; use .csv or .npz")
    if path.stat().st_size > MAX_FILE_BYTES:
        raise ValueError(f"{name} has {path.stat().st_size:,} bytes; at most {MAX_FILE_BYTES:,} are read "
                         f"(a {MAX_DURATION_S:g} s trajectory needs far less)")
    try:
        schema, table = _read_npz(path, name, schema) if path.suffix == ".npz" else _read_csv(path, name, schema)
    except (OSError, EOFError, zipfile.BadZipFile, UnicodeDecodeError, csv.Error) as exc:
        raise ValueError(f"{name} cannot be read as {path.suffix[1:].upper()}: {exc}") from None
    return schema, check_table(table, schema, name)


def _pick_schema(present: list[str], name: str, schema: Schema | None) -> Schema:
    """The schema whose columns the file has; an error lists what is missing from each."""
    candidates = [schema] if schema is not None else list(SCHEMAS)
    for s in candidates:
        if all(c in present for c in s.columns):
            return s
    best = max(candidates, key=lambda s: sum(c in present for c in s.columns))
    missing = [c for c in best.columns if c not in present]
    others = "; or ".join(f"{s.name}: {list(s.columns)}" for s in candidates if s is not best)
    return _raise(f"{name}: missing columns {missing}; has {present}, {best.name} need {list(best.columns)}"
                  + (f" (or {others})" if others else ""))


def _raise(message: str) -> Any:
    raise ValueError(message)


def _read_npz(path: Path, name: str, schema: Schema | None) -> tuple[Schema, np.ndarray]:
    if not zipfile.is_zipfile(path):         # np.load would try it as a pickle and talk about that
        raise ValueError(f"{name} cannot be read as NPZ: not a zip archive")
    with np.load(path, allow_pickle=False) as data:
        if "format_version" not in data:
            raise ValueError(f"{name}: no format_version; this softenv reads format_version={LOG_VERSION}")
        try:
            version = data["format_version"]
        except ValueError as exc:
            raise ValueError(f"{name}: format_version cannot be read without pickle: {exc}") from None
        if version.shape != () or version.dtype.kind not in "iu" or int(version) != LOG_VERSION:
            raise ValueError(f"{name}: format_version={version.tolist()!r}; this softenv reads {LOG_VERSION} "
                             "(one integer)")
        schema = _pick_schema([k for k in data.files if k != "format_version"], name, schema)
        columns = {}
        for c in schema.columns:
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
    return schema, np.stack([columns[c].astype(np.float64) for c in schema.columns], axis=1)


def _read_csv(path: Path, name: str, schema: Schema | None) -> tuple[Schema, np.ndarray]:
    with open(path, newline="", encoding="utf-8") as fh:
        rows = [r for r in csv.reader(line for line in fh if not line.startswith("#"))]
    if not rows:
        raise ValueError(f"{name} is empty; expected a header row")
    header = [h.strip() for h in rows[0]]
    schema = _pick_schema(header, name, schema)
    index = [header.index(c) for c in schema.columns]
    table = np.empty((len(rows) - 1, len(schema.columns)))
    for i, row in enumerate(rows[1:], start=1):
        for j, (col, k) in enumerate(zip(schema.columns, index)):
            try:
                table[i - 1, j] = float(row[k])
            except (ValueError, IndexError):
                raise ValueError(f"{name}: row {i}, column {col!r}: {row[k] if k < len(row) else ''!r} "
                                 "is not a number") from None
    return schema, table


def check_table(table: Any, schema: Schema, source: str = "trajectory") -> np.ndarray:
    """The rules every log shares, on an in-memory table: ``(n, 5)`` real numbers in the schema's
    column order, at least 2 rows, finite, times from 0 strictly increasing, at most ``MAX_DURATION_S``."""
    table = np.asarray(table)
    if table.ndim != 2 or table.shape[1] != len(schema.columns) or table.dtype.kind not in "iuf":
        raise ValueError(f"{source} must be a table of real numbers with {len(schema.columns)} columns "
                         f"{list(schema.columns)}, got shape {table.shape} and dtype {table.dtype}")
    if len(table) < 2:
        raise ValueError(f"{source}: needs at least 2 rows, has {len(table)}")
    bad = ~np.isfinite(table)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise ValueError(f"{source}: row {i + 1}, column {schema.columns[j]!r} = {float(table[i, j])!r} is not finite")
    t = table[:, 0]
    if t[0] < 0 or (np.diff(t) <= 0).any():
        i = 0 if t[0] < 0 else int(np.argmax(np.diff(t) <= 0)) + 1
        raise ValueError(f"{source}: row {i + 1}, column 'time_s' = {float(t[i])!r}: times must be >= 0 and strictly "
                         "increasing")
    if t[-1] > MAX_DURATION_S:
        raise ValueError(f"{source}: row {len(t)}, column 'time_s' = {t[-1]:g}: a trajectory lasts at most "
                         f"{MAX_DURATION_S:g} s")
    return table.astype(np.float64, copy=False)


def check_limits(table: np.ndarray, schema: Schema, limits: dict[str, tuple[float, float]], source: str) -> None:
    """Each named column within its ``(low, high)``; the first violation names its row and column."""
    for col, (lo, hi) in limits.items():
        j = schema.columns.index(col)
        out = (table[:, j] < lo) | (table[:, j] > hi)
        if out.any():
            i = int(np.argmax(out))
            raise ValueError(f"{source}: row {i + 1}, column {col!r} = {table[i, j]:g} is outside the device range "
                             f"[{lo:g}, {hi:g}]")


def save_log(table: np.ndarray, path: str | Path, schema: Schema, note: str = "") -> None:
    """Write a log as CSV (checked first; written atomically: a failed write leaves no short file)."""
    table = check_table(table, schema)

    def write(fh: Any) -> None:
        if note:
            fh.write(f"# {note}\n")
        writer = csv.writer(fh)
        writer.writerow(schema.columns)
        for row in table:
            writer.writerow([f"{v:.9g}" for v in row])

    atomic_write(path, write, text=True)
