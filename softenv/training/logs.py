"""Recorded trajectories: the two log schemas trainee scoring reads, their files, and their checks.

A log is a table with a ``time_s`` column and one row per sample, stored as CSV (a header row;
lines starting with ``#`` are comments) or NPZ (one 1-D array per column, plus an integer
``format_version``; read with ``allow_pickle=False``). A log of ``format_version`` 2 (what
:func:`save_log` writes) records the scene it was made on, as JSON: the scene's sections over the
schema's id (SoftSphereHaptic-v0 for hand poses, SoftSphere-v0 for force commands), in a first line
``# softenv-log: {"format_version": 2, "scene": {...}}`` of a CSV, or in a string member ``scene`` of
an NPZ; :func:`read_scene` reads it back. A log without it (``format_version`` 1, every CSV without
that line) records no scene: it is replayed on the scene its reader names, the id's own by default.
Which schema a file holds follows from its columns: exactly one schema's columns, each once (a column
twice, the columns of both schemas, or a column of neither is refused by name). Files over 64 MB (``MAX_FILE_BYTES``), more than
``MAX_ROWS`` rows, or NPZ members whose headers or inflated sizes claim more are refused before
anything is allocated; every problem is a ``ValueError`` naming the file, and the row (1 = first
data row) and column where one applies.

**Force commands** (``FORCE_LOG``, format_version 1): what the ideal device is told.

| column | unit | allowed |
|---|---|---|
| ``time_s`` | s | finite, strictly increasing, at most 600 s (``MAX_DURATION_S``) after the first row |
| ``insertion_deg`` | deg | within the scene's ``device.insertion_deg`` |
| ``lateral_deg`` | deg | within +- ``device.lateral_deg`` |
| ``normal_N`` | N | within [0, ``device.max_normal_force``] |
| ``sideways_N`` | N | within +- ``device.max_sideways_force`` |

Each row is held until the next (zero-order hold); time counts from the first row.

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

Poses and times are relative to the first row, which is the device's start pose (so a device's own
origin and clock do not matter), and are interpolated linearly between rows (a device samples a
continuous path), which are at most ``MAX_GAP_S`` = 1 s apart (beyond that the path is unknown).
Resampled at the scene's control period, the hand must not move faster than the device lets it:
``device.max_hand_speed`` along and across the blade, ``max_pitch_rate``, ``max_sweep_speed``.

A hand-pose log may also carry what sensors on the device read at each row (``HAND_LOG.optional``,
:data:`SENSOR_COLUMNS`; any of them, or none): what ``softenv play`` records and tissue identification
(:func:`softenv.training.identify.identify_log`) fits; :func:`read_readings` reads them. Scoring and
replay read the poses only.

| column | unit | allowed |
|---|---|---|
| ``tongue_force_N`` | N | finite, >= 0: the tongue's normal force on the blade (a blade-mounted load cell) |
| ``blade_z_mm`` | mm | finite: the blade's height (a tracked marker on its centre of mass; any zero) |
"""

from __future__ import annotations

import csv
import json
import zipfile
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path
from typing import Any

import numpy as np

from .._artifact import atomic_write

LOG_VERSION = 2                 # 2: the log records its scene; 1 (no scene) is still read
LOG_VERSIONS = (1, 2)
SCENE_TAG = "# softenv-log: "    # a CSV's first line, when it records its scene
MAX_SCENE_CHARS = 65_536        # a scene's JSON: a few hundred characters; a file claiming more is refused
MAX_DURATION_S = 600.0          # ten minutes: any laryngoscopy attempt; longer logs are refused up front
MAX_FILE_BYTES = 64 << 20
MAX_GAP_S = 1.0                 # hand poses are interpolated between rows: a longer gap leaves the path unknown
MAX_ROWS = 1_000_000            # 600 s sampled at 1.67 kHz; a table of them is 40 MB


@dataclass(frozen=True)
class Schema:
    """A log's columns (``time_s`` first), and the columns it may also carry (read by :func:`read_readings`)."""

    name: str
    columns: tuple[str, ...]
    optional: tuple[str, ...] = ()


