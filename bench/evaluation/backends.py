"""Execution backends of the evaluation runner: where its jobs run.

A **job** is one method on a chunk of one task's seeds (:class:`Job`); the runner makes
the jobs and merges what they return, a backend only decides where they run:

* ``serial`` — here, one after another;
* ``process`` — a spawn ``ProcessPoolExecutor`` of ``workers`` processes on this machine;
* ``ray`` — one ``@ray.remote`` task per job, gathered with ``ray.wait``, on the Ray
  cluster at ``address`` (``auto``: the one ``ray start`` runs on this node, or
  ``HOST:PORT``), on the one this process is already connected to, or else on a local
  cluster of ``workers`` CPUs started here and stopped afterwards. A method's weights
  file (with its ``<stem>.json`` record) is put once in the object store and written to
  each worker node's temporary folder, so nodes need not share a file system (they do
  need swarmloc installed).

Every random draw is keyed by (seed, step, stream, index), so a job's numbers do not
depend on where it runs nor on how seeds are chunked: the backends give identical
per-episode metrics. Ray is imported only by the ``ray`` backend (an optional extra,
``pip install "swarmloc[ray]"``).

**Faults.** A job whose method raises is reported failed with its error
(``on_failure``), the other jobs go on. A worker process that dies is retried up to
:data:`MAX_RETRIES` times (Ray's task ``max_retries``; for ``process`` the broken pool
is rebuilt and the unfinished jobs resubmitted). ``KeyboardInterrupt`` cancels the
outstanding jobs (``ray.cancel``, or the pool's workers are stopped) and propagates, so
the runner writes nothing.
"""

from __future__ import annotations

import hashlib
import multiprocessing
import os
import signal
import sys
import tempfile
import traceback
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

Backend = Literal["serial", "process", "ray"]
BACKENDS: tuple[str, ...] = ("serial", "process", "ray")
MAX_WORKERS = 64

MAX_RETRIES = 3
"""Times a job is re-run after its worker process died (not after its method raised)."""


@dataclass(frozen=True)
class Job:
    """One method on a chunk of one task's seeds.

    Attributes:
        task: task ID.
        method: method name or entry point.
        seeds: the chunk's seeds, in suite order.
        trace: keep the trace of the chunk's first seed (set on the task's first chunk).
        overrides: task-spec field overrides (shortened episodes in tests), or None.
    """

    task: str
    method: str
    seeds: tuple[int, ...]
    trace: bool = False
    overrides: Mapping[str, Any] | None = field(default=None, hash=False)


@dataclass(frozen=True)
class JobFailure:
    """A job that did not return: its method raised, or its worker died too often.

    Attributes:
        job: the job.
        error: ``"ExceptionType: message"``.
        details: the traceback (or Ray's report), for logs.
    """

    job: Job
    error: str
    details: str = ""


#: what the runner asks a backend to run: ``fn(job, weights file or None) -> result`` (picklable, top level)
JobFunction = Callable[[Job, "str | None"], Any]


def _guarded(fn: JobFunction, job: Job, weights: str | None) -> tuple[bool, Any]:
    """Run a job where it lands; an exception becomes ``(False, (error, traceback))``.

    Formatting the error in the worker keeps exceptions that do not pickle (or whose
    class the driver cannot import) from turning into a second, confusing error.
    """
    try:
        return True, fn(job, weights)
    except Exception as err:  # noqa: BLE001  (the job failed, the worker is fine: report it, go on)
        return False, (f"{type(err).__name__}: {err}", traceback.format_exc())


def _report(job: Job, outcome: tuple[bool, Any], on_result: Callable[[Job, Any], None],
            on_failure: Callable[[JobFailure], None]) -> None:
    ok, value = outcome
    if ok:
        on_result(job, value)
    else:
        on_failure(JobFailure(job, *value))


def check_backend(backend: str | None, workers: int, address: str | None) -> Backend:
    """The backend to use, after refusing a bad combination of options before any work.

    Args:
        backend: ``serial``, ``process``, ``ray``, or None: ``serial`` for one worker, else ``process``.
        workers: in [1, 64].
        address: a Ray cluster address (``ray`` only) or None.

    Returns:
        The backend.

    Raises:
        ValueError: naming the bad value and the allowed ones.
    """
    if backend is None:
        backend = "serial" if workers == 1 else "process"
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {', '.join(BACKENDS)}; got {backend!r}")
    if not 1 <= workers <= MAX_WORKERS:
        raise ValueError(f"workers must be in [1, {MAX_WORKERS}], got {workers}")
    if address is not None and backend != "ray":
        raise ValueError(f"address={address!r} names a Ray cluster; it needs backend='ray', got {backend!r}")
    return backend  # type: ignore[return-value]


