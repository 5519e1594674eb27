"""What a leaderboard submission is, and the checks it must pass before verification.

A submission is a results file (see :mod:`swarmloc.bench.evaluation.results`), the method's entry
point, an optional weights file, and metadata. :func:`validate_submission` checks, in
order and without running any submitted code:

1. sizes: the results file and the weights file are within :class:`SizeLimits`;
2. the results file parses and matches its schema (read once, by
   :func:`swarmloc.bench.evaluation.results.read_results_file`: the file read is the file stored);
3. the entry point, track, privileged flag and weights hash agree with the results
   (metadata itself is checked by :class:`~swarmloc.leaderboard.submit.metadata.SubmissionMetadata`);
4. the suite exists and the results name its current version and hash;
5. every (task, seed) of the suite is present, none twice, none extra;
6. every metric is finite and within its physical bounds (:data:`METRIC_BOUNDS`), and
   the submitted aggregates agree with the episodes.

Failures raise :class:`~swarmloc.leaderboard.errors.InvalidSubmission` listing the
problems.
"""

from __future__ import annotations

import hashlib
import json
import math
import shlex
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, Protocol

from pydantic import BaseModel, ConfigDict, ValidationError, field_validator

from swarmloc.bench.evaluation.results import (
    METRIC_NAMES,
    Results,
    ResultsFile,
    ResultsFileError,
    read_results_file,
    score_block,
)
from swarmloc.bench.scoring.stats import aggregate
from swarmloc.leaderboard.errors import InvalidSubmission
from swarmloc.leaderboard.submit.entry_points import (
    EntryPoint,
    locate_source,
    parse_entry_point,
    sha256_file,
)
from swarmloc.leaderboard.submit.metadata import SubmissionMetadata

SUBMISSION_VERSION: Literal[1] = 1
"""Version of the submission schema; bump on any change to :class:`Submission`."""

MAX_REPORTED_PROBLEMS: int = 20

METRIC_BOUNDS: dict[str, tuple[float, float]] = {
    # Distances in metres are non-negative.
    "rmse": (0.0, math.inf),
    "mean_error": (0.0, math.inf),
    "median_error": (0.0, math.inf),
    "max_error": (0.0, math.inf),
    "cep90": (0.0, math.inf),
    "fault_rmse": (0.0, math.inf),
    "healthy_rmse": (0.0, math.inf),
    "uniform_rmse": (0.0, math.inf),  # the standard CEKF on the same episode (the score's reference)
    "bound_rmse": (0.0, math.inf),  # the episode's information bound
    # Seconds after an IMU fault ends (censored at the episode's end), and a flag per episode.
    "recovery_s": (0.0, math.inf),
    "recovered": (0.0, 1.0),
    # A flag per episode, a fraction once averaged.
    "diverged": (0.0, 1.0),
    # Time and energy cannot be negative.
    "delay_ms": (0.0, math.inf),
    "energy_j": (0.0, math.inf),
    # Trust weights lie in [0, 1], so do their mean change and their variance.
    "jitter": (0.0, 1.0),
    "weight_var": (0.0, 1.0),
    "anomaly_detection_rate": (0.0, 1.0),
    # Returns may be any finite number.
    "team_return": (-math.inf, math.inf),
}
"""Closed physical range of every metric (non-finite values are always rejected)."""

SUBSET_SUFFIX: str = "-subset"
"""Name suffix of a suite restricted to some of its tasks (``bench.evaluation.suites.restrict_tasks``)."""

REQUIRED_METRICS: tuple[str, ...] = ()
"""Metrics every episode must define (the rest may be null). ``rmse`` is not among them: a method
that cannot run a task has null metrics on all of its seeds, and is ranked on the tasks it
covers (see :func:`coverage_problems`)."""