FORCE_LOG = Schema("force commands", ("time_s", "insertion_deg", "lateral_deg", "normal_N", "sideways_N"))
SENSOR_COLUMNS = ("tongue_force_N", "blade_z_mm")      # what a device's sensors read (the table above)
HAND_LOG = Schema("hand poses", ("time_s", "hand_x_m", "hand_z_m", "hand_pitch_rad", "hand_y_m"), SENSOR_COLUMNS)
SCHEMAS = (FORCE_LOG, HAND_LOG)
# the example logs the docs score, shipped with the package (scripts/make_example_trajectories.py writes them)
EXAMPLES_DIR = Path(str(files(__package__ or "softenv.training") / "examples"))
EXAMPLES = tuple(sorted(f"{folder.name}/{log.stem}" for folder in EXAMPLES_DIR.iterdir() if folder.is_dir()
                        for log in folder.glob("*.csv")))


def example_log(name: str) -> Path:
    """The shipped example log ``name`` (``device_logs/expert``, ``trajectories/too_forceful``: see
    ``EXAMPLES``), wherever the package is installed."""
    if name not in EXAMPLES:
        raise ValueError(f"example {name!r} is not a shipped log; shipped: {', '.join(EXAMPLES)}")
    return EXAMPLES_DIR / f"{name}.csv"


def read_log(path: str | Path, schema: Schema | None = None) -> tuple[Schema, np.ndarray]:
    """Read and check a log file; returns its schema (``schema``, or the one its columns name) and an
    ``(n, 5)`` float table in the schema's column order. Sizes are checked before anything is
    allocated (``MAX_FILE_BYTES`` on disk, ``MAX_ROWS`` rows, an NPZ's members by their headers), and
    a CSV is parsed row by row, so memory stays bounded whatever the file claims."""
    schema, table, _ = _read(path, schema)
    return schema, table[:, :len(schema.columns)]


def read_readings(path: str | Path) -> dict[str, np.ndarray]:
    """The sensor readings a hand-pose log carries (:data:`SENSOR_COLUMNS` it has, each ``(n,)``, a reading
    a row; empty when it has none), checked as the module docstring says."""
    schema, table, names = _read(path, HAND_LOG)
    return {c: table[:, len(schema.columns) + j] for j, c in enumerate(names)}


def check_readings(readings: dict[str, Any], rows: int, source: str = "log") -> dict[str, np.ndarray]:
    """Sensor readings by column (:data:`SENSOR_COLUMNS`), each ``rows`` finite real numbers, forces >= 0."""
    out = {}
    for c, values in readings.items():
        if c not in SENSOR_COLUMNS:
            raise ValueError(f"{source}: readings column {c!r} is not a sensor column; they are {list(SENSOR_COLUMNS)}")
        v = np.asarray(values)
        if v.shape != (rows,) or v.dtype.kind not in "iuf":
            raise ValueError(f"{source}: readings column {c!r} must be {rows} real numbers (one a row), got shape "
                             f"{v.shape} and dtype {v.dtype}")
        v = v.astype(np.float64)
        bad = ~np.isfinite(v) | ((v < 0) if c == "tongue_force_N" else False)
        if bad.any():
            i = int(np.argmax(bad))
            raise ValueError(f"{source}: row {i + 1}, column {c!r} = {float(v[i])!r}: "
                             + ("a force must be finite and >= 0" if c == "tongue_force_N" else "not finite"))
        out[c] = v
    return out


def _read(path: str | Path, schema: Schema | None) -> tuple[Schema, np.ndarray, tuple[str, ...]]:
    """:func:`read_log`'s reading: the schema, the table of its columns then of the optional columns the
    file has (checked as :func:`check_table` checks the first part), and those optional columns' names."""
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
        schema, table, names = _read_npz(path, name, schema) if path.suffix == ".npz" else _read_csv(path, name, schema)
    except (OSError, EOFError, zipfile.BadZipFile, UnicodeDecodeError, csv.Error) as exc:
        raise ValueError(f"{name} cannot be read as {path.suffix[1:].upper()}: {exc}") from None
    width = len(schema.columns)
    checked = check_table(table[:, :width], schema, name)
    check_readings({c: table[:, width + j] for j, c in enumerate(names)}, len(table), name)
    return schema, np.column_stack([checked, table[:, width:]]), names


