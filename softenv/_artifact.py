"""Versioned, pickle-free ``.npz`` artifacts with atomic saving.

Every file softenv writes is an ``.npz`` holding plain arrays plus one JSON string under
``__meta__`` with the artifact's ``kind`` and ``format_version``. Loading never enables pickle and
checks kind and version before anything else is read, so a corrupt, foreign or stale file fails with
a message naming the file, what was found and what was expected.
"""

from __future__ import annotations

import json
import os
import tempfile
import zipfile
from pathlib import Path
from typing import IO, Any, Callable

import numpy as np

_META_KEY = "__meta__"
STAMP_MEMBER = "built_from.txt"     # a cache entry's digest (softenv._cache), not an array


def save_artifact(path: str | os.PathLike, kind: str, version: int,
                  arrays: dict[str, np.ndarray], meta: dict[str, Any]) -> Path:
    """Write ``arrays`` and ``meta`` to ``path`` atomically (temporary file, then rename)."""
    path = Path(path)
    if path.suffix != ".npz":
        raise ValueError(f"path must end in .npz, got {str(path)!r}")
    header = dict(meta, kind=kind, format_version=int(version))
    payload = {name: np.asarray(a) for name, a in arrays.items()}
    for name, a in payload.items():
        if a.dtype.kind == "O":
            raise ValueError(f"artifact array {name!r} has dtype object, which cannot be saved without pickle")
    payload[_META_KEY] = np.array(json.dumps(header, sort_keys=True))
    return atomic_write(path, lambda handle: np.savez(handle, **payload))  # type: ignore[arg-type]  # (stub: **kwds)


Writer = Callable[[IO[Any]], Any]


def atomic_write(path: str | os.PathLike, write: Writer, text: bool = False) -> Path:
    """Write a file through ``write(handle)`` into a temporary file beside ``path``, then rename it over
    ``path``: a failed write leaves the old file (or none), never a short one. The file gets the mode
    ``open()`` would give it (0666 less the umask), not ``mkstemp``'s 0600."""
    return atomic_write_all([(Path(path), write, text)])[0]


def write_text(path: str | os.PathLike, text: str) -> Path:
    """:func:`atomic_write` of a text file."""
    return atomic_write(path, lambda handle: handle.write(text), text=True)


def save_figure(fig: Any, path: str | os.PathLike, **savefig: Any) -> Path:
    """:func:`atomic_write` of a matplotlib figure, in the format its suffix names."""
    return atomic_write(path, lambda handle: fig.savefig(handle, format=Path(path).suffix[1:], **savefig))


def atomic_write_all(files: list[tuple[Path, Writer, bool]]) -> list[Path]:
    """Write a set of files (path, ``write(handle)``, text) all or nothing: each into a temporary file
    beside it, then, once every write has succeeded, each renamed into place; a failed write removes the
    temporary files and leaves every path as it was."""
    written: list[tuple[str, Path]] = []
    try:
        for path, write, text in files:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
            written.append((tmp, path))
            os.fchmod(fd, 0o666 & ~_umask())
            with (os.fdopen(fd, "w", newline="") if text else os.fdopen(fd, "wb")) as handle:
                write(handle)
        for tmp, path in written:
            os.replace(tmp, path)
    except BaseException:
        for tmp, _ in written:
            Path(tmp).unlink(missing_ok=True)
        raise
    return [path for _, path in written]


def check_out_dir(path: str | os.PathLike, name: str = "out") -> Path:
    """An output directory: absent (made when written) or a directory, never an existing file."""
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise ValueError(f"{name} {str(out)!r} exists and is not a directory; give a directory (made if absent)")
    return out


def _umask() -> int:
    mask = os.umask(0o022)        # the only way to read it is to set it; put it straight back
    os.umask(mask)
    return mask


def load_artifact(path: str | os.PathLike, kind: str, version: int, *, header_only: bool = False,
                  finite_only: bool = True) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Read an artifact written by :func:`save_artifact`, checking its kind and format version.
    ``header_only``: check and return the header, read no array (the arrays come back empty).
    ``finite_only=False``: NaN and infinities are data (a metric an episode never reached)."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"path {str(path)!r} does not exist or is not a file")
    try:
        with path.open("rb") as handle, np.load(handle, allow_pickle=False) as data:   # numpy leaks its own handle on a bad zip
            if _META_KEY not in data.files:
                raise ValueError(f"{str(path)!r} is not a softenv artifact (no {_META_KEY!r} entry)")
            meta = json.loads(str(data[_META_KEY][()]))
            arrays = {} if header_only else {name: data[name] for name in data.files
                                             if name not in (_META_KEY, STAMP_MEMBER)}
    except (zipfile.BadZipFile, OSError, EOFError, json.JSONDecodeError, KeyError) as exc:
        raise ValueError(f"{str(path)!r} is corrupt or not an .npz artifact: {exc}") from exc
    except ValueError as exc:
        if "softenv artifact" in str(exc):
            raise
        raise ValueError(f"{str(path)!r} could not be read without pickle: {exc}") from exc
    if not isinstance(meta, dict):
        raise ValueError(f"{str(path)!r} has a header of type {type(meta).__name__}; expected a JSON object")
    for name, a in arrays.items():            # every loader gets real (and finite) arrays or nothing
        if a.dtype.kind not in "biuf":
            raise ValueError(f"{str(path)!r}: array {name!r} has dtype {a.dtype}; expected real numbers")
        if finite_only and a.dtype.kind == "f" and not np.isfinite(a).all():
            index = tuple(int(i) for i in np.argwhere(~np.isfinite(a))[0])
            raise ValueError(f"{str(path)!r}: array {name!r} has {float(a[index])!r} at index {index}; artifacts hold "
                             "finite numbers only")
    found_kind, found_version = meta.get("kind"), meta.get("format_version")
    if found_kind != kind:
        raise ValueError(f"{str(path)!r} holds a {found_kind!r} artifact; expected {kind!r}")
    if found_version != version:
        raise ValueError(f"{str(path)!r} has format_version={found_version!r}; this softenv reads "
                         f"{kind!r} format_version={version} only (re-create the file)")
    return arrays, meta


def require_arrays(arrays: dict[str, np.ndarray], names: list[str], path: str | os.PathLike) -> None:
    """Raise if an artifact lacks one of the arrays its loader needs."""
    missing = [n for n in names if n not in arrays]
    if missing:
        raise ValueError(f"{str(path)!r} is missing arrays {missing}; the file is corrupt or incomplete")
