"""The results file: what ``swarmloc evaluate`` writes and ``swarmloc submit`` reads.

One JSON document per (method, suite) evaluation, with exactly this top-level shape::

    {
      "schema_version": 6,
      "method":     {"name", "entry_point", "weights_sha256", "privileged", "track", "deterministic",
                     "privileged_training", "run", "flops_per_channel"},
      "suite":      {"name", "version", "sha256"},
      "provenance": {"package_version", "git_commit", "created_utc",
                     "python_version", "numpy_version", "torch_version",
                     "machine": {"platform", "cpu_count"}},
      "episodes":   [{"task", "seed", "metrics": {<every name in METRIC_NAMES>: float | null}}],
      "aggregates": {"<task id>": {"<metric>": {"mean", "iqm", "ci_low", "ci_high"} | null}},
      "score":      {"S", "ci_low", "ci_high", "times", "iqm", "gap_closed", "covered", "total",
                     "tasks": {"<task id>": {"gain", "achievable", "gap_closed"}},
                     "tracks": {"<track>": {"S", "ci_low", "ci_high", "times", "iqm", "gap_closed",
                                            "covered", "total"}} | null} | null
    }

A metric a task does not define (``fault_rmse`` on a fault-free task, say) is ``null``.
Files are written atomically (temporary file, fsync, ``os.replace``) so a reader never
sees half a file, and :func:`load_results` names the file and the problem when it is
truncated, corrupted or does not match the schema.

This module imports only the standard library and pydantic so that light tools (the
leaderboard, the verification worker's parent) can read results cheaply.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    ValidationError,
    model_validator,
)

from swarmloc.bench.common.files import write_bytes_atomic
from swarmloc.bench.common.provenance import MachineInfo, Provenance, collect_provenance  # noqa: F401  (re-exported)

SCHEMA_VERSION: Literal[6] = 6
"""Version of the results-file schema written by this module; bump on any change.