def _pick_schema(present: list[str], name: str, schema: Schema | None) -> Schema:
    """The one schema whose columns the file has, exactly: a column twice, columns of two schemas, or a
    column of none is refused by name, so that no file is read two ways; an error lists what is missing."""
    repeated = sorted({c for c in present if present.count(c) > 1})
    if repeated:
        raise ValueError(f"{name}: columns {repeated} appear more than once; each column once")
    candidates = [schema] if schema is not None else list(SCHEMAS)
    complete = [s for s in candidates if all(c in present for c in s.columns)]
    if len(complete) > 1:
        raise ValueError(f"{name} has the columns of {' and of '.join(s.name for s in complete)}; a log holds one "
                         "schema (split it into two files)")
    if not complete:
        best = max(candidates, key=lambda s: sum(c in present for c in s.columns))
        missing = [c for c in best.columns if c not in present]
        others = "; or ".join(f"{s.name}: {list(s.columns)}" for s in candidates if s is not best)
        raise ValueError(f"{name}: missing columns {missing}; has {present}, {best.name} need {list(best.columns)}"
                         + (f" (or {others})" if others else ""))
    found = complete[0]
    extra = [c for c in present if c not in found.columns and c not in found.optional]
    if extra:
        raise ValueError(f"{name}: columns {extra} are not {found.name} columns {list(found.columns)}"
                         + (f" nor their optional ones {list(found.optional)}" if found.optional else "")
                         + "; a log holds its schema's columns (remove the others)")
    return found


def _optional_present(schema: Schema, present: list[str]) -> tuple[str, ...]:
    return tuple(c for c in schema.optional if c in present)


def _read_npz(path: Path, name: str, schema: Schema | None) -> tuple[Schema, np.ndarray, tuple[str, ...]]:
    if not zipfile.is_zipfile(path):         # np.load would try it as a pickle and talk about that
        raise ValueError(f"{name} cannot be read as NPZ: not a zip archive")
    with zipfile.ZipFile(path) as archive:
        members = archive.infolist()
        names = [m.filename.removesuffix(".npy") for m in members]
        if len(members) > max(len(s.columns) + len(s.optional) for s in SCHEMAS) + 2:
            raise ValueError(f"{name} has {len(members)} members; a log has one per column, format_version and "
                             "scene")
        repeated = sorted({n for n in names if names.count(n) > 1})
        if repeated:
            raise ValueError(f"{name}: members {repeated} appear more than once; each column once")
        for member, key in zip(members, names):     # sizes from the headers, before anything is inflated
            _check_member(archive, member, key, name)
    with np.load(path, allow_pickle=False) as data:
        if "format_version" not in data:
            raise ValueError(f"{name}: no format_version; this softenv reads format_version={LOG_VERSION}")
        try:
            version = data["format_version"]
        except ValueError as exc:
            raise ValueError(f"{name}: format_version cannot be read without pickle: {exc}") from None
        if version.shape != () or version.dtype.kind not in "iu" or int(version) not in LOG_VERSIONS:
            raise ValueError(f"{name}: format_version={version.tolist()!r}; this softenv reads "
                             f"{' or '.join(map(str, LOG_VERSIONS))} (one integer)")
        if ("scene" in data.files) != (int(version) == 2):
            raise ValueError(f"{name}: format_version={int(version)} "
                             f"{'needs a' if int(version) == 2 else 'has no'} scene member")
        present = [k for k in data.files if k not in ("format_version", "scene")]
        schema = _pick_schema(present, name, schema)
        optional = _optional_present(schema, present)
        columns = {}
        for c in schema.columns + optional:
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
    return schema, np.stack([columns[c].astype(np.float64) for c in schema.columns + optional], axis=1), optional


