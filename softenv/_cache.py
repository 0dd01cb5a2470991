"""On-disk cache for expensive, deterministic artifacts (datasets, response tables).

Entries are keyed by a digest of everything that determines them (parameters plus a physics
version), so a stale entry is never read; a repeat request is a file read. The directory is
``$SOFTENV_CACHE_DIR`` if set, else ``~/.cache/softenv``. Writes are atomic, so parallel workers
(async vector envs) can share it.

An entry is built on one thread (BLAS and OpenMP, by threadpoolctl where installed; torch, whose MKL
is linked into it out of threadpoolctl's reach, by its own call): multi-threaded LAPACK and torch round
differently, and an entry's bits must not depend on the threads of whichever process built it first
(docs: how it works). Without threadpoolctl, a process whose thread variables are not all 1 builds on
its own threads, with a warning.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import warnings
import zipfile
from contextlib import contextmanager, nullcontext
from pathlib import Path
from typing import Any, Callable, Iterator, TypeVar

from ._artifact import STAMP_MEMBER as _STAMP
from .parallel import THREAD_VARS, pin_threads

try:  # in the rl, device and fem extras; the core stays numpy and gymnasium
    from threadpoolctl import threadpool_limits
except ImportError:  # pragma: no cover - exercised by monkeypatching in tests
    threadpool_limits = None

T = TypeVar("T")

# Bump when the tissue model, sampling or tabulation changes results: every cached entry is rebuilt.
# 2: entries built on one thread (version 1's could hold the last bits of a multi-threaded build)
# 3: torch too (version 2's MLPs trained on MKL_NUM_THREADS threads: other weights where that was not 1)
PHYSICS_VERSION = 3


def cache_dir() -> Path:
    """The cache directory (created on demand)."""
    root = os.environ.get("SOFTENV_CACHE_DIR")
    path = Path(root) if root else Path.home() / ".cache" / "softenv"
    path.mkdir(parents=True, exist_ok=True)
    return path


def cache_key(kind: str, params: dict[str, Any]) -> str:
    """A stable file stem for ``kind`` and ``params`` (JSON-serialisable)."""
    return f"{kind}-{_digest(kind, params)[:20]}"


def _digest(kind: str, params: dict[str, Any]) -> str:
    """The full digest of everything an entry is built from (its file name holds the first 20 digits)."""
    text = json.dumps({"kind": kind, "physics": PHYSICS_VERSION, **params}, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def cached(kind: str, params: dict[str, Any], build: Callable[[], T],
           load: Callable[[Path], T], save: Callable[[T, Path], Any], enabled: bool = True) -> T:
    """Return the cached artifact for ``(kind, params)``, building and saving it on a miss.

    Every entry carries the full digest of what it was built from (a ``built_from`` member of its
    ``.npz``) and is used only when that digest is the one asked for: a corrupt, unreadable, stale or
    swapped-in entry (another scene's table, another tissue's shape model under this name) is rebuilt
    with a warning, never trusted.
    """
    if not enabled:
        return _build_on_one_thread(build)
    digest = _digest(kind, params)
    path = cache_dir() / f"{kind}-{digest[:20]}.npz"
    if path.exists():
        try:
            found = built_from(path)
            if found != digest:
                raise ValueError("it records no build digest (an older softenv made it)" if found is None else
                                 f"it was built from config {found[:20]}..., not from this one ({digest[:20]}...)")
            return load(path)
        except (ValueError, KeyError, TypeError, AttributeError, OSError, EOFError, zipfile.BadZipFile) as exc:
            warnings.warn(f"rebuilding unreadable cache entry {path}: {exc}", RuntimeWarning, stacklevel=2)
    value = _build_on_one_thread(build)
    # saved beside, stamped, then renamed: readers see a whole, stamped entry or none
    tmp = path.with_name(f"{path.stem}.{os.getpid()}.building.npz")
    try:
        save(value, tmp)
        with zipfile.ZipFile(tmp, "a") as archive:
            archive.writestr(_STAMP, digest)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return value


def _build_on_one_thread(build: Callable[[], T]) -> T:
    if threadpool_limits is None and not all(os.environ.get(name) == "1" for name in THREAD_VARS):
        warnings.warn("building a cache entry on this process's BLAS/OpenMP threads: its last bits depend on "
                      f"them; install threadpoolctl (softenv[rl], [device] or [fem]) or set {', '.join(THREAD_VARS)}"
                      " to 1", RuntimeWarning, stacklevel=3)
    with _torch_on_one_thread(), (threadpool_limits(limits=1) if threadpool_limits is not None else nullcontext()):
        return build()


@contextmanager
def _torch_on_one_thread() -> Iterator[None]:
    """torch on one thread for the block, then back to its threads. torch sets OpenMP's threads from its
    MKL's on first use, so threadpoolctl's limit alone leaves an L-BFGS-trained MLP on MKL_NUM_THREADS
    threads; the variables are 1 meanwhile so that a torch first imported inside the block starts on one."""
    saved = {name: os.environ.get(name) for name in THREAD_VARS}
    torch = sys.modules.get("torch")
    threads = torch.get_num_threads() if torch is not None else None
    pin_threads()
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value
        torch = sys.modules.get("torch")
        if torch is not None:
            torch.set_num_threads(threads if threads is not None else _torch_default_threads(saved))


def _torch_default_threads(variables: dict[str, str | None]) -> int:
    """The threads torch takes when it loads under ``variables``, as its MKL counts them: MKL_NUM_THREADS,
    else OMP_NUM_THREADS, at most the CPUs; else one a CPU."""
    cpus = os.cpu_count() or 1
    for name in ("MKL_NUM_THREADS", "OMP_NUM_THREADS"):
        value = variables.get(name) or ""
        if value.isdigit() and int(value) > 0:
            return min(int(value), cpus)
    return cpus


def built_from(path: Path) -> str | None:
    """The digest a cache entry records, or None for a file without one."""
    with zipfile.ZipFile(path) as archive:
        try:
            return archive.read(_STAMP).decode()
        except KeyError:
            return None
