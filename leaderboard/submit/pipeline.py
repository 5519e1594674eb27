"""Submitting to the leaderboard: validate → verify → store.

:func:`submit` is what ``swarmloc submit`` calls. Nothing is written unless every step
passes; any refusal raises a :class:`~swarmloc.leaderboard.errors.SubmissionError`
subclass whose message says what was wrong, and leaves the store unchanged.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from swarmloc.bench.evaluation.results import Results, ResultsFile
from swarmloc.bench.scoring.stats import aggregate
from swarmloc.leaderboard.errors import InvalidSubmission
from swarmloc.leaderboard.store.database import (
    SHIPPED_REFERENCE_METHODS,
    LeaderboardEntry,
    LeaderboardStore,
)
from swarmloc.leaderboard.store.records import EntryScore
from swarmloc.leaderboard.store.schema import (
    SizeLimits,
    SubmissionMetadata,
    SuiteLookup,
    ValidatedSubmission,
    make_submission,
    read_submitted_results,
    validate_submission,
)
from swarmloc.leaderboard.verify.verification import (
    DEFAULT_RUNNER,
    Rerun,
    Tolerance,
    VerificationReport,
    VerifyLimits,
    run_in_worker,
    verify_results,
)


@dataclass(frozen=True)
class SubmissionReceipt:
    """What :func:`submit` stored.

    Attributes:
        id: The new submission's ID in the store.
        entry: The stored entry.
        report: The verification report, or ``None`` when trusted.
        store_url: The store it went to (password hidden).
    """

    id: int
    entry: LeaderboardEntry
    report: VerificationReport | None
    store_url: str

    def describe(self) -> str:
        """One paragraph for the terminal."""
        score = self.entry.score
        score_text = "n/a (no uniform_rmse in the results)" if score is None else (
            f"{score.times:.2f}× lower error than uniform (95% CI [{score.times_ci[0]:.2f}, "
            f"{score.times_ci[1]:.2f}]; S = {score.S:.3f})"
        )
        how = "trusted shipped method, not re-run" if self.report is None else self.report.describe()
        return (
            f"stored submission #{self.id} {self.entry.name!r} on suite "
            f"{self.entry.suite_name} v{self.entry.suite_version} in {self.store_url}\n"
            f"  score {score_text}\n  verification: {how}"
        )


def _mean_metric(validated: ValidatedSubmission, metric: str) -> float | None:
    values = [
        getattr(e.metrics, metric)
        for e in validated.results.episodes
        if getattr(e.metrics, metric) is not None
    ]
    return sum(values) / len(values) if values else None


def build_entry(
    validated: ValidatedSubmission, report: VerificationReport | None, trusted: bool
) -> LeaderboardEntry:
    """The store record of a validated (and verified or trusted) submission.

    Aggregates are recomputed from the episodes, never taken from the file.
    """
    results, meta = validated.results, validated.submission.metadata
    per_task = {
        task: {name: agg for name, agg in per_metric.items() if agg is not None}
        for task, per_metric in aggregate(results.episodes).items()
    }
    return LeaderboardEntry(
        created_utc=datetime.now(timezone.utc),
        name=meta.name,
        authors=meta.authors,
        url=meta.url,
        description=meta.description,
        track=meta.track,
        privileged=meta.privileged,
        deterministic=results.method.deterministic,
        entry_point=validated.submission.entry_point,
        method_hash=validated.method_hash,
        weights_sha256=validated.weights_sha256,
        suite_name=results.suite.name,
        suite_version=results.suite.version,
        suite_sha256=results.suite.sha256,
        verified=report is not None,
        trusted=trusted,
        verification_seed=None if report is None else report.sample_seed,
        verified_episodes=0 if report is None else len(report.episodes),
        score=EntryScore.of((e.model_dump() for e in results.episodes), suite=results.suite.name),
        delay_ms=_mean_metric(validated, "delay_ms"),
        energy_j=_mean_metric(validated, "energy_j"),
        jitter=_mean_metric(validated, "jitter"),
        package_version=results.provenance.package_version,
        git_commit=results.provenance.git_commit,
        results_json=validated.results_text,
        task_aggregates=per_task,
        run=results.method.run,
        privileged_training=results.method.privileged_training,
        flops_per_channel=results.method.flops_per_channel,
    )


def metadata_from_results(results: Results, overrides: SubmissionMetadata | dict[str, Any] | None = None
                          ) -> dict[str, Any]:
    """Submission metadata: the results file's method name, track and privileged flag, then ``overrides``.

    Args:
        results: The submitted results (read once: :func:`~swarmloc.leaderboard.store.schema.read_submitted_results`).
        overrides: Fields given by the submitter (a :class:`SubmissionMetadata` or a
            dict; ``None`` values are ignored).

    Returns:
        A dict of :class:`SubmissionMetadata` fields (validated later, with the rest).
    """
    method = results.method
    given = overrides.model_dump() if isinstance(overrides, SubmissionMetadata) else dict(overrides or {})
    fields = {"name": method.name, "track": method.track, "privileged": method.privileged}
    fields |= {key: value for key, value in given.items() if value is not None}
    return fields


def submit(
    results: str | Path | ResultsFile,
    entry_point: str | None = None,
    metadata: SubmissionMetadata | dict[str, Any] | None = None,
    weights: str | Path | None = None,
    db_url: str | None = None,
    trust: bool = False,
    sample_frac: float = 0.1,
    *,
    min_episodes: int = 3,
    sample_seed: int | None = None,
    limits: VerifyLimits = VerifyLimits(),
    tolerance: Tolerance | None = None,
    size_limits: SizeLimits = SizeLimits(),
    search_path: Sequence[str | Path] = (),
    sandbox: bool = True,
    runner: str = DEFAULT_RUNNER,
    runner_path: Sequence[str | Path] = (),
    suite_lookup: SuiteLookup | None = None,
    store: LeaderboardStore | None = None,
    rerun: Rerun = run_in_worker,
    replace_reference: bool = False,
) -> SubmissionReceipt:
    """Validate, verify and store a submission.

    Args:
        results: Results file written by ``swarmloc evaluate``, or that file as read already
            (:func:`~swarmloc.leaderboard.store.schema.read_submitted_results`): it is read once,
            and every step uses that one read.
        entry_point: The method (``package.module:factory``, ``path/to/file.py:factory`` or
            a registered name); default: the results file's ``method.entry_point``.
        metadata: Name, authors, URL, description, track, privileged (a
            :class:`SubmissionMetadata` or a dict of some of its fields); name, track and
            privileged default to the results file's method.
        weights: Weights file; its SHA-256 must match the results (required when the
            results record one).
        db_url: Store URL (default: ``SWARMLOC_DB`` or the user data directory).
        trust: Skip verification; only allowed for the shipped reference methods
            (:data:`~swarmloc.leaderboard.store.database.SHIPPED_REFERENCE_METHODS`).
        sample_frac: Fraction of episodes to re-run, in (0, 1].
        min_episodes: Re-run at least this many episodes.
        sample_seed: Sampler seed (fresh random one when None; recorded in the store).
        limits: Wall-time, memory, process and file-size limits of the re-run.
        tolerance: Override the comparison tolerance.
        size_limits: Largest results and weights files accepted.
        search_path: Directories the method's modules are imported from (visible,
            read-only, to the method's sandbox).
        sandbox: Re-run inside bubblewrap (see :mod:`swarmloc.leaderboard.verify.sandbox`);
            False runs your own method with the limits only, where bubblewrap is missing.
        runner: ``module:function`` the verification worker calls.
        runner_path: Extra directories for the worker's ``PYTHONPATH`` (runner code).
        suite_lookup: ``name -> suite`` (default ``swarmloc.bench.evaluation.suites.get_suite``).
        store: An open store (overrides ``db_url``).
        rerun: What runs the sandboxed re-runs (see :func:`~swarmloc.leaderboard.verify.verification.verify_results`;
            :func:`~swarmloc.leaderboard.verify.ray_rerun.ray_rerun` for Ray tasks).
        replace_reference: with ``trust``: a stored entry of the same shipped method and
            suite whose results differ is replaced, in one transaction (see
            :meth:`~swarmloc.leaderboard.store.database.LeaderboardStore.add`).

    Returns:
        A receipt with the new ID, the stored entry and the verification report.

    Raises:
        InvalidSubmission: malformed metadata, files too large, results not matching
            the suite (or of a task subset), bad metrics, or ``trust`` for a non-shipped method.
        SandboxUnavailable: ``sandbox`` is True and bubblewrap cannot run here.
        VerificationFailed: the re-run crashed, timed out, ran out of memory, or
            did not reproduce the submitted metrics.
        DuplicateSubmission: the same method is already stored for this suite.
    """
    file = results if isinstance(results, ResultsFile) else read_submitted_results(results, size_limits)
    if entry_point is None:
        entry_point = file.results.method.entry_point
    metadata = metadata_from_results(file.results, metadata)
    submission = make_submission(file.path, entry_point, metadata, weights, search_path)
    if trust and entry_point not in SHIPPED_REFERENCE_METHODS:
        raise InvalidSubmission(
            f"trust=True skips verification only for the shipped reference methods "
            f"{sorted(SHIPPED_REFERENCE_METHODS)}; {entry_point!r} is not one of them"
        )
    if replace_reference and not trust:
        raise InvalidSubmission("replace_reference=True replaces a shipped reference method's entry; "
                                "it needs trust=True")
    validated = validate_submission(submission, suite_lookup, size_limits, results_file=file)
    own_store = store is None
    active = store if store is not None else LeaderboardStore(db_url)
    try:
        if not replace_reference:  # cheap check before spending time on verification; add() checks again atomically
            active.ensure_new(entry_point, validated.method_hash, validated.results.suite.name,
                              validated.results.suite.version)
        report = None
        if not trust:
            report = verify_results(
                validated.results,
                entry_point,
                weights=submission.weights_path,
                sample_frac=sample_frac,
                min_episodes=min_episodes,
                sample_seed=sample_seed,
                limits=limits,
                tolerance=tolerance,
                runner=runner,
                runner_path=runner_path,
                method_path=search_path,
                sandbox=sandbox,
                store_file=active.database_file,
                rerun=rerun,
            )
        entry = build_entry(validated, report, trusted=trust)
        new_id = active.add(entry, replace_reference=replace_reference)
        return SubmissionReceipt(id=new_id, entry=active.get(new_id), report=report,
                                 store_url=active.url)
    finally:
        if own_store:
            active.close()


__all__ = ["SubmissionReceipt", "build_entry", "metadata_from_results", "submit"]
