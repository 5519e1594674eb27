"""Leaderboard verification on a Ray cluster: the sandboxed re-runs as Ray tasks.

``swarmloc submit --backend ray`` hands :func:`~swarmloc.leaderboard.verify.verification.verify_results`
the ``rerun`` made by :func:`ray_rerun` instead of
:func:`~swarmloc.leaderboard.verify.rerun.run_in_worker`. The sample is split by task into one
chunk per CPU of the cluster (at most one chunk per task); each chunk is one Ray task
that calls ``run_in_worker`` on the node it lands on, so every re-run keeps the
leaderboard's sandbox rules unchanged (two bubblewrap sandboxes, read-only view, no
network, the limits — which then apply to each chunk's re-run). The chunks' episodes are
merged in sample order and compared with the submitted ones as usual.

Nodes read the method's files, weights and search path at the paths this process
names (one node, or a shared file system), and need swarmloc and bubblewrap installed.
A chunk whose Ray worker dies is retried (``max_retries``); a chunk whose re-run fails
(crash, time-out, bad output, no sandbox) fails the verification with its message, once
every chunk has ended (the first failure's message).
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from typing import Any

from swarmloc.leaderboard import errors
from swarmloc.leaderboard.errors import SubmissionError, VerificationFailed
from swarmloc.leaderboard.verify.rerun import run_in_worker
from swarmloc.leaderboard.verify.verification import Rerun


def split_sample(episodes: Sequence[tuple[str, int]], n_chunks: int) -> list[list[tuple[str, int]]]:
    """Split a sample into at most ``n_chunks`` chunks, whole tasks each, of balanced size.

    Args:
        episodes: (task, seed) pairs.
        n_chunks: at least 1.

    Returns:
        The non-empty chunks (the largest task groups placed first, each into the smallest chunk).
    """
    if n_chunks < 1:
        raise ValueError(f"n_chunks must be at least 1, got {n_chunks}")
    by_task: dict[str, list[tuple[str, int]]] = {}
    for task, seed in episodes:
        by_task.setdefault(task, []).append((task, int(seed)))
    chunks: list[list[tuple[str, int]]] = [[] for _ in range(min(n_chunks, len(by_task)))]
    for group in sorted(by_task.values(), key=len, reverse=True):
        min(chunks, key=len).extend(group)
    return [c for c in chunks if c]


def _rerun_chunk(method: str, episodes: list[tuple[str, int]], options: dict[str, Any]) -> tuple[bool, Any]:
    """One chunk's sandboxed re-run, inside a Ray task; a refusal comes back as (class name, message)."""
    try:
        return True, run_in_worker(method, episodes, **options)
    except SubmissionError as err:  # VerificationFailed, SandboxUnavailable: re-raised by the driver
        return False, (type(err).__name__, str(err))


def ray_rerun(address: str | None = None, num_cpus: int | None = None) -> Rerun:
    """A drop-in for ``run_in_worker`` that re-runs the sample as Ray tasks.

    Args:
        address: Ray cluster to join (``auto`` or ``HOST:PORT``); None: the one this
            process is connected to, else ``RAY_ADDRESS``, else a local cluster.
        num_cpus: CPUs of a local cluster (default: every CPU here).

    Returns:
        ``rerun(entry_point, episodes, **options) -> (episodes, wall_s)``.
    """

    def rerun(method: str, episodes: Sequence[tuple[str, int]], **options: Any) -> tuple[list[dict], float]:
        from swarmloc.bench.evaluation.backends import MAX_RETRIES, cancel_outstanding, connect_ray, import_ray

        ray = import_ray()
        started = connect_ray(address, num_cpus or os.cpu_count() or 1)
        began = time.perf_counter()
        pending: list[Any] = []
        try:
            chunks = split_sample(episodes, max(1, int(ray.cluster_resources().get("CPU", 1))))
            remote = ray.remote(num_cpus=1, max_retries=MAX_RETRIES)(_rerun_chunk)
            pending = [remote.remote(method, chunk, options) for chunk in chunks]
            found: dict[tuple[str, int], dict] = {}
            failure: SubmissionError | None = None
            cause: BaseException | None = None
            # every chunk is awaited, also after one has failed: cancelling the others could abort
            # this process (see ``cancel_outstanding``), and each chunk is bounded by its sandbox's limits
            while pending:
                ready, pending = ray.wait(pending, num_returns=1)
                for ref in ready:
                    try:
                        ok, value = ray.get(ref)
                    except ray.exceptions.RayError as err:  # its Ray worker died more than MAX_RETRIES times, …
                        if failure is None:
                            failure, cause = VerificationFailed(f"the verification re-run on Ray failed: {err}"), err
                        continue
                    if not ok:
                        name, message = value
                        failure = failure or getattr(errors, name, VerificationFailed)(message)
                        continue
                    for episode in value[0]:
                        found[(str(episode["task"]), int(episode["seed"]))] = episode
            if failure is not None:
                raise failure from cause
            wanted = [(str(t), int(s)) for t, s in episodes]
            return [found[key] for key in wanted if key in found], time.perf_counter() - began
        except BaseException:
            cancel_outstanding(pending)  # interrupted (Ctrl-C): stop the chunks still running
            raise
        finally:
            if started:
                ray.shutdown()

    return rerun


__all__ = ["ray_rerun", "split_sample"]
