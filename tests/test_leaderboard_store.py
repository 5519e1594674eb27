"""The leaderboard store against SQLite *and* a real PostgreSQL server.

Every test here runs twice: on a SQLite file and on a fresh database of a throwaway
PostgreSQL server started for this module (``lb_postgres``: ``initdb`` + ``pg_ctl`` in a
temporary folder). Without the server binaries or the psycopg driver the PostgreSQL half
is skipped with the reason — or fails, when ``SWARMLOC_REQUIRE_POSTGRES=1`` (CI).
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import textwrap
import time
from collections.abc import Iterator
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import lb_helpers as H
import lb_postgres
import pytest
from sqlalchemy import MetaData, create_engine, event, inspect, select
from sqlalchemy.orm import Session

from swarmloc.bench.evaluation.results import Aggregate
from swarmloc.leaderboard.store import database as store_module
from swarmloc.leaderboard.errors import DuplicateSubmission, StoreError, VerificationFailed
from swarmloc.leaderboard.store.records import EntryScore, LeaderboardEntry
from swarmloc.leaderboard.store.database import LeaderboardStore
from swarmloc.leaderboard.submit.pipeline import submit


@pytest.fixture(scope="module")
def postgres() -> Iterator[lb_postgres.ThrowawayPostgres]:
    """One throwaway server for the module."""
    reason = lb_postgres.unavailable_reason()
    if reason is not None:
        if os.environ.get(lb_postgres.REQUIRE_ENV) == "1":
            pytest.fail(f"{lb_postgres.REQUIRE_ENV}=1 but {reason}")
        pytest.skip(reason)
    with lb_postgres.throwaway_postgres() as server:
        yield server


@pytest.fixture(params=["sqlite", "postgresql"])
def empty_url(request: pytest.FixtureRequest, tmp_path: Path) -> str:
    """URL of an empty database on each backend (the store creates its schema on open)."""
    if request.param == "sqlite":
        return f"sqlite:///{tmp_path / 'lb.db'}"
    return request.getfixturevalue("postgres").new_database()


@pytest.fixture
def db_url(empty_url: str, tmp_path: Path) -> str:
    """A store holding one accepted submission."""
    _submit(H.make_results_file(tmp_path / "seed.json", "lb_fake_runner:good_seed"),
            "lb_fake_runner:good_seed", empty_url, {"name": "seed method", "track": "A"})
    return empty_url


def _submit(path: Path, entry_point: str, db_url: str, meta: dict[str, Any] | None = None, **overrides: Any):
    return submit(path, entry_point, meta or {"name": "good method", "track": "A"},
                  **(H.submit_options(db_url) | overrides))


def dump(db_url: str) -> dict[str, list[tuple[Any, ...]]]:
    """Every row of every table, in primary-key order: the store's complete content."""
    engine = create_engine(db_url)
    try:
        tables = MetaData()
        tables.reflect(engine)
        with engine.connect() as conn:
            return {name: [tuple(row) for row in conn.execute(select(table).order_by(*table.primary_key.columns))]
                    for name, table in sorted(tables.tables.items())}
    finally:
        engine.dispose()


def _entry(**changes: Any) -> LeaderboardEntry:
    """An entry with awkward values in every field."""
    values: dict[str, Any] = {
        "name": "Ünïcødé 🛰 'quoted' \"name\"",
        "authors": "O'Brien; --",
        "url": "https://example.org/a?b=c&d=%20",
        "description": "line one\n\ttab\nπ ≈ 3.14159 " + "x" * 1900,
        "track": "B",
        "privileged": True,
        "deterministic": False,
        "entry_point": "pkg.sub_module:make_method",
        "method_hash": "f" * 64,
        "weights_sha256": "0123456789abcdef" * 4,
        "suite_name": "tiny-test",
        "suite_version": "1",
        "suite_sha256": "a" * 64,
        "verified": True,
        "trusted": False,
        "verification_seed": 2**63 - 1,
        "verified_episodes": 55,
        "score": EntryScore(S=0.1 + 0.2, iqm=-1e-300, ci_low=-1.7976931348623157e308, ci_high=5e-324),
        "delay_ms": 0.013733333333333408,
        "energy_j": 2.2250738585072014e-308,
        "jitter": None,
        "package_version": "0.1.0+local.build",
        "git_commit": "deadbeef" * 5,
        "results_json": '{"schema_version": 1, "é": "\\u0000 escaped NUL stays text"}',
        "task_aggregates": {
            "swarmloc/Ideal-v0": {"rmse": Aggregate(mean=1 / 3, iqm=2 / 3, ci_low=0.0, ci_high=1e300)},
            "swarmloc/NLOS-v0": {"rmse": Aggregate(mean=math.pi, iqm=math.e, ci_low=-0.0, ci_high=7.0),
                                 "jitter": Aggregate(mean=1e-12, iqm=1e-13, ci_low=0.0, ci_high=2e-12)},
        },
        "created_utc": datetime(2026, 11, 22, 3, 4, 5, 678901, tzinfo=timezone.utc),
    }
    return LeaderboardEntry(**(values | changes))


