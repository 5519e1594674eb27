"""Verification: re-run a random sample of submitted episodes in a sandbox.

The sample (default 10 % of the episodes, at least 3) is drawn with a seeded sampler;
the seed is fresh per submission unless given, and recorded so that a verification can
be repeated. The episodes run in :mod:`swarmloc.leaderboard.verify.rerun`: the runner in one
bubblewrap sandbox, the submitted method in another, each with a read-only view of
swarmloc and its own files only, a private tmp, no network, its own PID namespace, and
memory, process, file-size and wall-time limits (see :mod:`swarmloc.leaderboard.verify.sandbox`).

Per-episode metrics must equal the submitted ones exactly for methods that declare
themselves deterministic, and agree within :data:`NONDETERMINISTIC_TOLERANCE` otherwise.
"""

from __future__ import annotations

import math
import random
import secrets
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from swarmloc.bench.evaluation.results import SCHEMA_METRICS, Results
from swarmloc.leaderboard.errors import VerificationFailed
from swarmloc.leaderboard.verify.rerun import VerifyLimits, run_in_worker, worker_environment

Rerun = Callable[..., tuple[list[dict], float]]
"""``rerun(entry_point, episodes, *, weights, runner, runner_path, method_path, limits, sandbox, store_file)
-> (episodes, wall_s)``: :func:`run_in_worker` or a drop-in for it."""

DEFAULT_RUNNER: str = "swarmloc.bench.evaluation.runner:run_episodes"
"""``module:function`` the worker calls as ``run_episodes(method, episodes) -> list[dict]``."""

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


def compare_episodes(
    results: Results, recomputed: Sequence[dict], sample: Sequence[tuple[str, int]],
    tolerance: Tolerance,
) -> list[MetricMismatch]:
    """Every metric of every sampled episode that the re-run did not reproduce.

    Only the metrics the file's schema version holds are compared (a version-2 file has no
    ``recovery_s``, which the re-run computes). An episode missing from the re-run output
    counts as a mismatch of every metric.
    """
    submitted = {(e.task, e.seed): e.metrics.model_dump() for e in results.episodes}
    rerun = {(str(e["task"]), int(e["seed"])): e.get("metrics", {}) for e in recomputed}
    mismatches = []
    for key in sample:
        mine, theirs = submitted[key], rerun.get(key)
        for name in SCHEMA_METRICS[results.schema_version]:
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
    runner_path: Sequence[str | Path] = (),
    method_path: Sequence[str | Path] = (),
    sandbox: bool = True,
    store_file: Path | None = None,
    rerun: Rerun = run_in_worker,
) -> VerificationReport:
    """Re-run a sample of the submitted episodes and compare their metrics.

    Args:
        results: The validated results.
        entry_point: The method's entry point.
        weights: The method's weights file, if any.
        sample_frac: Fraction of episodes to re-run, in (0, 1].
        min_episodes: Lower bound on the sample size.
        sample_seed: Sampler seed; a fresh random one when None (recorded in the report).
        limits: Wall-time, memory, process and file-size limits.
        tolerance: Override; by default exact for deterministic methods, else
            :data:`NONDETERMINISTIC_TOLERANCE`.
        runner: ``module:function`` the worker calls.
        runner_path: Directories on the worker's ``PYTHONPATH`` (runner code).
        method_path: Directories on the method's ``PYTHONPATH`` (its modules).
        sandbox: Run inside bubblewrap; False runs plain subprocesses with the limits only.
        store_file: The store's SQLite file, kept out of the sandbox's view.
        rerun: What re-runs the sample, with :func:`run_in_worker`'s signature: that
            function (here), or :func:`swarmloc.leaderboard.verify.ray_rerun.ray_rerun`'s (the
            same sandboxed re-runs as Ray tasks).

    Returns:
        The report (``report.ok`` is True).

    Raises:
        SandboxUnavailable: ``sandbox`` is True and bubblewrap cannot run here.
        VerificationFailed: on a worker failure or any mismatch, with the report text.
    """
    seed = secrets.randbits(63) if sample_seed is None else sample_seed
    sample = sample_episodes(results.episode_keys(), sample_frac, min_episodes, seed)
    tol = tolerance or (EXACT if results.method.deterministic else NONDETERMINISTIC_TOLERANCE)
    recomputed, wall = rerun(
        entry_point, sample, weights=weights, runner=runner, runner_path=runner_path,
        method_path=method_path, limits=limits, sandbox=sandbox, store_file=store_file,
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
    "Rerun",
    "Tolerance",
    "VerificationReport",
    "VerifyLimits",
    "compare_episodes",
    "run_in_worker",
    "sample_episodes",
    "verify_results",
    "worker_environment",
]
