"""On-disk cache for expensive, deterministic artifacts (datasets, response tables).

Entries are keyed by a digest of everything that determines them (parameters plus a physics
version), so a stale entry is never read; a repeat request is a file read. The directory is
``$SOFTENV_CACHE_DIR`` if set, else ``~/.cache/softenv``. Writes are atomic, so parallel workers
(async vector envs) can share it.
"""

from __future__ import annotations

import hashlib
import json
import os
import warnings
from pathlib import Path
from typing import Any, Callable, TypeVar

T = TypeVar("T")

# Bump when the tissue model, sampling or tabulation changes results: every cached entry is rebuilt.
PHYSICS_VERSION = 1


def cache_dir() -> Path:
    """The cache directory (created on demand)."""
    root = os.environ.get("SOFTENV_CACHE_DIR")
    path = Path(root) if root else Path.home() / ".cache" / "softenv"
    path.mkdir(parents=True, exist_ok=True)
    return path


def cache_key(kind: str, params: dict[str, Any]) -> str:
    """A stable file stem for ``kind`` and ``params`` (JSON-serialisable)."""
    text = json.dumps({"kind": kind, "physics": PHYSICS_VERSION, **params}, sort_keys=True, default=str)
    return f"{kind}-{hashlib.sha256(text.encode()).hexdigest()[:20]}"


def cached(kind: str, params: dict[str, Any], build: Callable[[], T],
           load: Callable[[Path], T], save: Callable[[T, Path], Any], enabled: bool = True) -> T:
    """Return the cached artifact for ``(kind, params)``, building and saving it on a miss.

    A corrupt or unreadable entry is rebuilt (with a warning), never trusted.
    """
    if not enabled:
        return build()
    path = cache_dir() / f"{cache_key(kind, params)}.npz"
    if path.exists():
        try:
            return load(path)
        except ValueError as exc:
            warnings.warn(f"rebuilding unreadable cache entry {path}: {exc}", RuntimeWarning, stacklevel=2)
    value = build()
    save(value, path)
    return value