# -- every field, every type -----------------------------------------------------------


def test_every_field_round_trips_exactly(empty_url: str) -> None:
    entry = _entry()
    bare = _entry(method_hash="e" * 64, url=None, weights_sha256=None, git_commit=None, score=None,
                  delay_ms=None, energy_j=None, verification_seed=None, task_aggregates={}, privileged=False)
    with LeaderboardStore(empty_url) as store:
        ids = [store.add(entry), store.add(bare)]
    with LeaderboardStore(empty_url) as store:  # a fresh connection: nothing served from a cache
        for new_id, original in zip(ids, (entry, bare), strict=True):
            got = store.get(new_id)
            assert got.id == new_id
            for name in LeaderboardEntry.__dataclass_fields__:
                if name != "id":
                    assert getattr(got, name) == getattr(original, name), name
            assert got.created_utc.utcoffset().total_seconds() == 0
        assert [e.id for e in store.entries()] == ids and store.count() == 2


def test_columns_have_the_intended_types(empty_url: str) -> None:
    LeaderboardStore(empty_url).close()
    engine = create_engine(empty_url)
    try:
        columns = {c["name"]: c for c in inspect(engine).get_columns("submissions")}
    finally:
        engine.dispose()
    kinds = {name: type(c["type"]).__name__.upper() for name, c in columns.items()}
    assert kinds["verification_seed"] == "BIGINT"
    assert kinds["name"] == "VARCHAR" and columns["name"]["type"].length == 64
    assert kinds["results_json"] == "TEXT"
    if empty_url.startswith("postgresql"):
        assert kinds["created_utc"] == "TIMESTAMP" and columns["created_utc"]["type"].timezone
        assert kinds["score_mean"] == "DOUBLE_PRECISION" and kinds["privileged"] == "BOOLEAN"


def test_sql_metacharacters_are_stored_verbatim(db_url: str, tmp_path: Path) -> None:
    name = "Robert'); DROP TABLE submissions;-- \" % _ \\"
    path = H.make_results_file(tmp_path / "sql.json", "lb_fake_runner:good_sql")
    receipt = _submit(path, "lb_fake_runner:good_sql", db_url, {"name": name, "track": "A", "authors": "O'Brien; --"})
    with LeaderboardStore(db_url) as store:
        assert store.get(receipt.id).name == name
        assert store.get(receipt.id).authors == "O'Brien; --"
        assert store.count() == 2


# -- transactions ------------------------------------------------------------------------


def test_a_write_that_fails_midway_leaves_the_store_unchanged(db_url: str, tmp_path: Path) -> None:
    path = H.make_results_file(tmp_path / "mid.json", "lb_fake_runner:good_mid")
    before = dump(db_url)

    def fail_after_flush(session: Session, _context: Any) -> None:
        raise RuntimeError("disk unplugged after the rows were written")

    event.listen(Session, "after_flush", fail_after_flush)
    try:
        with pytest.raises(RuntimeError, match="disk unplugged"):
            _submit(path, "lb_fake_runner:good_mid", db_url)
    finally:
        event.remove(Session, "after_flush", fail_after_flush)
    assert dump(db_url) == before


def test_a_rejected_submission_leaves_no_rows(db_url: str, tmp_path: Path) -> None:
    before = dump(db_url)
    tampered = H.make_results_file(
        tmp_path / "bad.json", "lb_fake_runner:good_bad",
        metrics_edit=lambda t, s, m: m.update(rmse=m["rmse"] * 0.5) if s == H.SEEDS[0] else None,
    )
    with pytest.raises(VerificationFailed, match=r"rmse: submitted [0-9.]+, re-run gave"):
        _submit(tampered, "lb_fake_runner:good_bad", db_url, sample_frac=1.0)
    with pytest.raises(DuplicateSubmission, match="already on the leaderboard"):
        _submit(H.make_results_file(tmp_path / "again.json", "lb_fake_runner:good_seed"),
                "lb_fake_runner:good_seed", db_url)
    assert dump(db_url) == before


# -- concurrency ---------------------------------------------------------------------------


