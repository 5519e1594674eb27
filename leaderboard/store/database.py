"""The results store: accepted submissions in a SQL database (SQLAlchemy 2 ORM).

Where: the ``db_url`` argument, else the ``SWARMLOC_DB`` environment variable, else a
SQLite file ``leaderboard.db`` in ``platformdirs.user_data_dir("swarmloc")``. Only
portable SQL is used (ORM queries, generic column types), so a PostgreSQL URL such as
``postgresql+psycopg://user@host/db`` works unchanged (driver: ``pip install
'swarmloc[postgresql]'``).

Guarantees:

* **Schema versioning.** Table ``swarmloc_schema_version`` holds one row with the
  schema version. Opening a store creates a fresh schema, or upgrades an older one by
  applying :data:`MIGRATIONS` in order inside one transaction; a newer schema is refused.
* **Transactional writes.** A submission and its per-task aggregates are written in one
  transaction: a failure leaves the store unchanged.
* **Duplicates.** (method hash, suite name, suite version) is unique; a second submission
  raises :class:`~swarmloc.leaderboard.errors.DuplicateSubmission`.
* **Concurrency.** On SQLite, write transactions start with ``BEGIN IMMEDIATE`` (so two
  writers queue instead of dead-locking on a lock upgrade), wait on a busy timeout, and
  are retried with back-off if the database stays locked. On PostgreSQL, concurrent
  submissions of one method meet the unique constraint (one lands, the other is a
  duplicate), and schema creation or upgrade holds an advisory lock.

The test suite runs the same store tests on SQLite and on a throwaway PostgreSQL server
(``tests/test_leaderboard_store.py``).
"""

from __future__ import annotations

import json
import os
import random
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from datetime import timezone
from pathlib import Path
from typing import Any, TypeVar

from sqlalchemy import create_engine, delete, event, func, inspect, select, update
from sqlalchemy.engine import Connection, Engine, make_url
from sqlalchemy.exc import IntegrityError, OperationalError
from sqlalchemy.orm import Session

from swarmloc.bench.evaluation.results import Aggregate
from swarmloc.leaderboard.errors import DuplicateSubmission, StoreError
from swarmloc.leaderboard.store.records import (
    Base,
    EntryScore,
    LeaderboardEntry,
    SchemaVersionRow,
    SubmissionRow,
    TaskAggregateRow,
)

ENV_VAR: str = "SWARMLOC_DB"
"""Environment variable naming the store's database URL."""

SCHEMA_VERSION: int = 3
"""Schema version written by this code.

History: 1 — the ``score_*`` columns hold the retired normalized score (mean over all runs);
2 — they hold the score (``records.EntryScore``: S, its CI, the IQM of the gains), and the
retired metric has no per-task aggregates; 3 — ``submissions`` adds ``run``,
``privileged_training`` and ``flops_per_channel`` (results schema 6's method block).
"""


def _rescore(conn: Connection) -> None:
    """1 → 2: recompute every submission's score from its stored results file, and drop the
    per-task aggregates of the retired ``normalized_score``."""
    rows = SubmissionRow.__table__
    for row_id, text in conn.execute(select(rows.c.id, rows.c.results_json)).all():
        try:
            score = EntryScore.of(json.loads(text)["episodes"])
        except (ValueError, KeyError, TypeError):  # not a results file (a test's stub): no score
            score = None
        conn.execute(update(rows).where(rows.c.id == row_id).values(
            score_mean=score.S if score else None, score_iqm=score.iqm if score else None,
            score_ci_low=score.ci_low if score else None, score_ci_high=score.ci_high if score else None))
    aggregates = TaskAggregateRow.__table__
    conn.execute(delete(aggregates).where(aggregates.c.metric == "normalized_score"))


#: the columns schema 3 adds to ``submissions``, each filled from the stored results file's method block
_METHOD_COLUMNS = ("run", "privileged_training", "flops_per_channel")


