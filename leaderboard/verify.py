"""Verification: re-run a random sample of submitted episodes in a sandboxed subprocess.

The sample (default 10 % of the episodes, at least 3) is drawn with a seeded sampler;
the seed is fresh per submission unless given, and recorded so that a verification can
be repeated. The episodes run in ``python -m swarmloc.leaderboard.verify_worker``:

* a **clean environment** (``PATH``, a private temporary ``HOME``/``TMPDIR``, locale,
  ``PYTHONPATH`` for the method's search path): no ``SWARMLOC_DB``, no store URL;
* a **memory limit**: the worker sets ``RLIMIT_AS`` on itself before importing the method;
* a **wall-time limit**: the worker's whole process group is killed when it runs over.

Per-episode metrics must equal the submitted ones exactly for methods that declare
themselves deterministic, and agree within :data:`NONDETERMINISTIC_TOLERANCE` otherwise.

This isolates the store from honest mistakes and keeps runaway methods bounded; it is
not a security boundary against hostile code, which needs a container or VM around it.
"""

from __future__ import annotations

import json
import math
import os
import random
import secrets
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from swarmloc.bench.evaluation.results import METRIC_NAMES, Results
from swarmloc.leaderboard.entry_points import parse_entry_point
from swarmloc.leaderboard.errors import VerificationFailed

DEFAULT_RUNNER: str = "swarmloc.bench.evaluation.runner:run_episodes"
"""``module:function`` the worker calls as ``run_episodes(method, episodes) -> list[dict]``."""

WORKER_MODULE: str = "swarmloc.leaderboard.verify_worker"

_EXIT_MEMORY = 3
_MAX_RESPONSE_BYTES = 64 * 1024 * 1024
_LOG_TAIL_CHARS = 2000
_MAX_REPORTED_MISMATCHES = 20


@dataclass(frozen=True)
class Tolerance:
    """How close a re-run metric must be: ``|a − b| ≤ max(rel·max(|a|, |b|), abs)``."""

    rel: float = 0.0
    abs: float = 0.0

    def agrees(self, submitted: float | None, recomputed: float | None) -> bool:
        """True when both are None, or both numbers within the tolerance (exact if 0, 0)."""
        if submitted is None or recomputed is None:
            return submitted is None and recomputed is None
        if self.rel == 0.0 and self.abs == 0.0:
            return submitted == recomputed
        return math.isclose(submitted, recomputed, rel_tol=self.rel, abs_tol=self.abs)

    def describe(self) -> str:
        """Human-readable statement of the tolerance."""
        if self.rel == 0.0 and self.abs == 0.0:
            return "exact equality"
        return f"relative {self.rel:g} / absolute {self.abs:g}"


EXACT = Tolerance()
"""Deterministic methods must reproduce every metric bit for bit."""

NONDETERMINISTIC_TOLERANCE = Tolerance(rel=1e-3, abs=1e-6)
"""Methods declared non-deterministic must agree to 0.1 % (or 1e-6 absolute)."""


@dataclass(frozen=True)
class VerifyLimits:
    """Resources the verification worker may use.

    Attributes:
        wall_time_s: Wall-clock seconds for the whole sample (start-up included).
        memory_bytes: Address-space cap (``RLIMIT_AS``) of the worker process.
    """

    wall_time_s: float = 900.0
    memory_bytes: int = 8 * 1024**3

    def __post_init__(self) -> None:
        if not self.wall_time_s > 0:
            raise ValueError(f"wall_time_s must be positive, got {self.wall_time_s}")
        if self.memory_bytes < 64 * 1024**2:
            raise ValueError(f"memory_bytes must be at least 64 MiB, got {self.memory_bytes}")


@dataclass(frozen=True)
class MetricMismatch:
    """One metric of one episode that the re-run did not reproduce."""

    task: str
    seed: int
    metric: str
    submitted: float | None
    recomputed: float | None

    def describe(self) -> str:
        return (
            f"({self.task!r}, seed {self.seed}) {self.metric}: submitted {self.submitted!r}, "
            f"re-run gave {self.recomputed!r}"
        )


@dataclass(frozen=True)
class VerificationReport:
    """Outcome of :func:`verify_results`.

    Attributes:
        sample_seed: Seed of the episode sampler.
        episodes: The re-run (task, seed) pairs.
        tolerance: The tolerance applied.
        mismatches: Metrics that differ (empty when verification passed).
        wall_s: Seconds the worker ran.
    """

    sample_seed: int
    episodes: tuple[tuple[str, int], ...]
    tolerance: Tolerance
    mismatches: tuple[MetricMismatch, ...] = field(default=())
    wall_s: float = 0.0

    @property
    def ok(self) -> bool:
        return not self.mismatches

    def describe(self) -> str:
        """Multi-line summary naming every differing episode and metric."""
        head = (
            f"re-ran {len(self.episodes)} episode(s) (sampler seed {self.sample_seed}), "
            f"compared with {self.tolerance.describe()}"
        )
        if self.ok:
            return head + ": all metrics reproduced"
        episodes = sorted({(m.task, m.seed) for m in self.mismatches})
        lines = [
            head + f": {len(self.mismatches)} metric(s) in {len(episodes)} episode(s) differ:"
        ]
        lines += [f"  - {m.describe()}" for m in self.mismatches[:_MAX_REPORTED_MISMATCHES]]
        if len(self.mismatches) > _MAX_REPORTED_MISMATCHES:
            lines.append(f"  ... and {len(self.mismatches) - _MAX_REPORTED_MISMATCHES} more")
        return "\n".join(lines)