CONCURRENT_SUBMIT = textwrap.dedent(
    """
    import sys, time
    sys.path.insert(0, {tests!r})
    import lb_helpers as H
    from swarmloc.leaderboard.errors import DuplicateSubmission
    from swarmloc.leaderboard.store.database import LeaderboardStore
    from swarmloc.leaderboard.submit.pipeline import submit
    url, path, entry, name, start, extra = sys.argv[1:7]
    time.sleep(max(0.0, float(start) - time.time()))
    try:
        submit(path, entry, {{"name": name, "track": "A"}}, **H.submit_options(url))
    except DuplicateSubmission as err:
        print("duplicate", err)
        sys.exit(0)
    # Then hammer the store layer directly so the two writers really overlap.
    with LeaderboardStore(url) as store:
        base = next(e for e in store.entries() if e.name == name)
        for i in range(int(extra)):
            store.add(base.__class__(**{{**base.__dict__, "method_hash": f"{{name}}-{{i:03d}}".ljust(64, "0"),
                                         "id": None}}))
    print("stored", name)
    """
)


def _race(url: str, jobs: list[tuple[Path, str, str]], extra: int) -> list[str]:
    """Start one submitting process per job at the same instant; their outputs."""
    start = time.time() + 2.0
    procs = [
        subprocess.Popen([sys.executable, "-c", CONCURRENT_SUBMIT.format(tests=str(H.TESTS_DIR)),
                          url, str(path), entry, name, str(start), str(extra)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        for path, entry, name in jobs
    ]
    outputs = [p.communicate(timeout=120) for p in procs]
    for proc, (_out, err) in zip(procs, outputs, strict=True):
        assert proc.returncode == 0, err
    return [out for out, _err in outputs]


def test_concurrent_submits_from_two_processes_both_land(db_url: str, tmp_path: Path) -> None:
    jobs = []
    for name in ("alpha", "beta"):
        entry = f"lb_fake_runner:good_{name}"
        jobs.append((H.make_results_file(tmp_path / f"{name}.json", entry), entry, name))
    outputs = _race(db_url, jobs, extra=15)
    assert all(out.startswith("stored") for out in outputs), outputs
    with LeaderboardStore(db_url) as store:
        entries = store.entries()
    names = [e.name for e in entries]
    assert names.count("alpha") == 16 and names.count("beta") == 16 and len(names) == 33
    assert len({(e.method_hash, e.suite_name, e.suite_version) for e in entries}) == 33


def test_the_same_method_submitted_twice_at_once_lands_once(empty_url: str, tmp_path: Path) -> None:
    entry = "lb_fake_runner:good_twin"
    path = H.make_results_file(tmp_path / "twin.json", entry)
    outputs = _race(empty_url, [(path, entry, "twin one"), (path, entry, "twin two")], extra=0)
    assert sorted(out.split()[0] for out in outputs) == ["duplicate", "stored"], outputs
    with LeaderboardStore(empty_url) as store:
        assert store.count() == 1
        stored = store.entries()[0]
    assert len(dump(empty_url)["task_aggregates"]) == sum(len(m) for m in stored.task_aggregates.values())


OPEN_STORE = textwrap.dedent(
    """
    import sys, time
    from swarmloc.leaderboard.store.database import LeaderboardStore
    time.sleep(max(0.0, float(sys.argv[2]) - time.time()))
    with LeaderboardStore(sys.argv[1]) as store:
        print(store.schema_version(), store.count())
    """
)


def test_two_processes_creating_a_fresh_store_at_once(empty_url: str) -> None:
    start = str(time.time() + 1.5)
    procs = [subprocess.Popen([sys.executable, "-c", OPEN_STORE, empty_url, start],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(3)]
    for proc in procs:
        out, err = proc.communicate(timeout=60)
        assert proc.returncode == 0, err
        assert out.split() == [str(store_module.SCHEMA_VERSION), "0"]
    assert dump(empty_url)["swarmloc_schema_version"] == [(1, store_module.SCHEMA_VERSION)]


# -- schema versions ---------------------------------------------------------------------


def test_schema_version_and_migration_path(empty_url: str, monkeypatch: pytest.MonkeyPatch) -> None:
    with LeaderboardStore(empty_url) as store:
        assert store.schema_version() == store_module.SCHEMA_VERSION == 3
    applied = []

    def to_v4(conn: Any) -> None:
        conn.exec_driver_sql("CREATE TABLE probe_v4 (id INTEGER PRIMARY KEY)")
        applied.append(4)

    monkeypatch.setattr(store_module, "SCHEMA_VERSION", 4)
    monkeypatch.setitem(store_module.MIGRATIONS, 3, to_v4)
    with LeaderboardStore(empty_url) as store:
        assert store.schema_version() == 4 and applied == [4]
    with LeaderboardStore(empty_url):  # already upgraded: nothing re-applied
        assert applied == [4]
    assert "probe_v4" in dump(empty_url)
    monkeypatch.setattr(store_module, "SCHEMA_VERSION", 3)
    with pytest.raises(StoreError, match=r"schema version 4; this swarmloc supports up to 3"):
        LeaderboardStore(empty_url)


def test_a_version_1_store_is_rescored(empty_url: str, tmp_path: Path) -> None:
    """1 → 2: the score columns held the retired normalized score; they are recomputed from each stored
    results file (the score, ``EntryScore``), and the retired metric's per-task aggregates are dropped."""
    import json

    from sqlalchemy import text

    gain = 0.4
    path = H.make_results_file(tmp_path / "scored.json", "lb_fake_runner:scored_high",
                               metrics_edit=lambda t, s, m: m.update(uniform_rmse=m["rmse"] * 2.0**gain))
    scored = _entry(method_hash="1" * 64, results_json=path.read_text(), score=None)
    stub = _entry(method_hash="2" * 64)  # a results_json that is not a results file: no score
    with LeaderboardStore(empty_url) as store:
        ids = [store.add(scored), store.add(stub)]
    engine = create_engine(empty_url)
    try:
        with engine.begin() as conn:  # what a version-1 store holds: the v0 score and its aggregates
            conn.execute(text("UPDATE submissions SET score_mean = 0.5, score_iqm = 0.5, score_ci_low = 0.25, "
                              "score_ci_high = 0.75"))
            conn.execute(text("INSERT INTO task_aggregates (submission_id, task, metric, mean, iqm, ci_low, ci_high) "
                              "VALUES (:id, 'swarmloc/Ideal-v0', 'normalized_score', 0.5, 0.5, 0.25, 0.75)"),
                         {"id": ids[0]})
            conn.execute(text("UPDATE swarmloc_schema_version SET version = 1"))
    finally:
        engine.dispose()
    with LeaderboardStore(empty_url) as store:
        assert store.schema_version() == store_module.SCHEMA_VERSION
        rescored, bare = store.get(ids[0]), store.get(ids[1])
    expected = EntryScore.of(json.loads(path.read_text())["episodes"])
    assert expected is not None and expected.S == pytest.approx(gain, abs=1e-12)
    assert rescored.score == expected and bare.score is None
    assert all("normalized_score" not in per for per in rescored.task_aggregates.values())
    assert rescored.task_aggregates["swarmloc/Ideal-v0"]


def test_a_version_2_store_gains_the_method_columns(empty_url: str, tmp_path: Path) -> None:
    """2 → 3: ``run``, ``privileged_training`` and ``flops_per_channel`` are added and filled from each stored
    results file's method block (a file that does not say, or a stub, leaves them null)."""
    from sqlalchemy import text

    def made(raw: dict[str, Any]) -> None:
        raw["method"] |= {"run": 2, "privileged_training": True, "flops_per_channel": 7.0}

    path = H.make_results_file(tmp_path / "run2.json", "lb_fake_runner:good", edit=made)
    with LeaderboardStore(empty_url) as store:
        ids = [store.add(_entry(method_hash="1" * 64, results_json=path.read_text())),
               store.add(_entry(method_hash="2" * 64))]
    engine = create_engine(empty_url)
    try:
        with engine.begin() as conn:  # what a version-2 store holds: no such columns
            for column in ("run", "privileged_training", "flops_per_channel"):
                conn.execute(text(f"ALTER TABLE submissions DROP COLUMN {column}"))
            conn.execute(text("UPDATE swarmloc_schema_version SET version = 2"))
    finally:
        engine.dispose()
    with LeaderboardStore(empty_url) as store:
        assert store.schema_version() == 3
        made_entry, stub = store.get(ids[0]), store.get(ids[1])
    assert (made_entry.run, made_entry.privileged_training, made_entry.flops_per_channel) == (2, True, 7.0)
    assert (stub.run, stub.privileged_training, stub.flops_per_channel) == (None, None, None)


def test_a_failed_migration_leaves_the_old_schema(empty_url: str, monkeypatch: pytest.MonkeyPatch) -> None:
    LeaderboardStore(empty_url).close()
    before = dump(empty_url)

    def broken(conn: Any) -> None:
        conn.exec_driver_sql("CREATE TABLE half_done (id INTEGER PRIMARY KEY)")
        raise RuntimeError("migration bug")

    monkeypatch.setattr(store_module, "SCHEMA_VERSION", 4)
    monkeypatch.setitem(store_module.MIGRATIONS, 3, broken)
    with pytest.raises(RuntimeError, match="migration bug"):
        LeaderboardStore(empty_url)
    assert dump(empty_url) == before  # DDL rolled back too (both backends have transactional DDL)