def _method_columns(conn: Connection) -> None:
    """2 → 3: add ``run``, ``privileged_training`` and ``flops_per_channel`` to ``submissions`` (those it
    lacks) and fill them from every stored results file's method block (null where it does not say)."""
    rows = SubmissionRow.__table__
    present = {c["name"] for c in inspect(conn).get_columns(rows.name)}
    for name in _METHOD_COLUMNS:
        if name not in present:  # portable DDL: the column's type as this dialect spells it
            kind = rows.c[name].type.compile(dialect=conn.dialect)
            conn.exec_driver_sql(f"ALTER TABLE {rows.name} ADD COLUMN {name} {kind}")
    for row_id, text in conn.execute(select(rows.c.id, rows.c.results_json)).all():
        try:
            method = json.loads(text)["method"]
            values = {name: method.get(name) for name in _METHOD_COLUMNS}
        except (ValueError, KeyError, TypeError, AttributeError):  # not a results file (a test's stub)
            continue
        conn.execute(update(rows).where(rows.c.id == row_id).values(**values))


MIGRATIONS: dict[int, Callable[[Connection], None]] = {1: _rescore, 2: _method_columns}
"""``from_version -> upgrade(connection)`` bringing a store from ``v`` to ``v + 1``.

Add an entry (and bump :data:`SCHEMA_VERSION`) whenever the tables change; each step
runs inside the opening transaction, so a failed upgrade leaves the old schema intact.
Use portable DDL (``sqlalchemy`` constructs or ANSI SQL) so PostgreSQL stores upgrade too.
"""

_SHIPPED_TRACK_A: tuple[str, ...] = (
    "uniform", "fixed", "huber", "chi2-gate", "chi2-soft", "federated-coef", "cusum", "raim", "non-cooperative",
    "random", "oracle", "cusum-chi2",
    "huber-tuned", "chi2-gate-tuned", "chi2-soft-tuned", "cusum-tuned", "raim-tuned", "cusum-chi2-tuned",
    "mappo", "mappo-no-smoothing", "mappo-no-isolation", "mappo-accuracy-only", "mappo-set-gru", "supervised-trust",
)
_SHIPPED_TRACK_B: tuple[str, ...] = (
    "dead-reckoning", "imm-kf", "imm-ekf", "imm-arkf", "federated", "federated-fdi", "ci-ekf", "ci-ekf-no-aa",
    "pf", "pf-800", "adaptive-pf", "pf-nn", "centralized-oracle", "isam2-robust",
)

SHIPPED_REFERENCE_METHODS: frozenset[str] = frozenset(
    (*_SHIPPED_TRACK_A, *_SHIPPED_TRACK_B, *(f"{name}+smooth" for name in _SHIPPED_TRACK_A))
)
"""Registered names of the reference methods shipped with swarmloc (and their Track A
``+smooth`` variants).

Only these entry points may be submitted with ``trust=True`` (verification skipped). It
mirrors ``swarmloc.agents.registry.REGISTRY`` (the leaderboard may not import agents); a
test keeps the two in sync.
"""

_RETRIES = 8
_SCHEMA_LOCK_KEY = 0x5357_4C4F  # "SWLO": PostgreSQL advisory lock held while creating or upgrading the schema


def duplicate_error(entry_point: str, method_hash: str, suite_name: str, suite_version: str,
                    existing: int | None) -> DuplicateSubmission:
    """The error for a method already stored on a suite (``existing``: its ID if known)."""
    return DuplicateSubmission(
        f"method {entry_point!r} (hash {method_hash[:12]}…) is already on the leaderboard "
        f"for suite {suite_name!r} version {suite_version!r}"
        + (f" as submission #{existing}" if existing is not None else "")
        + "; change the method or its weights to submit again"
    )


def default_db_url() -> str:
    """``SWARMLOC_DB`` if set, else the SQLite file under the user data directory."""
    env = os.environ.get(ENV_VAR)
    if env:
        return env
    from platformdirs import user_data_dir

    return f"sqlite:///{Path(user_data_dir('swarmloc')) / 'leaderboard.db'}"


