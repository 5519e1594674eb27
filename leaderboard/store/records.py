"""Records of the leaderboard store: the ORM tables and the entry type views read.

Tables (generic SQLAlchemy types only, so SQLite and PostgreSQL share one schema):

* ``swarmloc_schema_version`` — one row, the schema version (see ``store.MIGRATIONS``);
* ``submissions`` — one row per accepted submission, unique on
  (method hash, suite name, suite version), with the submitted results file verbatim and
  its score (``score_mean`` is S, the mean over tasks of the per-task gain; ``score_iqm``
  the IQM of the episodes' gains; ``score_ci_*`` the 95 % CI of S), and how the method was made
  (``run``, ``privileged_training``) and what it declares it costs (``flops_per_channel``), from the
  results file's method block (null where an older file does not declare them);
* ``task_aggregates`` — mean, IQM and CI per (submission, task, metric).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from datetime import datetime, timezone
from typing import Any

from sqlalchemy import (
    BigInteger,
    DateTime,
    Float,
    ForeignKey,
    Integer,
    String,
    Text,
    UniqueConstraint,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship

from swarmloc.bench.evaluation.results import Aggregate


class Base(DeclarativeBase):
    """Declarative base of the store's tables."""


class SchemaVersionRow(Base):
    """The single row recording the schema version."""

    __tablename__ = "swarmloc_schema_version"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    version: Mapped[int] = mapped_column(Integer, nullable=False)