Version history: 1 — the first metrics, ``normalized_score`` among them; 2 — adds
``uniform_rmse`` (the standard CEKF on the same episode, the reference of the score) and
``bound_rmse`` (the episode's information bound); 3 — adds ``recovery_s`` and ``recovered``
(the faulty UAVs' recovery after an IMU fault); 4 — drops ``normalized_score`` (the retired
score against the oracle of the old fault labels); 5 — the ``score`` block adds ``tracks``, a
benchmark v2 suite's score per track (null for other suites and in older files); 6 — the ``method`` block
adds ``privileged_training``, ``run`` and ``flops_per_channel`` (how the method was made and what it costs;
an older file reads them as null: not declared).
"""
#: schema versions this module reads (an older file reads with the metrics it lacks null,
#: and without the retired ones)
READABLE_SCHEMA_VERSIONS = (1, 2, 3, 4, 5, 6)

METRIC_NAMES: tuple[str, ...] = (
    "rmse",
    "mean_error",
    "median_error",
    "max_error",
    "cep90",
    "fault_rmse",
    "healthy_rmse",
    "diverged",
    "delay_ms",
    "energy_j",
    "jitter",
    "weight_var",
    "anomaly_detection_rate",
    "team_return",
    "uniform_rmse",
    "bound_rmse",
    "recovery_s",
    "recovered",
)
"""Every per-episode metric, in the order they appear in results files."""
RETIRED_METRICS: dict[str, int] = {"normalized_score": 4}
"""Metrics that files of older schema versions hold and this one does not, with the schema
version that dropped them: reading such a file accepts them and leaves them out."""
SCHEMA_METRICS: dict[int, tuple[str, ...]] = {
    1: METRIC_NAMES[:METRIC_NAMES.index("uniform_rmse")],
    2: METRIC_NAMES[:METRIC_NAMES.index("recovery_s")],
    3: METRIC_NAMES,
    4: METRIC_NAMES,
    5: METRIC_NAMES,
    6: METRIC_NAMES,
}
"""The current metrics a results file of each schema version holds (the others read as null)."""

AGGREGATE_FIELDS: tuple[str, ...] = ("mean", "iqm", "ci_low", "ci_high")
"""Statistics kept per (task, metric): mean, interquartile mean, 95 % bootstrap CI of the mean."""


class ResultsFileError(ValueError):
    """A results file cannot be read: missing, truncated, corrupted or off-schema."""


def _reject_text(value: Any) -> Any:
    """Refuse strings where a number is expected (pydantic's lax mode would parse them)."""
    if isinstance(value, (str, bytes)):
        raise ValueError(f"expected a number or null, got the string {value!r}")
    return value


MetricValue = Annotated[float | None, BeforeValidator(_reject_text)]
"""A metric value: a float (``int``/``bool`` are widened) or ``None`` when undefined."""

_FROZEN = ConfigDict(extra="forbid", frozen=True, ser_json_inf_nan="constants")


class MethodInfo(BaseModel):
    """The evaluated method.

    Attributes:
        name: Human-readable method name.
        entry_point: ``module:factory``, ``path/to/file.py:factory`` or a registered name.
        weights_sha256: SHA-256 (hex) of the weights file, if the method loads one.
        privileged: True when the method reads privileged information (truth, fault labels).
        track: ``"A"`` (link trust inside the env's CEKF) or ``"B"`` (full estimator).
        deterministic: True when re-running an episode reproduces its metrics bit for bit.
        privileged_training: True when the method's weights were fitted to privileged labels (fault
            or error labels, read while training only); it runs without them (``privileged`` False).
            ``swarmloc evaluate`` always states it; null: not declared (files older than schema 6, and
            files rewritten from them, e.g. by ``refresh_bounds``).
        run: the training run these weights come from (the run seed, ``config.seed`` of the
            weights' training record); null for a method without one, or weights without a record.
            The leaderboard shows the runs of one method as one standing (docs/leaderboard.md).
        flops_per_channel: FLOPs the method declares per present channel per step (Track A;
            ``swarmloc.agents.protocols``); null where it declares none (Track B reports FLOPs per
            UAV-step in its output instead, which ``delay_ms`` counts).
    """

    model_config = _FROZEN

    name: str = Field(min_length=1, max_length=128)
    entry_point: str = Field(min_length=1, max_length=512)
    weights_sha256: str | None = Field(default=None, pattern=r"^[0-9a-f]{64}$")
    privileged: bool
    track: Literal["A", "B"]
    deterministic: bool
    privileged_training: bool | None = False
    run: Annotated[int, Field(strict=True, ge=0)] | None = None
    flops_per_channel: MetricValue = Field(default=None, ge=0.0, allow_inf_nan=False)


class SuiteInfo(BaseModel):
    """The suite the method was evaluated on.

    Attributes:
        name: Suite name, e.g. ``standard-v0``.
        version: Suite version string.
        sha256: SHA-256 (hex) of the suite's (task, seed) list, see :func:`suite_sha256`.
    """

    model_config = _FROZEN

    name: str = Field(min_length=1, max_length=128)
    version: str = Field(min_length=1, max_length=64)
    sha256: str = Field(pattern=r"^[0-9a-f]{64}$")


class EpisodeMetrics(BaseModel):
    """Per-episode metrics; every name in :data:`METRIC_NAMES` must be present (``null`` allowed)."""

    model_config = _FROZEN

    rmse: MetricValue
    mean_error: MetricValue
    median_error: MetricValue
    max_error: MetricValue
    cep90: MetricValue
    fault_rmse: MetricValue
    healthy_rmse: MetricValue
    diverged: MetricValue
    delay_ms: MetricValue
    energy_j: MetricValue
    jitter: MetricValue
    weight_var: MetricValue
    anomaly_detection_rate: MetricValue
    team_return: MetricValue
    uniform_rmse: MetricValue = None
    bound_rmse: MetricValue = None
    recovery_s: MetricValue = None
    recovered: MetricValue = None

    @classmethod
    def of(cls, **known: float | None) -> EpisodeMetrics:
        """Build metrics from the ones a task defines; the rest become ``None``.

        Raises:
            ValueError: if a name is not in :data:`METRIC_NAMES`.
        """
        unknown = sorted(set(known) - set(METRIC_NAMES))
        if unknown:
            raise ValueError(f"unknown metric name(s) {unknown}; allowed: {list(METRIC_NAMES)}")
        return cls.model_validate({name: known.get(name) for name in METRIC_NAMES})


class Episode(BaseModel):
    """One evaluated (task, seed) pair and its metrics."""

    model_config = _FROZEN

    task: str = Field(min_length=1, max_length=128)
    seed: int = Field(ge=0)
    metrics: EpisodeMetrics


class Aggregate(BaseModel):
    """Statistics of one metric over a task's seeds (the CI is for the mean)."""

    model_config = _FROZEN

    mean: float
    iqm: float
    ci_low: float
    ci_high: float


class TaskScoreBlock(BaseModel):
    """The score of one covered task (``swarmloc.bench.scoring.score``).

    Attributes:
        gain: ``G_t``, the mean over seeds of log2(RMSE_uniform / RMSE).
        achievable: ``A_t``, the mean of log2(RMSE_uniform / bound) (null where the bound is undefined).
        gap_closed: ``G_t / A_t`` where ``A_t ≥ log2 1.25``, else null.
    """

    model_config = _FROZEN

    gain: float
    achievable: float | None
    gap_closed: float | None


class TrackScoreBlock(BaseModel):
    """The score on one track of a benchmark v2 suite: its tasks scored as a suite of their own (score v2).

    Attributes:
        S, ci_low, ci_high: the track's score (families weigh equally) and its hierarchical-bootstrap 95 % CI.
        times: ``2^S``.
        iqm: interquartile mean of the track's covered episodes' gains.
        gap_closed: as the file's, over the track's tasks (null if none has one).
        covered, total: the track's tasks covered and evaluated.
    """

    model_config = _FROZEN

    S: float
    ci_low: float
    ci_high: float
    times: float
    iqm: float
    gap_closed: float | None
    covered: int = Field(ge=0)
    total: int = Field(ge=1)


class ScoreBlock(TrackScoreBlock):
    """The score of the whole file: ``S`` (log2 units; ``2^S`` × lower error than uniform) and its parts
    (a ``TrackScoreBlock``'s fields over every task the file ran, then these).

    Attributes:
        S, ci_low, ci_high: the suite score and its 95 % CI (score v1: stratified bootstrap;
            score v2, for a v2 suite: family-weighted, hierarchical bootstrap).
        times: ``2^S``.
        iqm: interquartile mean of the covered episodes' gains.
        gap_closed: mean over tasks of their gap closed (null if no task has one).
        covered, total: tasks covered and tasks evaluated.
        tasks: per covered task.
        tracks: a benchmark v2 suite's score per track, headline first (scores never mix tracks: the
            boards rank by these, and ``S`` above spans every task the file ran); a track the method
            covers no task of is absent. Null for other suites. No cooperation gain: it needs
            ``non-cooperative``'s RMSE per episode, which a file of another method does not hold.
    """

    tasks: dict[str, TaskScoreBlock]
    tracks: dict[str, TrackScoreBlock] | None = None


def score_block(episodes: Sequence[Episode], tasks: Sequence[str], suite: str | None = None) -> ScoreBlock | None:
    """The ``score`` block of a results file (None without ``uniform_rmse``, e.g. a version-1 file).

    ``suite`` (the suite's name) picks score v1 or v2 (``swarmloc.bench.scoring.score.score_version``);
    a v2 suite's block also holds the score of each track its tasks fall into
    (``swarmloc.bench.scoring.tracks.track_scores``).
    """
    # local: score imports stats, stats this module; tracks reads the task catalogue
    from swarmloc.bench.scoring.score import score_version, suite_score
    from swarmloc.bench.scoring.tracks import named_tracks, registered_track, track_scores

    dumped = [e.model_dump() for e in episodes]
    s = suite_score(dumped, list(tasks), suite=suite)
    if s is None:
        return None
    k, n = s.coverage
    tasks_block = {t: TaskScoreBlock(gain=v.mean, achievable=v.achievable, gap_closed=v.gap_closed)
                   for t, v in s.tasks.items()}
    tracks_block = None
    if score_version(suite) >= 2 and named_tracks(tasks):
        per_track = track_scores(dumped, list(tasks), suite=suite, track_of=registered_track)  # unregistered: no track
        tracks_block = {track: TrackScoreBlock(S=t.S, ci_low=t.ci_low, ci_high=t.ci_high, times=t.times, iqm=t.iqm,
                                               gap_closed=t.gap_closed, covered=t.coverage[0], total=t.coverage[1])
                        for track, t in per_track.items() if track is not None and t is not None}
    return ScoreBlock(S=s.S, ci_low=s.ci_low, ci_high=s.ci_high, times=s.times, iqm=s.iqm, gap_closed=s.gap_closed,
                      covered=k, total=n, tasks=tasks_block, tracks=tracks_block)


class Results(BaseModel):
    """A complete results file (see the module docstring for the shape)."""

    model_config = _FROZEN

    schema_version: Literal[1, 2, 3, 4, 5, 6] = SCHEMA_VERSION
    method: MethodInfo
    suite: SuiteInfo
    provenance: Provenance
    episodes: list[Episode] = Field(min_length=1)
    aggregates: dict[str, dict[str, Aggregate | None]]
    score: ScoreBlock | None = None

    @model_validator(mode="before")
    @classmethod
    def _read_older_versions(cls, raw: Any) -> Any:
        """An older file lacks the later versions' metrics: they read as null (aggregates included);
        it may hold retired metrics: they are accepted and left out (episodes and aggregates). A file
        older than schema 6 did not declare ``privileged_training``: it reads as null, not False."""
        version = raw.get("schema_version") if isinstance(raw, dict) else None
        if version not in SCHEMA_METRICS or version == SCHEMA_VERSION:
            return raw
        if version < 6 and isinstance(raw.get("method"), dict):  # how the method was made: not declared then
            raw = {**raw, "method": {"privileged_training": None, **raw["method"]}}
        retired = {name for name, dropped in RETIRED_METRICS.items() if version < dropped}

        def current(metrics: Any) -> Any:
            return {k: v for k, v in metrics.items() if k not in retired} if isinstance(metrics, dict) else metrics

        raw = dict(raw)
        if isinstance(raw.get("episodes"), list):
            raw["episodes"] = [{**e, "metrics": current(e.get("metrics"))} if isinstance(e, dict) else e
                               for e in raw["episodes"]]
        if isinstance(raw.get("aggregates"), dict):
            added = {name: None for name in METRIC_NAMES if name not in SCHEMA_METRICS[version]}
            raw["aggregates"] = {task: ({**added, **current(per)} if isinstance(per, dict) else per)
                                 for task, per in raw["aggregates"].items()}
        return raw

    @model_validator(mode="after")
    def _consistent(self) -> Results:
        """Episodes are unique and the aggregates cover exactly the evaluated tasks."""
        counts = Counter((e.task, e.seed) for e in self.episodes)
        repeated = sorted(k for k, n in counts.items() if n > 1)
        if repeated:
            raise ValueError(f"episodes listed more than once (task, seed): {repeated[:10]}")
        tasks = {e.task for e in self.episodes}
        if set(self.aggregates) != tasks:
            missing = sorted(tasks - set(self.aggregates))
            extra = sorted(set(self.aggregates) - tasks)
            raise ValueError(
                f"aggregates must have one entry per evaluated task; "
                f"missing {missing}, not evaluated {extra}"
            )
        for task, per_metric in self.aggregates.items():
            if set(per_metric) != set(METRIC_NAMES):
                raise ValueError(
                    f"aggregates[{task!r}] must list every metric in {list(METRIC_NAMES)} "
                    f"(null when undefined); got {sorted(per_metric)}"
                )
        return self

    def episode_keys(self) -> list[tuple[str, int]]:
        """The evaluated (task, seed) pairs in file order."""
        return [(e.task, e.seed) for e in self.episodes]


def suite_sha256(episodes: Iterable[tuple[str, int]], specs: Iterable[str] = ()) -> str:
    """Canonical SHA-256 of a suite's (task, seed) list, and of its task specs where given.

    The list is sorted first, so the hash names the set of episodes, not their order. The v1
    suites also pass the canonical JSON of every task's spec, so changing a task changes the
    hash; without specs (the v0 suites) the hash is that of the episode list alone.

    Args:
        episodes: (task ID, seed) pairs.
        specs: the tasks' spec JSON (``TaskSpec.model_dump_json()``), any order.

    Returns:
        Lower-case hex digest of the compact JSON ``[[task, seed], ...]``, or of
        ``{"episodes": [...], "specs": [sorted spec JSON]}`` when specs are given.
    """
    canonical = [list(pair) for pair in sorted((str(task), int(seed)) for task, seed in episodes)]
    specs = sorted(specs)
    payload = {"episodes": canonical, "specs": specs} if specs else canonical
    text = json.dumps(payload, separators=(",", ":"))
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def make_results(
    method: MethodInfo,
    suite: SuiteInfo,
    episodes: Sequence[Episode | Mapping[str, Any]],
    provenance: Provenance | None = None,
) -> Results:
    """Assemble a :class:`Results` from per-episode metrics, computing the aggregates.

    Args:
        method: The evaluated method.
        suite: The suite it ran on.
        episodes: ``Episode`` objects or dicts ``{"task", "seed", "metrics": {...}}``.
        provenance: Defaults to :func:`collect_provenance`.

    Returns:
        The validated results, aggregates from :func:`swarmloc.bench.scoring.stats.aggregate`
        and the ``score`` block from :func:`score_block`.
    """
    from swarmloc.bench.scoring.stats import aggregate  # local: stats imports this module

    parsed = [e if isinstance(e, Episode) else Episode.model_validate(e) for e in episodes]
    aggregates = aggregate(parsed)
    return Results(
        method=method,
        suite=suite,
        provenance=provenance or collect_provenance(),
        episodes=parsed,
        aggregates=aggregates,
        score=score_block(parsed, list(aggregates), suite.name),
    )


def dumps_results(results: Results) -> str:
    """Serialize results to the JSON text written by :func:`write_results`."""
    return results.model_dump_json(indent=1) + "\n"


def write_results(path: str | os.PathLike[str], results: Results) -> Path:
    """Write a results file atomically.

    The text goes to a temporary file in the same directory, is flushed and fsynced,
    then ``os.replace``-d over ``path``; the directory is fsynced too where possible.
    A crash at any point leaves either the old file or the new one, never half of one.

    Args:
        path: Destination file; its parent directory must exist.
        results: The results to write.

    Returns:
        The destination path.
    """
    return write_bytes_atomic(path, dumps_results(results).encode("utf-8"))


def _describe_validation_error(err: ValidationError, limit: int = 8) -> str:
    """Compact, readable list of pydantic errors: ``location: message``."""
    lines = []
    for item in err.errors()[:limit]:
        loc = ".".join(str(part) for part in item["loc"]) or "(top level)"
        lines.append(f"  {loc}: {item['msg']}")
    more = err.error_count() - limit
    if more > 0:
        lines.append(f"  ... and {more} more")
    return "\n".join(lines)


def _ends_inside_value(text: str) -> bool:
    """True when the text stops inside a string or with brackets left open."""
    depth, in_string, escaped = 0, False, False
    for char in text:
        if in_string:
            if escaped:
                escaped = False
            elif char == "\\":
                escaped = True
            elif char == '"':
                in_string = False
        elif char == '"':
            in_string = True
        elif char in "{[":
            depth += 1
        elif char in "}]":
            depth -= 1
    return in_string or depth > 0


def _decode(raw: bytes, source: str) -> str:
    """The file's text, or the error naming it as corrupted when it is not UTF-8."""
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as err:
        raise ResultsFileError(f"results file {source} is corrupted: not UTF-8 text ({err})") from None


def parse_results(text: str | bytes, source: str = "<results>") -> Results:
    """Parse and validate results JSON text.

    Args:
        text: The file contents.
        source: Name used in error messages (usually the path).

    Raises:
        ResultsFileError: naming ``source`` and what is wrong (bad JSON and where,
            likely truncation, unsupported schema version, or schema violations).
    """
    if isinstance(text, bytes):
        text = _decode(text, source)
    if not text.strip():
        raise ResultsFileError(f"results file {source} is empty")
    try:
        raw = json.loads(text)
    except json.JSONDecodeError as err:
        truncated = err.pos >= len(text.rstrip()) or _ends_inside_value(text)
        problem = "truncated (the JSON ends early)" if truncated else "corrupted (invalid JSON)"
        raise ResultsFileError(
            f"results file {source} is {problem}: {err.msg} (line {err.lineno}, "
            f"column {err.colno})"
        ) from None
    if not isinstance(raw, dict):
        raise ResultsFileError(
            f"results file {source} must hold a JSON object, got {type(raw).__name__}"
        )
    version = raw.get("schema_version")
    if version not in READABLE_SCHEMA_VERSIONS:
        newer = isinstance(version, int) and version > SCHEMA_VERSION
        raise ResultsFileError(
            f"results file {source} has schema_version {version!r}; this swarmloc reads schema versions "
            f"{', '.join(map(str, READABLE_SCHEMA_VERSIONS))}"
            + (" (the file was written by a newer swarmloc: upgrade to read it)" if newer else "")
        )
    try:
        return Results.model_validate(raw)
    except ValidationError as err:
        raise ResultsFileError(
            f"results file {source} does not match the results schema "
            f"({err.error_count()} problem(s)):\n{_describe_validation_error(err)}"
        ) from None


@dataclass(frozen=True)
class ResultsFile:
    """A results file as read once: where it came from, its exact text and the validated results.

    The leaderboard keeps the text as submitted (for download) and checks the results; both
    come from the one read, so what is stored is what was validated.

    Attributes:
        path: The file.
        text: Its exact contents.
        results: The validated results.
    """

    path: Path
    text: str
    results: Results

    @property
    def size(self) -> int:
        """The file's length in bytes."""
        return len(self.text.encode("utf-8"))


def read_results_file(path: str | os.PathLike[str], max_bytes: int | None = None) -> ResultsFile:
    """Read and validate a results file, keeping its exact text (what :func:`load_results` reads).

    Args:
        path: The file.
        max_bytes: Refuse files larger than this, if given: checked before reading, and no
            more than ``max_bytes + 1`` bytes are read (a file growing meanwhile is refused too).

    Returns:
        The path, the text and the validated :class:`Results`.

    Raises:
        ResultsFileError: as :func:`load_results`.
    """
    file = Path(path)
    try:
        size = file.stat().st_size
    except FileNotFoundError:
        raise ResultsFileError(f"results file {file} does not exist") from None
    except OSError as err:
        raise ResultsFileError(f"results file {file} cannot be read: {err.strerror or err}") from None
    if not file.is_file():
        raise ResultsFileError(f"results file {file} is not a regular file")
    if max_bytes is not None and size > max_bytes:
        raise ResultsFileError(f"results file {file} is {size} bytes; the limit is {max_bytes} bytes")
    try:
        with file.open("rb") as handle:
            raw = handle.read() if max_bytes is None else handle.read(max_bytes + 1)
    except OSError as err:
        raise ResultsFileError(f"results file {file} cannot be read: {err.strerror or err}") from None
    if max_bytes is not None and len(raw) > max_bytes:
        raise ResultsFileError(f"results file {file} grew past {max_bytes} bytes while it was read; "
                               f"the limit is {max_bytes} bytes")
    text = _decode(raw, str(file))
    return ResultsFile(path=file, text=text, results=parse_results(text, source=str(file)))


def load_results(path: str | os.PathLike[str], max_bytes: int | None = None) -> Results:
    """Read and validate a results file: the one reader of results files.

    Args:
        path: The file.
        max_bytes: Refuse files larger than this (checked before reading), if given.

    Returns:
        The validated :class:`Results`.

    Raises:
        ResultsFileError: naming the file and the problem: missing, too large, not
            UTF-8, truncated or otherwise invalid JSON, wrong schema version, or a
            schema violation (with the offending fields).
    """
    return read_results_file(path, max_bytes).results


__all__ = [
    "AGGREGATE_FIELDS",
    "METRIC_NAMES",
    "RETIRED_METRICS",
    "SCHEMA_METRICS",
    "SCHEMA_VERSION",
    "Aggregate",
    "Episode",
    "EpisodeMetrics",
    "MachineInfo",
    "MethodInfo",
    "Provenance",
    "Results",
    "ResultsFile",
    "ResultsFileError",
    "ScoreBlock",
    "SuiteInfo",
    "TaskScoreBlock",
    "TrackScoreBlock",
    "collect_provenance",
    "dumps_results",
    "load_results",
    "make_results",
    "parse_results",
    "read_results_file",
    "score_block",
    "suite_sha256",
    "write_results",
]