def run_jobs(fn: JobFunction, jobs: Sequence[Job], *, backend: Backend = "serial", workers: int = 1,
             weights: Mapping[str, str | None] | None = None, address: str | None = None,
             on_result: Callable[[Job, Any], None], on_failure: Callable[[JobFailure], None]) -> None:
    """Run every job on a backend; report each as it finishes (in completion order).

    Args:
        fn: the job function, ``fn(job, weights) -> result`` (a top-level function of an
            importable module, so that workers can unpickle it).
        jobs: the jobs, in the order to start them (costliest first balances best).
        backend: ``serial``, ``process`` or ``ray``.
        workers: worker processes (``process``), or the CPUs of a local Ray cluster.
        weights: method → weights file (None: the method's default).
        address: Ray cluster to join (``auto`` or ``HOST:PORT``; ``ray`` only).
        on_result: called with ``(job, result)`` in this process.
        on_failure: called with a :class:`JobFailure` in this process.

    Raises:
        ValueError: bad backend, workers or address.
        ImportError: ``ray`` without Ray installed (the message says how to install it).
        KeyboardInterrupt: after cancelling the outstanding jobs.
    """
    backend = check_backend(backend, workers, address)
    weights = dict(weights or {})
    if backend == "serial":
        for job in jobs:
            _report(job, _guarded(fn, job, weights.get(job.method)), on_result, on_failure)
    elif backend == "process":
        _run_process(fn, list(jobs), workers, weights, on_result, on_failure)
    else:
        _run_ray(fn, list(jobs), workers, weights, address, on_result, on_failure)


# --------------------------------------------------------------------------- process


def worker_init() -> None:
    """Spawned workers run numba, and torch where a job loads it, single-threaded (the
    parallelism is across jobs) and leave Ctrl-C to the parent, which stops them.

    With torch's default threads (one per core), two workers running `mappo` each spin two
    OpenMP threads on two cores: quick-v1 ran 4.4× slower than in one process. A worker
    imports torch only when its first job loads a method that uses it, so its thread count
    is set then, by ``pin_torch_threads``, once and never switched back.
    """
    import numba

    numba.set_num_threads(1)
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def pin_torch_threads() -> None:
    """Put torch on one thread if a job has imported it (a no-op without torch, and after the first
    time). Call it after loading a method and before running it.

    In every process, the caller's included: a threaded matrix product may sum in an order that
    depends on the thread count (MKL on AVX-512 CPUs), and a learned method must act the same on
    every backend. In a pool worker it also keeps two workers from spinning four threads on two cores.
    """
    torch = sys.modules.get("torch")
    if torch is not None and torch.get_num_threads() != 1:
        torch.set_num_threads(1)


def _stop_workers(pool: ProcessPoolExecutor) -> None:
    """Cancel queued jobs and stop the pool's processes now (their running jobs are abandoned)."""
    kill = getattr(pool, "kill_workers", None)  # Python ≥ 3.14
    if kill is not None:
        kill()
    else:  # before shutdown, which forgets the processes (and would leave them running their jobs)
        for process in list((getattr(pool, "_processes", None) or {}).values()):
            process.kill()
    pool.shutdown(wait=False, cancel_futures=True)


def _run_process(fn: JobFunction, jobs: list[Job], workers: int, weights: Mapping[str, str | None],
                 on_result: Callable[[Job, Any], None], on_failure: Callable[[JobFailure], None]) -> None:
    """Jobs on a spawn pool; a pool broken by a dead worker is rebuilt for the unfinished jobs."""
    ctx = multiprocessing.get_context("spawn")
    attempts = [0] * len(jobs)
    todo = list(range(len(jobs)))
    while todo:
        pool = ProcessPoolExecutor(max_workers=min(workers, len(todo)), mp_context=ctx, initializer=worker_init)
        try:
            futures = {pool.submit(_guarded, fn, jobs[i], weights.get(jobs[i].method)): i for i in todo}
            todo = []
            for future in as_completed(futures):
                i = futures[future]
                try:
                    outcome = future.result()
                except BrokenProcessPool:  # a worker died: this job and every unfinished one come here
                    attempts[i] += 1
                    if attempts[i] <= MAX_RETRIES:
                        todo.append(i)
                    else:
                        on_failure(JobFailure(jobs[i], f"worker process died {attempts[i]} times running it"))
                    continue
                _report(jobs[i], outcome, on_result, on_failure)
        except BaseException:
            _stop_workers(pool)
            raise
        pool.shutdown(wait=True)
        todo.sort()  # keep the costliest-first order on the retry


# --------------------------------------------------------------------------- ray


def import_ray() -> Any:
    """``import ray``, or an ImportError that says how to install it."""
    try:
        import ray
    except ImportError as err:
        raise ImportError('the ray backend needs Ray: pip install "swarmloc[ray]" (or pip install "ray[default]")'
                          ) from err
    return ray


#: object store of a local cluster: jobs move metrics and weights, not data sets (Ray's default is 30 % of RAM)
LOCAL_OBJECT_STORE_BYTES = 256 * 1024**2