class Submission(BaseModel):
    """A leaderboard submission (versioned).

    Attributes:
        submission_version: Schema version, currently 1.
        results_path: The results file written by ``swarmloc evaluate``.
        entry_point: ``package.module:factory``, ``path/to/file.py:factory`` or a
            registered method name; must equal the results file's ``method.entry_point``.
        weights_path: Optional weights file; its SHA-256 must equal the results'.
        search_path: Directories the method's modules are imported from (besides the
            installed packages).
        metadata: Display metadata.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    submission_version: Literal[1] = SUBMISSION_VERSION
    results_path: Path
    entry_point: str
    weights_path: Path | None = None
    search_path: tuple[Path, ...] = ()
    metadata: SubmissionMetadata

    @field_validator("entry_point")
    @classmethod
    def _entry_point(cls, value: str) -> str:
        parse_entry_point(value)
        return value


@dataclass(frozen=True)
class SizeLimits:
    """Largest files accepted, in bytes (checked before reading)."""

    results_bytes: int = 16 * 1024 * 1024
    weights_bytes: int = 256 * 1024 * 1024


class SuiteLike(Protocol):
    """What ``swarmloc.bench.evaluation.suites.get_suite(name)`` returns."""

    name: str
    version: str
    sha256: str
    episodes: Sequence[tuple[str, int]]


SuiteLookup = Callable[[str], SuiteLike]


@dataclass(frozen=True)
class ValidatedSubmission:
    """A submission that passed :func:`validate_submission`.

    Attributes:
        submission: The submission as given.
        results: The parsed results file.
        results_text: The results file's exact text (kept for download).
        suite: The suite definition it was checked against.
        entry: The parsed entry point.
        method_hash: See :func:`method_hash`.
        weights_sha256: SHA-256 of the weights file, if any.
    """

    submission: Submission
    results: Results
    results_text: str
    suite: SuiteLike
    entry: EntryPoint
    method_hash: str
    weights_sha256: str | None = None


def default_suite_lookup(name: str) -> SuiteLike:
    """Look a suite up in ``swarmloc.bench.evaluation.suites`` (imported lazily)."""
    try:
        from swarmloc.bench.evaluation.suites import get_suite
    except ImportError as err:
        raise InvalidSubmission(
            f"cannot look up suite {name!r}: swarmloc.bench.evaluation.suites.get_suite is not "
            f"available ({err})"
        ) from None
    return get_suite(name)


def method_hash(
    entry_point: str, weights_sha256: str | None, search_path: Sequence[str | Path] = ()
) -> str:
    """Identity of a method for duplicate detection.

    SHA-256 over the entry point string, the weights hash, and the hash of the source
    file that defines the factory when it can be located without importing it.
    Changing the code or the weights therefore makes a new method.

    Args:
        entry_point: The entry point string.
        weights_sha256: Hex SHA-256 of the weights, or None.
        search_path: Extra directories searched for the module.

    Returns:
        Lower-case hex digest.
    """
    source = locate_source(parse_entry_point(entry_point), search_path)
    identity = {
        "entry_point": entry_point,
        "weights_sha256": weights_sha256,
        "source_sha256": sha256_file(source) if source is not None else None,
    }
    text = json.dumps(identity, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _file_size(path: Path, what: str, limit: int) -> None:
    try:
        size = path.stat().st_size
    except FileNotFoundError:
        raise InvalidSubmission(f"{what} {path} does not exist") from None
    if not path.is_file():
        raise InvalidSubmission(f"{what} {path} is not a regular file")
    if size > limit:
        raise InvalidSubmission(f"{what} {path} is {size} bytes; the limit is {limit} bytes")


def read_submitted_results(path: str | Path, limits: SizeLimits = SizeLimits()) -> ResultsFile:
    """Read a submitted results file once, within the size limit, refusing it as :class:`InvalidSubmission`.

    Args:
        path: The results file.
        limits: Its largest size is ``limits.results_bytes``.

    Returns:
        Its path, exact text and validated results, to pass along to :func:`validate_submission`.

    Raises:
        InvalidSubmission: the file is missing, too large or not a valid results file (the
            message of :class:`~swarmloc.bench.evaluation.results.ResultsFileError`).
    """
    try:
        return read_results_file(path, limits.results_bytes)
    except ResultsFileError as err:
        raise InvalidSubmission(str(err)) from None


def _refuse_subset(results: Results, path: Path) -> None:
    """Refuse results of ``swarmloc evaluate --tasks`` (suite ``<name>-subset``), saying what to run."""
    name = results.suite.name
    if not name.endswith(SUBSET_SUFFIX):
        return
    whole = name[: -len(SUBSET_SUFFIX)]
    tasks = sorted({episode.task for episode in results.episodes})
    raise InvalidSubmission(
        f"results file {path} covers {len(tasks)} task(s) of suite {whole!r} (suite {name!r}, "
        f"from `swarmloc evaluate --tasks`); only whole suites can be submitted. Evaluate the whole "
        f"suite: swarmloc evaluate --method {shlex.quote(results.method.entry_point)} --suite "
        f"{shlex.quote(whole)} --out {shlex.quote(path.name)}"
    )


def metric_problems(results: Results) -> list[str]:
    """Every non-finite, missing or out-of-range metric value, one line each."""
    problems: list[str] = []
    for episode in results.episodes:
        values = episode.metrics.model_dump()
        for name in METRIC_NAMES:
            value = values[name]
            where = f"episode ({episode.task!r}, seed {episode.seed}) metric {name!r}"
            if value is None:
                if name in REQUIRED_METRICS:
                    problems.append(f"{where} is null; every episode must define it")
                continue
            low, high = METRIC_BOUNDS[name]
            if not math.isfinite(value):
                problems.append(f"{where} is {value}; metrics must be finite numbers")
            elif not low <= value <= high:
                problems.append(f"{where} is {value}; allowed range is [{low}, {high}]")
    return problems


def coverage_problems(results: Results) -> list[str]:
    """A task run on some seeds but not others, or no task run at all.

    A method either runs a task (an RMSE on every seed) or cannot run it (null on every
    seed: partial coverage, ranked apart on its own tasks); half-run tasks are refused.
    """
    by_task: dict[str, list[bool]] = {}
    for episode in results.episodes:
        by_task.setdefault(episode.task, []).append(episode.metrics.rmse is not None)
    problems = [f"task {task!r} has an RMSE on {sum(ran)} of its {len(ran)} seeds; a method runs a task on every "
                f"seed or on none" for task, ran in by_task.items() if 0 < sum(ran) < len(ran)]
    if not any(all(ran) for ran in by_task.values()):
        problems.append("no task has an RMSE on its seeds: the method ran nothing")
    return problems


def score_problems(results: Results) -> list[str]:
    """A ``score`` block that disagrees with the episodes (the leaderboard recomputes it anyway)."""
    if results.score is None:
        return []
    expected = score_block(results.episodes, list(results.aggregates), results.suite.name)
    if expected is None:
        return ["the results file has a score block, but its episodes give none (no uniform_rmse)"]
    problems = []
    for name in ("S", "iqm", "times"):
        a, b = getattr(results.score, name), getattr(expected, name)
        if not math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12):
            problems.append(f"score.{name} is {a}, but the episodes give {b}")
    if (results.score.covered, results.score.total) != (expected.covered, expected.total):
        problems.append(f"score covers {results.score.covered}/{results.score.total} tasks, but the episodes "
                        f"give {expected.covered}/{expected.total}")
    return problems


def aggregate_problems(results: Results) -> list[str]:
    """Submitted per-task mean and IQM values that disagree with the episodes.

    The leaderboard stores aggregates recomputed from the episodes; this check only
    catches results files whose aggregates were edited by hand.
    """
    problems: list[str] = []
    recomputed = aggregate(results.episodes, n_resamples=1)
    for task, per_metric in recomputed.items():
        for name, expected in per_metric.items():
            given = results.aggregates.get(task, {}).get(name)
            if (expected is None) != (given is None):
                problems.append(
                    f"aggregates[{task!r}][{name!r}] is {given}, but the episodes give {expected}"
                )
                continue
            if expected is None or given is None:
                continue
            for stat in ("mean", "iqm"):
                a, b = getattr(given, stat), getattr(expected, stat)
                if not math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12):
                    problems.append(
                        f"aggregates[{task!r}][{name!r}].{stat} is {a}, but the episodes give {b}"
                    )
    return problems


def _coverage_problems(results: Results, suite: SuiteLike) -> list[str]:
    expected = Counter((str(t), int(s)) for t, s in suite.episodes)
    given = Counter(results.episode_keys())
    problems = []
    missing = sorted(expected - given)
    extra = sorted(given - expected)
    if missing:
        shown = ", ".join(f"({t!r}, {s})" for t, s in missing[:10])
        more = f" and {len(missing) - 10} more" if len(missing) > 10 else ""
        problems.append(
            f"{len(missing)} episode(s) of suite {suite.name!r} are missing: {shown}{more}"
        )
    if extra:
        shown = ", ".join(f"({t!r}, {s})" for t, s in extra[:10])
        problems.append(f"{len(extra)} episode(s) are not in suite {suite.name!r}: {shown}")
    return problems


def _fail(source: Path, problems: Sequence[str]) -> InvalidSubmission:
    shown = list(problems[:MAX_REPORTED_PROBLEMS])
    if len(problems) > MAX_REPORTED_PROBLEMS:
        shown.append(f"... and {len(problems) - MAX_REPORTED_PROBLEMS} more")
    lines = "\n".join(f"  - {p}" for p in shown)
    return InvalidSubmission(f"submission {source} was refused ({len(problems)} problem(s)):\n{lines}")


def validate_submission(
    submission: Submission,
    suite_lookup: SuiteLookup | None = None,
    limits: SizeLimits = SizeLimits(),
    results_file: ResultsFile | None = None,
) -> ValidatedSubmission:
    """Check a submission without running it (see the module docstring for the checks).

    Args:
        submission: The submission.
        suite_lookup: ``name -> suite`` (default: ``swarmloc.bench.evaluation.suites.get_suite``).
        limits: File size limits.
        results_file: ``submission.results_path`` as read already (:func:`read_submitted_results`);
            read here when None. Its size is checked against ``limits`` either way.

    Returns:
        The validated submission, with the parsed results and the method hash.

    Raises:
        InvalidSubmission: naming the file and every problem found.
    """
    lookup = suite_lookup or default_suite_lookup
    path = submission.results_path
    if submission.weights_path is not None:
        _file_size(submission.weights_path, "weights file", limits.weights_bytes)
    if results_file is None:
        results_file = read_submitted_results(path, limits)
    elif results_file.path != Path(path):
        raise ValueError(f"results_file is {results_file.path}, but the submission names {path}")
    elif results_file.size > limits.results_bytes:
        raise InvalidSubmission(f"results file {path} is {results_file.size} bytes; "
                                f"the limit is {limits.results_bytes} bytes")
    results = results_file.results
    _refuse_subset(results, path)
    entry = parse_entry_point(submission.entry_point)
    meta = submission.metadata
    problems: list[str] = []
    if results.method.entry_point != submission.entry_point:
        problems.append(
            f"entry point {submission.entry_point!r} differs from the results file's "
            f"method.entry_point {results.method.entry_point!r}"
        )
    if results.method.track != meta.track:
        problems.append(f"track {meta.track!r} differs from the results' {results.method.track!r}")
    if results.method.privileged != meta.privileged:
        problems.append(
            f"privileged={meta.privileged} differs from the results' "
            f"privileged={results.method.privileged}"
        )
    weights_sha = None
    if submission.weights_path is not None:
        weights_sha = sha256_file(submission.weights_path)
    if weights_sha is None and results.method.weights_sha256 is not None:
        problems.append(
            f"the results were produced with a weights file (SHA-256 {results.method.weights_sha256}) "
            f"but none was given; pass the file given to `swarmloc evaluate --weights` as --weights"
        )
    elif weights_sha != results.method.weights_sha256:
        problems.append(
            f"weights file SHA-256 {weights_sha} differs from the results' "
            f"method.weights_sha256 {results.method.weights_sha256}"
        )
    try:
        suite = lookup(results.suite.name)
    except InvalidSubmission:
        raise
    except Exception as err:  # the registry's own error, e.g. KeyError for unknown names
        raise _fail(path, [f"unknown suite {results.suite.name!r}: {err}"]) from None
    if results.suite.version != suite.version:
        problems.append(
            f"suite {suite.name!r} version {results.suite.version!r} is not the current "
            f"version {suite.version!r}; re-evaluate on the current suite"
        )
    elif results.suite.sha256 != suite.sha256:
        problems.append(
            f"suite {suite.name!r} hash {results.suite.sha256} differs from the registered "
            f"{suite.sha256}; the (task, seed) list was changed"
        )
    problems += _coverage_problems(results, suite)
    problems += metric_problems(results)
    problems += coverage_problems(results)
    if not problems:
        problems += aggregate_problems(results) + score_problems(results)
    if problems:
        raise _fail(path, problems)
    search = [str(p) for p in submission.search_path]
    return ValidatedSubmission(
        submission=submission,
        results=results,
        results_text=results_file.text,
        suite=suite,
        entry=entry,
        method_hash=method_hash(submission.entry_point, weights_sha, search),
        weights_sha256=weights_sha,
    )


def make_submission(
    results_path: str | Path,
    entry_point: str,
    metadata: SubmissionMetadata | dict[str, Any],
    weights: str | Path | None = None,
    search_path: Sequence[str | Path] = (),
) -> Submission:
    """Build a :class:`Submission`, turning pydantic errors into :class:`InvalidSubmission`."""
    try:
        return Submission(
            results_path=Path(results_path),
            entry_point=entry_point,
            weights_path=None if weights is None else Path(weights),
            search_path=tuple(Path(p) for p in search_path),
            metadata=metadata,  # type: ignore[arg-type]  # a dict is validated as nested
        )
    except ValidationError as err:
        lines = []
        for item in err.errors():
            loc = ".".join(str(p) for p in item["loc"])
            lines.append(f"  - {loc}: {item['msg']}")
        raise InvalidSubmission(
            f"submission of {results_path} is malformed:\n" + "\n".join(lines)
        ) from None


__all__ = [
    "METRIC_BOUNDS",
    "REQUIRED_METRICS",
    "SUBMISSION_VERSION",
    "SUBSET_SUFFIX",
    "SizeLimits",
    "Submission",
    "SubmissionMetadata",
    "SuiteLike",
    "SuiteLookup",
    "ValidatedSubmission",
    "aggregate_problems",
    "coverage_problems",
    "default_suite_lookup",
    "make_submission",
    "method_hash",
    "metric_problems",
    "read_submitted_results",
    "score_problems",
    "validate_submission",
]