class SubmissionRow(Base):
    """One accepted submission."""

    __tablename__ = "submissions"
    __table_args__ = (
        UniqueConstraint("method_hash", "suite_name", "suite_version", name="uq_method_suite"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    created_utc: Mapped[datetime] = mapped_column(DateTime(timezone=True), nullable=False)
    name: Mapped[str] = mapped_column(String(64), nullable=False)
    authors: Mapped[str] = mapped_column(String(256), nullable=False)
    url: Mapped[str | None] = mapped_column(String(512))
    description: Mapped[str] = mapped_column(Text, nullable=False)
    track: Mapped[str] = mapped_column(String(1), nullable=False)
    privileged: Mapped[bool] = mapped_column(nullable=False)
    deterministic: Mapped[bool] = mapped_column(nullable=False)
    entry_point: Mapped[str] = mapped_column(String(512), nullable=False)
    method_hash: Mapped[str] = mapped_column(String(64), nullable=False)
    weights_sha256: Mapped[str | None] = mapped_column(String(64))
    suite_name: Mapped[str] = mapped_column(String(128), nullable=False)
    suite_version: Mapped[str] = mapped_column(String(64), nullable=False)
    suite_sha256: Mapped[str] = mapped_column(String(64), nullable=False)
    verified: Mapped[bool] = mapped_column(nullable=False)
    trusted: Mapped[bool] = mapped_column(nullable=False)
    verification_seed: Mapped[int | None] = mapped_column(BigInteger)
    verified_episodes: Mapped[int] = mapped_column(Integer, nullable=False)
    score_mean: Mapped[float | None] = mapped_column(Float)
    score_iqm: Mapped[float | None] = mapped_column(Float)
    score_ci_low: Mapped[float | None] = mapped_column(Float)
    score_ci_high: Mapped[float | None] = mapped_column(Float)
    delay_ms: Mapped[float | None] = mapped_column(Float)
    energy_j: Mapped[float | None] = mapped_column(Float)
    jitter: Mapped[float | None] = mapped_column(Float)
    package_version: Mapped[str] = mapped_column(String(64), nullable=False)
    git_commit: Mapped[str | None] = mapped_column(String(64))
    results_json: Mapped[str] = mapped_column(Text, nullable=False)
    run: Mapped[int | None] = mapped_column(BigInteger)
    privileged_training: Mapped[bool | None] = mapped_column()
    flops_per_channel: Mapped[float | None] = mapped_column(Float)

    aggregates: Mapped[list[TaskAggregateRow]] = relationship(
        back_populates="submission", cascade="all, delete-orphan", lazy="selectin"
    )


class TaskAggregateRow(Base):
    """Mean, IQM and 95 % CI of one metric on one task for one submission."""

    __tablename__ = "task_aggregates"
    __table_args__ = (
        UniqueConstraint("submission_id", "task", "metric", name="uq_submission_task_metric"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    submission_id: Mapped[int] = mapped_column(
        ForeignKey("submissions.id", ondelete="CASCADE"), nullable=False, index=True
    )
    task: Mapped[str] = mapped_column(String(128), nullable=False)
    metric: Mapped[str] = mapped_column(String(32), nullable=False)
    mean: Mapped[float] = mapped_column(Float, nullable=False)
    iqm: Mapped[float] = mapped_column(Float, nullable=False)
    ci_low: Mapped[float] = mapped_column(Float, nullable=False)
    ci_high: Mapped[float] = mapped_column(Float, nullable=False)

    submission: Mapped[SubmissionRow] = relationship(back_populates="aggregates")


@dataclass(frozen=True)
class EntryScore:
    """The score of a submission's own episodes (``swarmloc.bench.scoring.score``, docs/scoring.md).

    The same score the boards rank by (``ranking.Standing.score``), which also fills a missing
    ``uniform_rmse`` from the suite's ``uniform`` entry; here only the file's episodes count.

    Attributes:
        S: the suite score of the mean gains log2(RMSE_uniform / RMSE) (log2 units): mean over the
            covered tasks (score v1), or over families of their tasks' (score v2, v2 suites).
        ci_low, ci_high: its 95 % CI (stratified bootstrap; hierarchical under score v2).
        iqm: interquartile mean of the covered episodes' gains.
    """

    S: float
    ci_low: float
    ci_high: float
    iqm: float

    @property
    def times(self) -> float:
        """``2^S``: how many times lower the error is than uniform's."""
        return 2.0**self.S

    @property
    def times_ci(self) -> tuple[float, float]:
        """The CI of ``2^S``."""
        return 2.0**self.ci_low, 2.0**self.ci_high

    @classmethod
    def of(cls, episodes: Iterable[Mapping[str, Any]], suite: str | None = None) -> EntryScore | None:
        """The score of results-file episodes (``{"task", "seed", "metrics"}``; tasks in the order they
        appear) on the named suite (it picks score v1 or v2; None: v1); None when no task has a gain
        (no ``uniform_rmse``, or no episode the method ran)."""
        from swarmloc.bench.scoring.score import suite_score  # local: numpy, only when scoring

        s = suite_score(episodes, suite=suite)
        return None if s is None else cls(S=s.S, ci_low=s.ci_low, ci_high=s.ci_high, iqm=s.iqm)


@dataclass(frozen=True)
class LeaderboardEntry:
    """A stored submission, as views read it.

    ``score`` is the score of the submitted episodes (:class:`EntryScore`: S with its IQM of
    the gains and task-stratified 95 % CI); ``delay_ms``, ``energy_j``, ``jitter`` are means
    over all episodes; ``task_aggregates[task][metric]`` holds per-task statistics (undefined
    metrics absent). ``results_json`` is the submitted results file, byte for byte.
    ``run``, ``privileged_training`` and ``flops_per_channel`` are the results file's
    (``swarmloc.bench.evaluation.results.MethodInfo``): the training run of the weights (the board
    shows the runs of one method as one standing), weights fitted to privileged labels, the FLOPs
    the method declares per channel; None where the file does not say.
    """

    name: str
    authors: str
    url: str | None
    description: str
    track: str
    privileged: bool
    deterministic: bool
    entry_point: str
    method_hash: str
    weights_sha256: str | None
    suite_name: str
    suite_version: str
    suite_sha256: str
    verified: bool
    trusted: bool
    verification_seed: int | None
    verified_episodes: int
    score: EntryScore | None
    delay_ms: float | None
    energy_j: float | None
    jitter: float | None
    package_version: str
    git_commit: str | None
    results_json: str
    task_aggregates: dict[str, dict[str, Aggregate]] = field(default_factory=dict)
    created_utc: datetime = field(default_factory=lambda: datetime.now(timezone.utc))
    id: int | None = None
    run: int | None = None
    privileged_training: bool | None = None
    flops_per_channel: float | None = None

    @property
    def tasks(self) -> list[str]:
        """Task IDs with aggregates, sorted."""
        return sorted(self.task_aggregates)


__all__ = ["Base", "EntryScore", "LeaderboardEntry", "SchemaVersionRow", "SubmissionRow", "TaskAggregateRow"]