def connect_ray(address: str | None, num_cpus: int) -> bool:
    """Connect this process to a Ray cluster; returns True when it started one (to shut down after).

    Args:
        address: ``auto`` (the cluster ``ray start`` runs on this node) or ``HOST:PORT``;
            None: the cluster this process is already connected to, else the one
            ``RAY_ADDRESS`` names (as under ``ray job submit``), else a new local one.
        num_cpus: CPUs of a new local cluster.
    """
    ray = import_ray()
    if ray.is_initialized():
        if address is not None:
            raise RuntimeError(f"this process is already connected to a Ray cluster; cannot join {address!r} too")
        return False
    address = address or os.environ.get("RAY_ADDRESS") or None
    if address is not None:
        ray.init(address=address, logging_level="warning")
        return False
    ray.init(address="local", num_cpus=num_cpus, include_dashboard=False, logging_level="warning",
             object_store_memory=LOCAL_OBJECT_STORE_BYTES)
    return True


def cancel_outstanding(refs: Sequence[Any]) -> None:
    """Force-cancel the Ray tasks of ``refs`` that have not finished; finished ones are left alone.

    Ray 2.60's owner aborts (``Check failed: it != submissible_tasks_.end() Tried to
    complete task that was not pending``, task_manager.cc) when a cancellation races with
    the reply of a task that is finishing; the driver process dies with it. We saw it kill a
    test process after a failed verification cancelled its sibling chunks. Skipping the
    tasks whose result is already here narrows the window to a task whose reply is in
    flight; callers cancel only when they must stop (Ctrl-C), never to end a run early.
    """
    if not refs:
        return
    ray = import_ray()
    _, running = ray.wait(list(refs), num_returns=len(refs), timeout=0)
    for ref in running:
        ray.cancel(ref, force=True)


def weights_bundle(path: str | os.PathLike[str]) -> dict[str, bytes]:
    """A weights file and the provenance record beside it (``<stem>.json``, which factories may read), by name."""
    path = Path(path)
    bundle = {path.name: path.read_bytes()}
    record = path.with_suffix(".json")
    if record != path and record.is_file():
        bundle[record.name] = record.read_bytes()
    return bundle


def local_weights(bundle: Mapping[str, bytes], name: str) -> str:
    """A weights bundle as files on this node, written once; returns the path of ``name``.

    The folder is ``<tmp>/swarmloc-weights/<digest of the bundle>/``, so workers on one node share it.
    """
    from swarmloc.bench.common.files import write_bytes_atomic

    digest = hashlib.sha256()
    for file_name in sorted(bundle):
        digest.update(file_name.encode() + b"\0" + hashlib.sha256(bundle[file_name]).digest())
    folder = Path(tempfile.gettempdir()) / "swarmloc-weights" / digest.hexdigest()[:32]
    folder.mkdir(parents=True, exist_ok=True)
    for file_name, data in bundle.items():
        if not (folder / file_name).exists():
            write_bytes_atomic(folder / file_name, data)
    return str(folder / name)


def _ray_job(fn: JobFunction, job: Job, weights: Mapping[str, bytes] | None, weights_name: str | None,
             driver_path: list[str]) -> tuple[bool, Any]:
    """A job inside a Ray worker (the body of the remote task)."""
    import sys

    import numba

    numba.set_num_threads(1)
    # methods given as `module:factory` import from the driver's path, as in spawned workers
    sys.path.extend(p for p in driver_path if p not in sys.path)
    path = None if weights is None or weights_name is None else local_weights(weights, weights_name)
    return _guarded(fn, job, path)


def _run_ray(fn: JobFunction, jobs: list[Job], workers: int, weights: Mapping[str, str | None], address: str | None,
             on_result: Callable[[Job, Any], None], on_failure: Callable[[JobFailure], None]) -> None:
    """One remote task per job, results gathered with ``ray.wait``; Ctrl-C cancels the rest."""
    import sys

    ray = import_ray()
    started = connect_ray(address, workers)
    by_ref: dict[Any, Job] = {}  # the outstanding tasks
    try:
        remote = ray.remote(num_cpus=1, max_retries=MAX_RETRIES, retry_exceptions=False)(_ray_job)
        blobs = {m: (ray.put(weights_bundle(w)), Path(w).name) for m, w in weights.items() if w is not None}
        driver_path = [p for p in sys.path if p and Path(p).is_dir()]
        for job in jobs:
            blob, name = blobs.get(job.method, (None, None))
            by_ref[remote.remote(fn, job, blob, name, driver_path)] = job
        pending = list(by_ref)
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            for ref in ready:
                job = by_ref.pop(ref)
                try:
                    outcome = ray.get(ref)
                except ray.exceptions.RayError as err:  # its worker died more than MAX_RETRIES times, …
                    on_failure(JobFailure(job, f"{type(err).__name__}: {str(err).splitlines()[0]}", str(err)))
                    continue
                _report(job, outcome, on_result, on_failure)
    except BaseException:
        cancel_outstanding(list(by_ref))
        raise
    finally:
        if started:
            ray.shutdown()


__all__ = [
    "BACKENDS",
    "MAX_RETRIES",
    "Backend",
    "Job",
    "JobFailure",
    "cancel_outstanding",
    "check_backend",
    "connect_ray",
    "import_ray",
    "run_jobs",
]
