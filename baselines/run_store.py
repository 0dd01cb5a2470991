"""A run directory's finished jobs (``<runs>/jobs/``): each job's result is saved the moment it
finishes and read back by the next run of the same plan, so a ``softenv compare`` that was stopped
(Ctrl-C, SIGTERM, a lost machine) resumes where it stopped and prints the table of a run that never
stopped, bit for bit but for the wall-clock columns.

An entry is an ``.npz`` artifact (no pickle, written by rename) named after its job's key. Its header
holds the job's fingerprint: the function, its arguments, softenv's version, a digest of the code
that computes results (the sources of ``softenv`` and ``baselines``, the agents' YAML) and the kernel
set numpy's OpenBLAS runs (``OPENBLAS_CORETYPE`` or the CPU picks it; it changes the last bits of every
product, so the report's command line names it). An entry whose fingerprint differs (another plan,
other settings, changed code, other BLAS kernels), or that cannot be read, is never used: its job runs
again and the new result replaces it.
"""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path
from typing import Any

import numpy as np

import softenv
from softenv._artifact import load_artifact, save_artifact
from softenv._blas import openblas_kernels
from softenv.parallel import Job, JobResult

from .evaluate import Episodes

ENTRY_KIND = "softenv-job-result"
ENTRY_VERSION = 1
_CODE_ROOTS = (Path(softenv.__file__).parent, Path(__file__).parent)


def code_digest() -> str:
    """SHA-256 of every ``.py`` and ``.yml`` file of ``softenv`` and ``baselines`` (paths and bytes)."""
    digest = hashlib.sha256()
    for root in _CODE_ROOTS:
        for path in sorted(p for p in root.rglob("*") if p.suffix in (".py", ".yml") and "__pycache__" not in p.parts):
            digest.update(f"{root.name}/{path.relative_to(root).as_posix()}\0".encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()


class RunStore:
    """The finished jobs of the runs under ``runs_dir`` (one file each in ``runs_dir/jobs``)."""

    def __init__(self, runs_dir: Path) -> None:
        self.dir = Path(runs_dir) / "jobs"
        self.code = code_digest()
        self.blas_kernels = openblas_kernels()

    def path(self, job: Job) -> Path:
        slug = re.sub(r"[^A-Za-z0-9.-]+", "_", job.key).strip("_")
        return self.dir / f"{slug}-{hashlib.sha256(job.key.encode()).hexdigest()[:8]}.npz"

    def fingerprint(self, job: Job) -> str:
        what = {"fn": f"{job.fn.__module__}.{job.fn.__qualname__}", "args": job.args, "softenv": softenv.__version__,
                "code": self.code, "blas_kernels": self.blas_kernels}
        return hashlib.sha256(json.dumps(what, sort_keys=True, default=str).encode()).hexdigest()

    def load(self, job: Job) -> tuple[JobResult | None, str]:
        """The job's stored result, or ``None`` and why not (``"absent"`` when no entry exists)."""
        path = self.path(job)
        if not path.exists():
            return None, "absent"
        try:
            arrays, meta = load_artifact(path, ENTRY_KIND, ENTRY_VERSION, finite_only=False)
            if meta.get("key") != job.key:
                return None, f"{path.name} holds job {meta.get('key')!r}"
            if meta.get("fingerprint") != self.fingerprint(job):
                return None, "made by other settings, other code or other BLAS kernels"
            value = _decode(meta["value"], arrays)
            return JobResult(job.key, value, attempts=int(meta["attempts"]), wall_s=float(meta["wall_s"])), ""
        except (ValueError, KeyError, TypeError, AttributeError) as exc:
            return None, f"unreadable ({exc})"

    def save(self, job: Job, result: JobResult) -> None:
        """Keep a successful result (a failed job runs again next time)."""
        if not result.ok:
            return
        arrays: dict[str, np.ndarray] = {}
        tree = _encode(result.value, arrays)
        save_artifact(self.path(job), ENTRY_KIND, ENTRY_VERSION, arrays,
                      {"key": job.key, "fingerprint": self.fingerprint(job), "value": tree,
                       "attempts": result.attempts, "wall_s": result.wall_s})


def _encode(value: Any, arrays: dict[str, np.ndarray]) -> Any:
    """A job's result as JSON, its arrays moved to ``arrays``: None, numbers, strings, arrays, tuples,
    lists and :class:`Episodes`, the types the benchmark's jobs return."""
    if value is None or isinstance(value, (bool, int, float, str)):
        return {"value": value}
    if isinstance(value, np.ndarray):
        name = f"a{len(arrays)}"
        arrays[name] = value
        return {"array": name}
    if isinstance(value, (tuple, list)):
        return {type(value).__name__: [_encode(v, arrays) for v in value]}
    if isinstance(value, Episodes):
        return {"episodes": {"policy": value.policy, "scene": value.scene, "decision_us": value.decision_us,
                             "values": {k: _encode(v, arrays) for k, v in value.values.items()}}}
    raise TypeError(f"a job result of type {type(value).__name__} cannot be stored")


def _decode(tree: Any, arrays: dict[str, np.ndarray]) -> Any:
    (tag, body), = tree.items()
    if tag == "value":
        return body
    if tag == "array":
        return arrays[body]
    if tag in ("tuple", "list"):
        items = [_decode(v, arrays) for v in body]
        return tuple(items) if tag == "tuple" else items
    if tag == "episodes":
        return Episodes(body["policy"], body["scene"], {k: _decode(v, arrays) for k, v in body["values"].items()},
                        float(body["decision_us"]))
    raise ValueError(f"unknown entry {tag!r}")