def read_scene(path: str | Path) -> dict[str, Any] | None:
    """The scene sections a log records (``format_version`` 2), or None for a log that records none.
    Call it on a file :func:`read_log` accepted; a record that is not the documented JSON is refused by
    name."""
    path = Path(path)
    name = f"trajectory {str(path)!r}"
    if path.suffix == ".npz":
        with np.load(path, allow_pickle=False) as data:
            if "scene" not in data.files:
                return None
            try:
                member = data["scene"]
            except ValueError as exc:
                raise ValueError(f"{name}: member 'scene' cannot be read without pickle: {exc}") from None
            return _scene_json(str(member), f"{name}: member 'scene'", wrapped=False)
    with open(path, encoding="utf-8") as fh:
        first = fh.readline()
    if not first.startswith(SCENE_TAG):
        return None
    return _scene_json(first[len(SCENE_TAG):], f"{name}: line 1", wrapped=True)


def _scene_json(text: str, where: str, wrapped: bool) -> dict[str, Any]:
    """A recorded scene from its JSON text (a CSV's line wraps it with its format_version)."""
    try:
        record = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{where} is not JSON: {exc}") from None
    if wrapped:
        if not isinstance(record, dict) or set(record) != {"format_version", "scene"} or record["format_version"] != 2:
            raise ValueError(f"{where} must be {{\"format_version\": 2, \"scene\": {{...}}}}, got {text.strip()[:200]!r}")
        record = record["scene"]
    if not isinstance(record, dict) or not all(isinstance(v, dict) for v in record.values()):
        raise ValueError(f"{where}: the scene must be a JSON object of sections (objects), got {str(record)[:200]!r}")
    return record


def scene_json(scene: dict[str, Any] | None) -> str:
    """``scene``'s sections as the JSON a log records (None: the id's own scene, ``{}``)."""
    try:
        return json.dumps(scene or {}, sort_keys=True, allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"scene={scene!r} cannot be recorded in a log: {exc} (use plain numbers, strings, lists "
                         "and dicts)") from None


def _check_member(archive: zipfile.ZipFile, member: zipfile.ZipInfo, key: str, name: str) -> None:
    """One NPZ member's size, from the zip directory and the ``.npy`` header alone: at most ``MAX_ROWS``
    numbers of at most 8 bytes (a header may claim anything; the inflated size must match it)."""
    limit = MAX_ROWS * 8 + 4096
    if member.file_size > limit:
        raise ValueError(f"{name}: member {key!r} inflates to {member.file_size:,} bytes; at most {limit:,} "
                         f"({MAX_ROWS:,} rows)")
    with archive.open(member) as fh:
        try:
            version = np.lib.format.read_magic(fh)
            shape, _, dtype = (np.lib.format.read_array_header_1_0(fh) if version == (1, 0)
                               else np.lib.format.read_array_header_2_0(fh))
        except ValueError as exc:
            raise ValueError(f"{name}: member {key!r} is not a .npy array: {exc}") from None
    if key == "scene":
        if shape != () or dtype.kind != "U" or dtype.itemsize > 4 * MAX_SCENE_CHARS:
            raise ValueError(f"{name}: member 'scene' declares shape {shape} of {dtype}; it is one string (JSON) of "
                             f"at most {MAX_SCENE_CHARS:,} characters")
        return
    count = int(np.prod(shape, dtype=object))
    if count > MAX_ROWS or dtype.itemsize > 8:
        raise ValueError(f"{name}: member {key!r} declares shape {shape} of {dtype}; at most {MAX_ROWS:,} numbers "
                         "of at most 8 bytes")


def _read_csv(path: Path, name: str, schema: Schema | None) -> tuple[Schema, np.ndarray, tuple[str, ...]]:
    with open(path, newline="", encoding="utf-8") as fh:
        rows = csv.reader(line for line in fh if not line.startswith("#"))
        header = [h.strip() for h in next(rows, [])]
        if not header:
            raise ValueError(f"{name} is empty; expected a header row")
        schema = _pick_schema(header, name, schema)
        optional = _optional_present(schema, header)
        wanted = schema.columns + optional
        index = [header.index(c) for c in wanted]
        table = np.empty((1024, len(wanted)))          # grown by doubling, up to MAX_ROWS rows
        n = 0
        for i, row in enumerate(rows, start=1):
            if i > MAX_ROWS:
                raise ValueError(f"{name} has more than {MAX_ROWS:,} rows; at most {MAX_ROWS:,} are read")
            if len(row) != len(header):
                raise ValueError(f"{name}: row {i} has {len(row)} fields; the header has {len(header)}")
            if n == len(table):
                table = np.concatenate([table, np.empty_like(table)])
            for j, (col, k) in enumerate(zip(wanted, index)):
                try:
                    table[n, j] = float(row[k])
                except ValueError:
                    raise ValueError(f"{name}: row {i}, column {col!r}: {row[k]!r} is not a number") from None
            n += 1
    return schema, table[:n], optional