T = TypeVar("T")


class LeaderboardStore:
    """Accepted submissions, in SQLite by default or any SQLAlchemy database URL.

    Args:
        db_url: Database URL; default :func:`default_db_url`.
        busy_timeout_s: SQLite only: how long a writer waits for the lock per attempt.

    Raises:
        StoreError: if the URL is invalid, the database cannot be opened, or its schema
            is newer than this code or unknown.
    """

    def __init__(self, db_url: str | None = None, *, busy_timeout_s: float = 30.0) -> None:
        raw = db_url or default_db_url()
        try:
            url = make_url(raw)
        except Exception as err:  # sqlalchemy raises ArgumentError
            raise StoreError(f"invalid database URL {raw!r}: {err}") from None
        self._is_sqlite = url.get_backend_name() == "sqlite"
        self.database_file: Path | None = None
        """The SQLite file (None for other databases and in-memory SQLite)."""
        if self._is_sqlite and url.database not in (None, "", ":memory:"):
            self.database_file = Path(url.database).expanduser().resolve()
            self.database_file.parent.mkdir(parents=True, exist_ok=True)
        try:
            self._engine = create_engine(url)
        except Exception as err:  # missing driver, bad options
            raise StoreError(f"cannot open database {url.render_as_string()}: {err}") from None
        self._write_engine: Engine = self._engine
        if self._is_sqlite:
            self._configure_sqlite(self._engine, busy_timeout_s)
            self._write_engine = self._engine.execution_options(swarmloc_begin="IMMEDIATE")
        self.url = url.render_as_string(hide_password=True)
        self._ensure_schema()

    # -- connection set-up -------------------------------------------------------------

    @staticmethod
    def _configure_sqlite(engine: Engine, busy_timeout_s: float) -> None:
        @event.listens_for(engine, "connect")
        def _on_connect(dbapi_connection: Any, _record: Any) -> None:
            # We issue BEGIN ourselves (below), so pysqlite must not.
            dbapi_connection.isolation_level = None
            cursor = dbapi_connection.cursor()
            cursor.execute(f"PRAGMA busy_timeout = {int(busy_timeout_s * 1000)}")
            cursor.execute("PRAGMA foreign_keys = ON")
            cursor.close()

        @event.listens_for(engine, "begin")
        def _on_begin(connection: Connection) -> None:
            mode = connection.get_execution_options().get("swarmloc_begin", "DEFERRED")
            connection.exec_driver_sql(f"BEGIN {mode}")

    def _retrying(self, work: Callable[[], T]) -> T:
        """Run ``work``; on SQLite retry with back-off while the database is locked."""
        for attempt in range(_RETRIES):
            try:
                return work()
            except OperationalError as err:
                locked = "locked" in str(err).lower() or "busy" in str(err).lower()
                if not (self._is_sqlite and locked) or attempt == _RETRIES - 1:
                    raise
                time.sleep(min(2.0, 0.05 * 2**attempt) * (0.5 + random.random()))
        raise AssertionError("unreachable")  # pragma: no cover

    @contextmanager
    def _writing(self) -> Iterator[Session]:
        with Session(self._write_engine, expire_on_commit=False) as session, session.begin():
            yield session

    @contextmanager
    def _reading(self) -> Iterator[Session]:
        with Session(self._engine) as session, session.begin():
            yield session

    # -- schema ----------------------------------------------------------------------

    def _ensure_schema(self) -> None:
        def work() -> None:
            with self._write_engine.begin() as conn:
                if conn.dialect.name == "postgresql":
                    # Two processes opening a fresh store would both create the tables; this
                    # lock (released at commit) makes the second wait, then see them.
                    conn.exec_driver_sql(f"SELECT pg_advisory_xact_lock({_SCHEMA_LOCK_KEY})")
                tables = set(inspect(conn).get_table_names())
                if SchemaVersionRow.__tablename__ not in tables:
                    if tables & {SubmissionRow.__tablename__, TaskAggregateRow.__tablename__}:
                        raise StoreError(
                            f"database {self.url} has leaderboard tables but no "
                            f"{SchemaVersionRow.__tablename__} table; refusing to guess its version"
                        )
                    Base.metadata.create_all(conn)
                    with Session(conn) as session:
                        session.add(SchemaVersionRow(id=1, version=SCHEMA_VERSION))
                        session.flush()
                    return
                with Session(conn) as session:
                    row = session.get(SchemaVersionRow, 1)
                    version = row.version if row is not None else None
                    if version is None:
                        raise StoreError(f"database {self.url} has an empty schema version table")
                    if version > SCHEMA_VERSION:
                        raise StoreError(
                            f"database {self.url} has schema version {version}; this swarmloc "
                            f"supports up to {SCHEMA_VERSION}. Upgrade swarmloc."
                        )
                    while version < SCHEMA_VERSION:
                        if version not in MIGRATIONS:
                            raise StoreError(
                                f"no migration from schema version {version} to {version + 1}"
                            )
                        MIGRATIONS[version](conn)
                        version += 1
                    assert row is not None
                    row.version = version
                    session.flush()

        try:
            self._retrying(work)
        except OperationalError as err:
            raise StoreError(f"cannot open database {self.url}: {err.orig}") from None

    def schema_version(self) -> int:
        """The schema version recorded in the database."""
        with self._reading() as session:
            row = session.get(SchemaVersionRow, 1)
            assert row is not None
            return row.version

    # -- writes ----------------------------------------------------------------------

    @staticmethod
    def _existing_id(session: Session, method_hash: str, suite_name: str,
                     suite_version: str) -> int | None:
        return session.scalar(
            select(SubmissionRow.id).where(
                SubmissionRow.method_hash == method_hash,
                SubmissionRow.suite_name == suite_name,
                SubmissionRow.suite_version == suite_version,
            )
        )

    def ensure_new(self, entry_point: str, method_hash: str, suite_name: str,
                   suite_version: str) -> None:
        """Raise :class:`DuplicateSubmission` if this method is stored for this suite."""
        with self._reading() as session:
            existing = self._existing_id(session, method_hash, suite_name, suite_version)
        if existing is not None:
            raise duplicate_error(entry_point, method_hash, suite_name, suite_version, existing)

    def add(self, entry: LeaderboardEntry, *, replace_reference: bool = False) -> int:
        """Store a submission and its per-task aggregates in one transaction.

        Args:
            entry: The submission (its ``id`` is ignored).
            replace_reference: a trusted entry (a shipped reference method) stored for the
                same method hash and suite whose results differ from ``entry``'s is deleted in
                the same transaction. A registered method's hash covers its name and weights,
                not its code, so a release that changes how a reference method runs ships new
                results under the same hash.

        Returns:
            The new submission ID.

        Raises:
            DuplicateSubmission: same method hash and suite already stored (with the same
                results, or not trusted, when ``replace_reference``).
        """
        columns = {c.key for c in SubmissionRow.__table__.columns} - {"id"}
        values = {k: getattr(entry, k) for k in columns if k not in ("score_mean", "score_iqm",
                                                                    "score_ci_low", "score_ci_high")}
        score = entry.score
        values.update(
            score_mean=score.S if score else None,
            score_iqm=score.iqm if score else None,
            score_ci_low=score.ci_low if score else None,
            score_ci_high=score.ci_high if score else None,
        )

        def work() -> int:
            with self._writing() as session:
                existing = self._existing_id(
                    session, entry.method_hash, entry.suite_name, entry.suite_version
                )
                if existing is not None:
                    stale = session.get(SubmissionRow, existing)
                    if not (replace_reference and stale.trusted and stale.results_json != entry.results_json):
                        raise duplicate_error(entry.entry_point, entry.method_hash,
                                              entry.suite_name, entry.suite_version, existing)
                    session.delete(stale)
                    session.flush()
                row = SubmissionRow(**values)
                row.aggregates = [
                    TaskAggregateRow(task=task, metric=metric, **agg.model_dump())
                    for task, per_metric in sorted(entry.task_aggregates.items())
                    for metric, agg in per_metric.items()
                ]
                session.add(row)
                session.flush()
                return row.id

        try:
            return self._retrying(work)
        except IntegrityError:  # a concurrent writer stored the same method first
            raise duplicate_error(entry.entry_point, entry.method_hash, entry.suite_name,
                                  entry.suite_version, None) from None

    # -- reads -----------------------------------------------------------------------

    @staticmethod
    def _to_entry(row: SubmissionRow) -> LeaderboardEntry:
        per_task: dict[str, dict[str, Aggregate]] = {}
        for agg in row.aggregates:
            per_task.setdefault(agg.task, {})[agg.metric] = Aggregate(
                mean=agg.mean, iqm=agg.iqm, ci_low=agg.ci_low, ci_high=agg.ci_high
            )
        score = None
        if row.score_mean is not None:
            score = EntryScore(
                S=row.score_mean,
                iqm=row.score_iqm if row.score_iqm is not None else row.score_mean,
                ci_low=row.score_ci_low if row.score_ci_low is not None else row.score_mean,
                ci_high=row.score_ci_high if row.score_ci_high is not None else row.score_mean,
            )
        created = row.created_utc
        if created.tzinfo is None:  # SQLite keeps no zone; we always store UTC
            created = created.replace(tzinfo=timezone.utc)
        return LeaderboardEntry(
            id=row.id,
            created_utc=created,
            name=row.name,
            authors=row.authors,
            url=row.url,
            description=row.description,
            track=row.track,
            privileged=row.privileged,
            deterministic=row.deterministic,
            entry_point=row.entry_point,
            method_hash=row.method_hash,
            weights_sha256=row.weights_sha256,
            suite_name=row.suite_name,
            suite_version=row.suite_version,
            suite_sha256=row.suite_sha256,
            verified=row.verified,
            trusted=row.trusted,
            verification_seed=row.verification_seed,
            verified_episodes=row.verified_episodes,
            score=score,
            delay_ms=row.delay_ms,
            energy_j=row.energy_j,
            jitter=row.jitter,
            package_version=row.package_version,
            git_commit=row.git_commit,
            results_json=row.results_json,
            task_aggregates=per_task,
            run=row.run,
            privileged_training=row.privileged_training,
            flops_per_channel=row.flops_per_channel,
        )

    def entries(self, suite_name: str | None = None) -> list[LeaderboardEntry]:
        """All stored submissions (optionally of one suite), oldest first."""
        query = select(SubmissionRow).order_by(SubmissionRow.id)
        if suite_name is not None:
            query = query.where(SubmissionRow.suite_name == suite_name)
        with self._reading() as session:
            return [self._to_entry(row) for row in session.scalars(query)]

    def get(self, entry_id: int) -> LeaderboardEntry:
        """One stored submission by ID; ``KeyError`` naming the ID when absent."""
        with self._reading() as session:
            row = session.get(SubmissionRow, entry_id)
            if row is None:
                raise KeyError(f"no submission #{entry_id} in {self.url}")
            return self._to_entry(row)

    def count(self) -> int:
        """Number of stored submissions."""
        with self._reading() as session:
            return int(session.scalar(select(func.count()).select_from(SubmissionRow)) or 0)

    def close(self) -> None:
        """Release all connections."""
        self._engine.dispose()

    def __enter__(self) -> LeaderboardStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


__all__ = [
    "ENV_VAR",
    "duplicate_error",
    "MIGRATIONS",
    "SCHEMA_VERSION",
    "SHIPPED_REFERENCE_METHODS",
    "EntryScore",
    "LeaderboardEntry",
    "LeaderboardStore",
    "default_db_url",
]