def sample_episodes(
    episodes: Sequence[tuple[str, int]],
    fraction: float = 0.1,
    minimum: int = 3,
    seed: int = 0,
) -> list[tuple[str, int]]:
    """Draw ``max(minimum, ⌈fraction·n⌉)`` distinct episodes (all of them if fewer).

    Args:
        episodes: (task, seed) pairs; their order does not matter.
        fraction: In (0, 1].
        minimum: At least 1.
        seed: Sampler seed; the same seed and episodes give the same sample.

    Returns:
        The sample, sorted.
    """
    if not 0.0 < fraction <= 1.0:
        raise ValueError(f"sample fraction must be in (0, 1], got {fraction}")
    if minimum < 1:
        raise ValueError(f"minimum sample size must be at least 1, got {minimum}")
    pool = sorted(set(episodes))
    size = min(len(pool), max(minimum, math.ceil(fraction * len(pool))))
    return sorted(random.Random(seed).sample(pool, size))


def worker_environment(home: Path, pythonpath: Sequence[str]) -> dict[str, str]:
    """The complete environment of the worker: nothing inherited but ``PATH``."""
    env = {
        "PATH": os.environ.get("PATH", os.defpath),
        "HOME": str(home),
        "TMPDIR": str(home),
        "LANG": "C.UTF-8",
        "LC_ALL": "C.UTF-8",
        "PYTHONHASHSEED": "0",
        "PYTHONDONTWRITEBYTECODE": "1",
        "PYTHONNOUSERSITE": "1",
        # glibc reserves 64 MiB of address space per thread arena; keep RLIMIT_AS meaningful.
        "MALLOC_ARENA_MAX": "2",
    }
    if pythonpath:
        env["PYTHONPATH"] = os.pathsep.join(pythonpath)
    return env


def _tail(path: Path) -> str:
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return ""
    return text[-_LOG_TAIL_CHARS:].strip()


def _signal_name(code: int) -> str:
    try:
        return signal.Signals(-code).name
    except ValueError:
        return f"signal {-code}"


def run_in_worker(
    method: str,
    episodes: Sequence[tuple[str, int]],
    *,
    weights: Path | None = None,
    runner: str = DEFAULT_RUNNER,
    pythonpath: Sequence[str | Path] = (),
    limits: VerifyLimits = VerifyLimits(),
    python: str = sys.executable,
) -> tuple[list[dict], float]:
    """Run episodes in the sandboxed worker and return its per-episode results.

    Args:
        method: Entry point as in the results file (file entry points are rewritten to
            ``stem:factory`` with their directory on the worker's path).
        episodes: (task, seed) pairs to run.
        weights: Weights file handed to the runner as ``weights=``.
        runner: ``module:function`` the worker calls.
        pythonpath: Directories for the worker's ``PYTHONPATH`` (method and runner code).
        limits: Wall-time and memory limits.
        python: Interpreter for the worker.

    Returns:
        ``(episodes, wall_seconds)`` where each episode is ``{"task", "seed", "metrics"}``.

    Raises:
        VerificationFailed: when the worker crashes, runs out of time or memory, or
            returns malformed output; the message carries the worker's error.
    """
    runner_method, extra_path = parse_entry_point(method).for_runner()
    with tempfile.TemporaryDirectory(prefix="swarmloc-verify-") as tmp:
        home = Path(tmp)
        request_path, response_path = home / "request.json", home / "response.json"
        stdout_path, stderr_path = home / "stdout.log", home / "stderr.log"
        request = {
            "runner": runner,
            "method": runner_method,
            "weights": str(Path(weights).resolve()) if weights is not None else None,
            "sys_path": extra_path,
            "episodes": [[task, seed] for task, seed in episodes],
        }
        request_path.write_text(json.dumps(request), encoding="utf-8")
        command = [
            python, "-m", WORKER_MODULE,
            "--request", str(request_path),
            "--response", str(response_path),
            "--memory-bytes", str(limits.memory_bytes),
        ]
        env = worker_environment(home, [str(Path(p).resolve()) for p in pythonpath])
        started = time.monotonic()
        with open(stdout_path, "wb") as out, open(stderr_path, "wb") as err:
            proc = subprocess.Popen(
                command, cwd=home, env=env, stdin=subprocess.DEVNULL, stdout=out, stderr=err,
                start_new_session=True,
            )
            try:
                code = proc.wait(timeout=limits.wall_time_s)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
                raise VerificationFailed(
                    f"method {method!r} exceeded the wall-time limit of {limits.wall_time_s:g} s "
                    f"while re-running {len(episodes)} episode(s); the worker was killed"
                ) from None
            finally:
                if proc.poll() is None:  # pragma: no cover - only on unexpected errors
                    os.killpg(proc.pid, signal.SIGKILL)
                    proc.wait()
        wall = time.monotonic() - started
        # Reap grandchildren the method may have left behind.
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
        response = None
        if response_path.is_file() and response_path.stat().st_size <= _MAX_RESPONSE_BYTES:
            try:
                response = json.loads(response_path.read_text(encoding="utf-8"))
            except (json.JSONDecodeError, UnicodeDecodeError):
                response = None
        mib = limits.memory_bytes / 1024**2
        if code == 0 and isinstance(response, dict) and response.get("ok"):
            return list(response.get("episodes", [])), wall
        if isinstance(response, dict) and response.get("kind") == "memory" or code == _EXIT_MEMORY:
            detail = response.get("message") if isinstance(response, dict) else None
            raise VerificationFailed(
                f"method {method!r} exceeded the memory limit of {mib:.0f} MiB "
                f"while re-running {len(episodes)} episode(s)"
                + (f" ({detail})" if detail else "")
            )
        if isinstance(response, dict) and not response.get("ok", True):
            detail = response.get("traceback") or response.get("message") or ""
            what = "returned malformed output" if response.get("kind") == "bad_output" else "crashed"
            raise VerificationFailed(
                f"method {method!r} {what} during verification: {response.get('message')}\n"
                f"{detail}".rstrip()
            )
        how = f"died with {_signal_name(code)}" if code < 0 else f"exited with status {code}"
        hint = f" (possibly the memory limit of {mib:.0f} MiB)" if code < 0 else ""
        raise VerificationFailed(
            f"verification worker for method {method!r} {how}{hint} without a result; "
            f"stderr:\n{_tail(stderr_path) or '(empty)'}"
        )


