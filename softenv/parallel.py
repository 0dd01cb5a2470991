"""One way to fan out independent work: a list of :class:`Job` run in this process, over local worker
processes, or as Ray tasks on a cluster, with retries, progress and results in the jobs' order.

Every job must be a module-level function of picklable arguments whose result depends on its
arguments only (seeded from its key, never from run order), so that every executor gives the same
result bit for bit. Workers run BLAS, OpenMP and torch on one thread each: ``n`` workers use ``n``
cores and never oversubscribe them.

* ``executor="local"``: ``jobs=1`` runs in this process, one job after another; ``jobs=N`` starts N
  worker processes (``spawn``, so nothing of the parent's threads or locks is inherited).
* ``executor="ray"`` (``pip install 'softenv[ray]'``): ``ray.init()`` attaches to the cluster that
  ``RAY_ADDRESS`` names, or starts a local one with ``jobs`` CPUs. Each job is a Ray task of one
  CPU; the driver receives every result, so no shared file system is needed.

A job that raises is retried ``retries`` times, then reported as failed (:attr:`JobResult.error`),
never fatal to the others.

Nothing outlives the run: a local worker exits within a second of its parent's death (SIGKILL
included: it watches its parent) and ignores Ctrl-C, which is the parent's to handle. SIGINT or
SIGTERM to the parent raise :class:`Interrupted` out of :func:`run_jobs`, after the workers are
stopped (local) or the run's Ray tasks cancelled; ``on_result`` has seen every job finished by then,
so a caller that keeps them (``softenv compare``'s run directory) resumes where it stopped.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
import subprocess
import sys
import threading
import time
import traceback
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence

EXECUTORS = ("local", "ray")
THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS")
PARENT_POLL_S = 0.2          # how often a local worker looks for its parent (and for the stop signal)


class Interrupted(KeyboardInterrupt):
    """A run stopped by SIGINT (Ctrl-C) or SIGTERM. ``signum`` is the signal; a command line ends with
    exit status ``128 + signum`` (130, 143), as a shell reports a process the signal ended."""

    def __init__(self, signum: int, kept: str = "") -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum
        self.kept = kept                 # what the run kept, and how to resume: said by the caller that knows

    @property
    def exit_status(self) -> int:
        return 128 + self.signum


@contextlib.contextmanager
def stop_on_signals() -> Iterator[None]:
    """Within the block SIGINT and SIGTERM raise :class:`Interrupted` in the main thread (SIGTERM would
    otherwise end the process with no cleanup). Elsewhere than the main thread it does nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum: int, frame: Any) -> None:
        raise Interrupted(signum)

    previous = {sig: signal.signal(sig, interrupt) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


@dataclass(frozen=True)
class Job:
    """``fn(*args)`` under a unique, stable ``key`` (its name in progress lines and reports)."""

    key: str
    fn: Callable[..., Any]
    args: tuple = ()


@dataclass
class JobResult:
    key: str
    value: Any = None
    error: str | None = None           # "ExceptionType: message" of the last attempt; None when it succeeded
    attempts: int = 1
    wall_s: float = 0.0                 # the successful (or last) attempt's run time in its worker
    traceback: str = ""                 # of the last failed attempt

    @property
    def ok(self) -> bool:
        return self.error is None


def usable_cores() -> int:
    """Cores this process may run on (its affinity where the platform tells, else the CPU count)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:                      # pragma: no cover - macOS, Windows
        return max(1, os.cpu_count() or 1)


def describe(executor: str, jobs: int) -> str:
    """How a run fans out, in words for reports."""
    if executor == "ray":
        where = os.environ.get("RAY_ADDRESS")
        return f"Ray tasks ({'cluster ' + where if where else f'local Ray, {jobs} CPUs'})"
    return "one process, jobs in sequence" if jobs == 1 else f"{jobs} local worker processes"


def run_jobs(jobs: Sequence[Job], executor: str = "local", n_jobs: int = 1, retries: int = 1,
             echo: Callable[[str], None] | None = print,
             on_result: Callable[[JobResult], None] | None = None) -> list[JobResult]:
    """Run ``jobs``; return their results in the order given. ``echo`` gets one progress line per
    finished job: jobs done / total, the job's time and the estimated time left; ``on_result`` gets
    each finished job's result (successful or failed after its retries) as it comes, in this process.
    SIGINT or SIGTERM raise :class:`Interrupted` once every worker is stopped."""
    if executor not in EXECUTORS:
        raise ValueError(f"executor={executor!r}; choose from {list(EXECUTORS)}")
    if isinstance(n_jobs, bool) or not isinstance(n_jobs, int) or not 1 <= n_jobs <= 4096:
        raise ValueError(f"jobs={n_jobs!r} must be an int in [1, 4096]")
    if isinstance(retries, bool) or not isinstance(retries, int) or not 0 <= retries <= 100:
        raise ValueError(f"retries={retries!r} must be an int in [0, 100]")
    keys = [job.key for job in jobs]
    if len(set(keys)) != len(keys):
        raise ValueError("job keys must be unique; repeated: " + ", ".join(sorted({k for k in keys if keys.count(k) > 1})))
    progress = _Progress(len(jobs), echo, on_result)
    with stop_on_signals():
        if executor == "ray":
            return _run_ray(jobs, n_jobs, retries, progress)
        if n_jobs == 1:
            results = []
            for job in jobs:
                for attempt in range(1, retries + 2):
                    result = _attempt(job.key, job.fn, job.args)
                    result.attempts = attempt
                    if result.ok:
                        break
                results.append(progress.done(result))
            return results
        return _run_pool(jobs, n_jobs, retries, progress)


def pin_threads() -> None:
    """One BLAS/OpenMP/torch thread in this process (BLAS reads its variables when it loads, so they
    are also set for the processes started from here)."""
    os.environ.update({name: "1" for name in THREAD_VARS})
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(1)


def _attempt(key: str, fn: Callable[..., Any], args: tuple) -> JobResult:
    """Run one job, catching its failure (what a worker sends back)."""
    pin_threads()
    t0 = time.perf_counter()
    try:
        value = fn(*args)
    except Exception as exc:  # a job's failure is data for the report, not the end of the grid
        return JobResult(key, error=f"{type(exc).__name__}: {exc}", wall_s=time.perf_counter() - t0,
                         traceback=traceback.format_exc())
    return JobResult(key, value, wall_s=time.perf_counter() - t0)


def _watch_parent(parent: int, stop: Any) -> None:
    """A local worker's start: Ctrl-C is the parent's to handle; the worker ends itself at once when its
    parent is gone (killed, even by SIGKILL: it is then re-parented) or asks it to stop."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)

    def watch() -> None:
        while os.getppid() == parent and not stop.wait(PARENT_POLL_S):
            pass
        os._exit(1)                    # no cleanup to run: the job's files are committed by rename or not at all

    threading.Thread(target=watch, name="softenv-watch-parent", daemon=True).start()


def _run_pool(jobs: Sequence[Job], n_jobs: int, retries: int, progress: "_Progress") -> list[JobResult]:
    pin_threads()                      # inherited by the spawned workers before they load BLAS
    results: list[JobResult | None] = [None] * len(jobs)
    attempts = [0] * len(jobs)
    context = multiprocessing.get_context("spawn")
    stop = context.Event()
    pool = ProcessPoolExecutor(max_workers=min(n_jobs, max(len(jobs), 1)), mp_context=context,
                               initializer=_watch_parent, initargs=(os.getpid(), stop))
    try:
        def submit(i: int) -> Future:
            attempts[i] += 1
            future = pool.submit(_attempt, jobs[i].key, jobs[i].fn, jobs[i].args)
            pending[future] = i
            return future

        pending: dict[Future, int] = {}
        for i in range(len(jobs)):
            submit(i)
        while pending:
            finished, _ = wait(list(pending), return_when=FIRST_COMPLETED)
            for future in finished:
                i = pending.pop(future)
                exc = future.exception()
                result = future.result() if exc is None else JobResult(jobs[i].key, error=f"worker died: {exc!r}")
                if not result.ok and attempts[i] <= retries:
                    submit(i)
                    continue
                result.attempts = attempts[i]
                results[i] = progress.done(result)
    except BaseException:
        stop.set()                     # each worker ends itself within PARENT_POLL_S; the pool then reaps them
        pool.shutdown(cancel_futures=True)
        raise
    pool.shutdown()
    return [r for r in results if r is not None]


def _run_ray(jobs: Sequence[Job], n_jobs: int, retries: int, progress: "_Progress") -> list[JobResult]:
    try:
        import ray                                          # the ray extra
    except ImportError as exc:
        raise ValueError(f"executor='ray' needs Ray: pip install 'softenv[ray]' ({exc})") from exc
    started_here = not ray.is_initialized()
    if started_here:
        env = {"env_vars": {name: "1" for name in THREAD_VARS}}
        # a local instance's workers at the processes executor's priority: at Ray's default niceness (15) they got
        # a few percent of a core beside any other busy process (a tenth of their speed on a shared 2-core host)
        local: dict[str, Any] = {} if os.environ.get("RAY_ADDRESS") else {
            "num_cpus": n_jobs, "include_dashboard": False, "_system_config": {"worker_niceness": 0}}
        ray.init(runtime_env=env, log_to_driver=False, **local)
    # a local instance's own services would outlive a killed driver by a minute or more (its agents
    # wait on the dead head node): a watcher kills them the moment this process is gone
    reaper = _start_reaper() if started_here and not os.environ.get("RAY_ADDRESS") else None
    # _attempt catches the job's exception, so retry here on a failed result; Ray itself retries a task
    # whose worker or node died (max_retries)
    task = ray.remote(num_cpus=1, max_retries=retries)(_attempt)
    results: list[JobResult | None] = [None] * len(jobs)
    attempts = [0] * len(jobs)
    pending: dict[Any, int] = {}

    def submit(i: int) -> None:
        attempts[i] += 1
        pending[task.remote(jobs[i].key, jobs[i].fn, jobs[i].args)] = i

    try:
        for i in range(len(jobs)):
            submit(i)
        while pending:
            finished, _ = ray.wait(list(pending), num_returns=1)
            for ref in finished:
                i = pending.pop(ref)
                try:
                    result = ray.get(ref)
                except Exception as exc:  # the task's worker or node was lost after Ray's own retries
                    result = JobResult(jobs[i].key, error=f"Ray task lost: {type(exc).__name__}: {exc}")
                if not result.ok and attempts[i] <= retries:
                    submit(i)
                    continue
                result.attempts = attempts[i]
                results[i] = progress.done(result)
    except BaseException:
        if not started_here:           # a shared cluster: cancel this run's tasks (a local instance just ends)
            for ref in pending:
                ray.cancel(ref, force=True)
        raise
    finally:
        if started_here:
            ray.shutdown()
        if reaper is not None:
            reaper.kill()
            reaper.wait()
    return [r for r in results if r is not None]


def descendants(pid: int) -> set[int]:
    """The living descendants of ``pid`` (Linux ``/proc``; elsewhere none are known)."""
    found: set[int] = set()
    todo = [pid]
    while todo:
        for task in Path(f"/proc/{todo.pop()}/task").glob("*"):
            try:
                children = set(map(int, (task / "children").read_text().split()))
            except OSError:
                continue
            todo += children - found
            found |= children
    return found


def start_time(pid: int) -> str | None:
    """When ``pid`` started (clock ticks since boot, Linux): with the pid, a process's identity."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[19]
    except (OSError, IndexError):
        return None


_REAPER = """
import os, signal, sys, time
parent, marks = int(sys.argv[1]), [m.split(":") for m in sys.argv[2:]]
while os.getppid() == parent:
    time.sleep(0.2)
for pid, started in marks:
    try:
        with open(f"/proc/{pid}/stat") as f:
            if f.read().rsplit(")", 1)[1].split()[19] == started:
                os.kill(int(pid), signal.SIGKILL)
    except (OSError, IndexError):
        pass
"""


def _start_reaper() -> subprocess.Popen | None:
    """A process that kills this process's present descendants (by pid and start time, so a reused
    pid is spared) once this process is gone; ``None`` where ``/proc`` is not there to tell."""
    marks = [f"{pid}:{started}" for pid in sorted(descendants(os.getpid())) if (started := start_time(pid))]
    if not marks:
        return None
    return subprocess.Popen([sys.executable, "-c", _REAPER, str(os.getpid()), *marks], start_new_session=True,
                            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


class _Progress:
    def __init__(self, total: int, echo: Callable[[str], None] | None,
                 on_result: Callable[[JobResult], None] | None = None) -> None:
        self.total, self.count, self.echo, self.on_result = total, 0, echo, on_result
        self.start = time.perf_counter()

    def done(self, result: JobResult) -> JobResult:
        if self.on_result is not None:
            self.on_result(result)
        self.count += 1
        if self.echo is not None:
            elapsed = time.perf_counter() - self.start
            left = elapsed / self.count * (self.total - self.count)
            status = f"{result.wall_s:.0f} s" if result.ok else f"FAILED after {result.attempts} attempts: {result.error}"
            self.echo(f"[{self.count}/{self.total} jobs, {elapsed:.0f} s, ~{left:.0f} s left] {result.key}: {status}")
        return result