def check_table(table: Any, schema: Schema, source: str = "trajectory") -> np.ndarray:
    """The rules every log shares, on an in-memory table: ``(n, 5)`` real numbers in the schema's
    column order, 2 to ``MAX_ROWS`` rows, finite, times strictly increasing over at most
    ``MAX_DURATION_S`` (counted from the first row: a device's own clock does not matter)."""
    try:
        table = np.asarray(table)
    except ValueError as exc:                        # ragged rows
        raise ValueError(f"{source} must be a table of real numbers with {len(schema.columns)} columns "
                         f"{list(schema.columns)}: {exc}") from None
    if table.ndim != 2 or table.shape[1] != len(schema.columns) or table.dtype.kind not in "iuf":
        raise ValueError(f"{source} must be a table of real numbers with {len(schema.columns)} columns "
                         f"{list(schema.columns)}, got shape {table.shape} and dtype {table.dtype}")
    if not 2 <= len(table) <= MAX_ROWS:
        raise ValueError(f"{source}: has {len(table):,} rows; a log has 2 to {MAX_ROWS:,}")
    table = table.astype(np.float64, copy=False)
    bad = ~np.isfinite(table)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise ValueError(f"{source}: row {i + 1}, column {schema.columns[j]!r} = {float(table[i, j])!r} is not finite")
    t = table[:, 0]
    if (np.diff(t) <= 0).any():
        i = int(np.argmax(np.diff(t) <= 0)) + 1
        raise ValueError(f"{source}: row {i + 1}, column 'time_s' = {float(t[i])!r}: times must be strictly "
                         f"increasing (row {i} has {float(t[i - 1])!r})")
    if t[-1] - t[0] > MAX_DURATION_S:
        raise ValueError(f"{source}: row {len(t)}, column 'time_s' = {t[-1]:g}: the log lasts {t[-1] - t[0]:g} s "
                         f"from its first row; at most {MAX_DURATION_S:g} s")
    return table


def check_limits(table: np.ndarray, schema: Schema, limits: dict[str, tuple[float, float]], source: str) -> None:
    """Each named column within its ``(low, high)``; the first violation names its row and column."""
    for col, (lo, hi) in limits.items():
        j = schema.columns.index(col)
        out = (table[:, j] < lo) | (table[:, j] > hi)
        if out.any():
            i = int(np.argmax(out))
            raise ValueError(f"{source}: row {i + 1}, column {col!r} = {table[i, j]:g} is outside the device range "
                             f"[{lo:g}, {hi:g}]")


def save_log(table: np.ndarray, path: str | Path, schema: Schema, note: str = "",
             scene: dict[str, Any] | None = None, readings: dict[str, Any] | None = None) -> None:
    """Write a log as CSV of ``format_version`` 2, recording ``scene`` (the sections over the schema's id;
    None: the id's own scene), with sensor ``readings`` (column -> a value a row: a hand-pose log's optional
    columns). Checked first; written atomically: a failed write leaves no short file."""
    table = check_table(table, schema)
    extra = dict(readings or {})
    if extra and schema is not HAND_LOG:
        raise ValueError(f"readings {sorted(extra)}: only a hand-pose log carries sensor readings")
    extra = check_readings(extra, len(table), f"log {str(path)!r}")
    names = [c for c in SENSOR_COLUMNS if c in extra]
    full = np.column_stack([table, *(extra[c] for c in names)])
    record = f'{SCENE_TAG}{{"format_version": 2, "scene": {scene_json(scene)}}}\n'

    def write(fh: Any) -> None:
        fh.write(record)
        if note:
            fh.write(f"# {note}\n")
        writer = csv.writer(fh)
        writer.writerow(schema.columns + tuple(names))
        for row in full:
            writer.writerow([f"{v:.9g}" for v in row])

    atomic_write(path, write, text=True)