def compare_episodes(
    results: Results, recomputed: Sequence[dict], sample: Sequence[tuple[str, int]],
    tolerance: Tolerance,
) -> list[MetricMismatch]:
    """Every metric of every sampled episode that the re-run did not reproduce.

    An episode missing from the re-run output counts as a mismatch of every metric.
    """
    submitted = {(e.task, e.seed): e.metrics.model_dump() for e in results.episodes}
    rerun = {(str(e["task"]), int(e["seed"])): e.get("metrics", {}) for e in recomputed}
    mismatches = []
    for key in sample:
        mine, theirs = submitted[key], rerun.get(key)
        for name in METRIC_NAMES:
            got = None if theirs is None else theirs.get(name)
            if theirs is None or not tolerance.agrees(mine[name], got):
                mismatches.append(MetricMismatch(key[0], key[1], name, mine[name], got))
    return mismatches


def verify_results(
    results: Results,
    entry_point: str,
    *,
    weights: Path | None = None,
    sample_frac: float = 0.1,
    min_episodes: int = 3,
    sample_seed: int | None = None,
    limits: VerifyLimits = VerifyLimits(),
    tolerance: Tolerance | None = None,
    runner: str = DEFAULT_RUNNER,
    pythonpath: Sequence[str | Path] = (),
) -> VerificationReport:
    """Re-run a sample of the submitted episodes and compare their metrics.

    Args:
        results: The validated results.
        entry_point: The method's entry point.
        weights: The method's weights file, if any.
        sample_frac: Fraction of episodes to re-run, in (0, 1].
        min_episodes: Lower bound on the sample size.
        sample_seed: Sampler seed; a fresh random one when None (recorded in the report).
        limits: Worker wall-time and memory limits.
        tolerance: Override; by default exact for deterministic methods, else
            :data:`NONDETERMINISTIC_TOLERANCE`.
        runner: ``module:function`` the worker calls.
        pythonpath: Directories for the worker's ``PYTHONPATH``.

    Returns:
        The report (``report.ok`` is True).

    Raises:
        VerificationFailed: on a worker failure or any mismatch, with the report text.
    """
    seed = secrets.randbits(63) if sample_seed is None else sample_seed
    sample = sample_episodes(results.episode_keys(), sample_frac, min_episodes, seed)
    tol = tolerance or (EXACT if results.method.deterministic else NONDETERMINISTIC_TOLERANCE)
    recomputed, wall = run_in_worker(
        entry_point, sample, weights=weights, runner=runner, pythonpath=pythonpath, limits=limits
    )
    report = VerificationReport(
        sample_seed=seed,
        episodes=tuple(sample),
        tolerance=tol,
        mismatches=tuple(compare_episodes(results, recomputed, sample, tol)),
        wall_s=wall,
    )
    if not report.ok:
        raise VerificationFailed(
            f"verification of {entry_point!r} failed: {report.describe()}", report=report
        )
    return report


__all__ = [
    "DEFAULT_RUNNER",
    "EXACT",
    "NONDETERMINISTIC_TOLERANCE",
    "MetricMismatch",
    "Tolerance",
    "VerificationReport",
    "VerifyLimits",
    "compare_episodes",
    "run_in_worker",
    "sample_episodes",
    "verify_results",
]
