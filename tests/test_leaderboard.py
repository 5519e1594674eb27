"""Leaderboard: validation, sandboxed verification, the store, and the views.

A tiny suite (2 tasks × 3 seeds) is injected instead of ``swarmloc.bench.evaluation.suites``, and
verification calls ``tests/lb_fake_runner.py`` instead of the real runner.
"""

from __future__ import annotations

import io
import json
import math
import sys
import types
from pathlib import Path
from typing import Any

import lb_helpers as H
import pytest
from rich.console import Console

from swarmloc.cli import leaderboard_export, leaderboard_html, leaderboard_show
from swarmloc.cli import submit as submit_command
from swarmloc.leaderboard.store import database as store_module
from swarmloc.leaderboard.site import views
from swarmloc.leaderboard.submit.entry_points import parse_entry_point
from swarmloc.leaderboard.errors import (
    DuplicateSubmission,
    InvalidSubmission,
    StoreError,
    SubmissionError,
    VerificationFailed,
)
from swarmloc.leaderboard.store.database import LeaderboardStore
from swarmloc.leaderboard.submit.pipeline import submit
from swarmloc.leaderboard.verify.verification import (
    Tolerance,
    VerifyLimits,
    sample_episodes,
    worker_environment,
)

META = {"name": "good method", "authors": "A. Author", "track": "A"}


def _submit(path: Path, entry_point: str, db_url: str, meta: dict[str, Any] | None = None,
            **overrides: Any):
    return submit(path, entry_point, meta or META, **(H.submit_options(db_url) | overrides))


def _snapshot(db_url: str) -> tuple[Any, ...]:
    with LeaderboardStore(db_url) as store:
        return tuple(
            (e.id, e.name, e.method_hash, json.dumps(
                {t: {m: a.model_dump() for m, a in per.items()} for t, per in e.task_aggregates.items()}
            ))
            for e in store.entries()
        )


@pytest.fixture
def db_url(tmp_path: Path) -> str:
    """A store that already holds one accepted submission."""
    url = f"sqlite:///{tmp_path / 'lb.db'}"
    _submit(H.make_results_file(tmp_path / "seed.json", "lb_fake_runner:good_seed"),
            "lb_fake_runner:good_seed", url, {"name": "seed method", "track": "A"})
    return url


# -- acceptance and ranking ------------------------------------------------------------


def test_valid_submission_is_accepted_and_ranked(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'lb.db'}"
    plain = H.make_results_file(tmp_path / "plain.json", "lb_fake_runner:good_plain")
    receipt = _submit(plain, "lb_fake_runner:good_plain", url, {"name": "plain", "track": "A"})
    assert receipt.report is not None and receipt.report.ok
    assert receipt.report.sample_seed == 7 and len(receipt.report.episodes) == 3
    assert receipt.entry.verified and not receipt.entry.trusted
    assert "stored submission #1 'plain'" in receipt.describe()

    worse = H.make_results_file(tmp_path / "worse.json", "lb_fake_runner:good_worse")
    oracle = H.make_results_file(tmp_path / "oracle.json", "lb_fake_runner:good_oracle",
                                 privileged=True)
    _submit(worse, "lb_fake_runner:good_worse", url, {"name": "worse", "track": "A"})
    _submit(oracle, "lb_fake_runner:good_oracle", url,
            {"name": "oracle", "track": "A", "privileged": True})
    with LeaderboardStore(url) as store:
        entries = store.entries()
        assert [e.name for e in entries] == ["plain", "worse", "oracle"]
        ranked, privileged = views.split_ranked(entries)
        assert [e.name for e in ranked] == ["plain", "worse"]  # equal scores: older first
        assert [e.name for e in privileged] == ["oracle"]
        entry = entries[0]
        assert entry.score is None  # no uniform_rmse in these files: no score (the views may fill it in)
        assert sorted(entry.task_aggregates) == list(H.TASKS)
        assert "fault_rmse" not in entry.task_aggregates[H.TASKS[0]]  # undefined metric
        assert entry.results_json == plain.read_text()
        assert entry.verification_seed == 7


def test_the_entry_score_is_the_score_the_board_ranks_by(tmp_path: Path) -> None:
    """``entry.score`` is the score (S, log2 gain over uniform), the one ``Standing.score`` ranks by."""
    from swarmloc.leaderboard.site.ranking import suite_board

    url = f"sqlite:///{tmp_path / 'lb.db'}"
    gains = {"low": -0.3, "high": 0.4, "mid": 0.0}
    with LeaderboardStore(url) as store:
        for name, gain in gains.items():
            path = H.make_results_file(
                tmp_path / f"{name}.json", f"lb_fake_runner:good_{name}",
                metrics_edit=lambda t, s, m, g=gain: m.update(uniform_rmse=m["rmse"] * 2.0**g),
            )
            # The runner re-runs a gain of 0 (uniform_rmse = rmse), so compare with a loose tolerance.
            options = H.submit_options(url) | {"runner": "lb_fake_runner:run_episodes_with_reference",
                                               "tolerance": Tolerance(abs=1.0)}
            receipt = submit(path, f"lb_fake_runner:good_{name}", {"name": name, "track": "A"}, **options,
                             store=store)
            assert "normalized" not in receipt.describe() and "lower error than uniform" in receipt.describe()
        ranked, _ = views.split_ranked(store.entries())
        assert [e.name for e in ranked] == ["high", "mid", "low"]
        board = suite_board("tiny-test", "1", store.entries())
        for standing in board.ranked:
            entry = standing.entry
            assert entry.score is not None and entry.score.S == pytest.approx(gains[entry.name], abs=1e-12)
            assert (entry.score.S, entry.score.ci_low, entry.score.ci_high, entry.score.iqm) == \
                (standing.score.S, standing.score.ci_low, standing.score.ci_high, standing.score.iqm)


# -- rejections: clear message, store unchanged -------------------------------------------


def _nan_rmse(raw: dict) -> None:
    raw["episodes"][0]["metrics"]["rmse"] = math.nan


def _inf_delay(raw: dict) -> None:
    raw["episodes"][4]["metrics"]["delay_ms"] = math.inf


def _negative_rmse(raw: dict) -> None:
    raw["episodes"][1]["metrics"]["rmse"] = -0.25


def _edited_aggregate(raw: dict) -> None:
    raw["aggregates"][H.TASKS[1]]["rmse"]["mean"] = 0.01


def _oversize(path: Path) -> None:
    text = path.read_text()
    path.write_text(text + " " * (16 * 1024 * 1024))


REJECTIONS: dict[str, tuple[dict[str, Any], dict[str, Any], type[SubmissionError], str]] = {
    # case: (results-file options, submit options, error type, message regex)
    "missing episodes": (
        {"episodes": [(t, s) for t in H.TASKS for s in H.SEEDS][:4]}, {}, InvalidSubmission,
        r"2 episode\(s\) of suite 'tiny-test' are missing: \('swarmloc/NLOS-v0', 1001\), "
        r"\('swarmloc/NLOS-v0', 1002\)",
    ),
    "nan metric": (
        {"edit": _nan_rmse}, {}, InvalidSubmission,
        r"episode \('swarmloc/Ideal-v0', seed 1000\) metric 'rmse' is nan; metrics must be finite",
    ),
    "inf metric": (
        {"edit": _inf_delay}, {}, InvalidSubmission,
        r"metric 'delay_ms' is inf; metrics must be finite",
    ),
    "negative rmse": (
        {"edit": _negative_rmse}, {}, InvalidSubmission,
        r"seed 1001\) metric 'rmse' is -0.25; allowed range is \[0.0, inf\]",
    ),
    "hand-edited aggregate": (
        {"edit": _edited_aggregate}, {}, InvalidSubmission,
        r"aggregates\['swarmloc/NLOS-v0'\]\['rmse'\].mean is 0.01, but the episodes give",
    ),
    "tampered metric": (
        {"metrics_edit": lambda t, s, m: m.update(rmse=m["rmse"] * 0.9)
         if (t, s) == (H.TASKS[1], 1002) else None},
        {"sample_frac": 1.0}, VerificationFailed,
        r"1 metric\(s\) in 1 episode\(s\) differ:\n  - \('swarmloc/NLOS-v0', seed 1002\) rmse: "
        r"submitted [0-9.]+, re-run gave [0-9.]+",
    ),
    "wrong suite version": (
        {"suite_version": "0"}, {}, InvalidSubmission,
        r"suite 'tiny-test' version '0' is not the current version '1'",
    ),
    "method crashes": (
        {"entry_point": "lb_fake_runner:crash"}, {}, VerificationFailed,
        r"method 'lb_fake_runner:crash' crashed during verification: MethodFailed: the method "
        r"raised RuntimeError in load\(\): simulated crash inside the method",
    ),
    "method exceeds time limit": (
        {"entry_point": "lb_fake_runner:sleep"},
        {"limits": VerifyLimits(wall_time_s=1.5, memory_bytes=512 * 1024**2)},
        VerificationFailed,
        r"method 'lb_fake_runner:sleep' exceeded the wall-time limit of 1.5 s while re-running "
        r"3 episode\(s\); it was killed",
    ),
    "method exceeds memory limit": (
        {"entry_point": "lb_fake_runner:oom"}, {}, VerificationFailed,
        r"method 'lb_fake_runner:oom' exceeded the memory limit of 512 MiB",
    ),
}


@pytest.mark.parametrize("case", list(REJECTIONS))
def test_bad_submission_is_rejected_and_store_unchanged(
    case: str, db_url: str, tmp_path: Path
) -> None:
    file_options, submit_overrides, error, message = REJECTIONS[case]
    entry_point = file_options.get("entry_point", "lb_fake_runner:good_candidate")
    path = H.make_results_file(tmp_path / "candidate.json", **(file_options | {"entry_point": entry_point}))
    before = _snapshot(db_url)
    with pytest.raises(error, match=message):
        _submit(path, entry_point, db_url, **submit_overrides)
    assert _snapshot(db_url) == before


def test_oversized_results_file_is_rejected(db_url: str, tmp_path: Path) -> None:
    path = H.make_results_file(tmp_path / "big.json", "lb_fake_runner:good_big")
    _oversize(path)  # still valid JSON: only the size check can refuse it
    before = _snapshot(db_url)
    with pytest.raises(InvalidSubmission, match=r"big\.json is \d+ bytes; the limit is 16777216 bytes"):
        _submit(path, "lb_fake_runner:good_big", db_url)
    assert _snapshot(db_url) == before


def test_a_results_file_read_already_is_held_to_the_same_limit(tmp_path: Path) -> None:
    from swarmloc.bench.evaluation.results import read_results_file
    from swarmloc.leaderboard.store.schema import SizeLimits, make_submission, validate_submission

    path = H.make_results_file(tmp_path / "read.json", "lb_fake_runner:good_read")
    read = read_results_file(path)  # no limit here: validation applies the leaderboard's
    submission = make_submission(path, "lb_fake_runner:good_read", META)
    assert validate_submission(submission, H.suite_lookup, results_file=read).results_text == read.text
    with pytest.raises(InvalidSubmission, match=rf"read\.json is {read.size} bytes; the limit is 100 bytes"):
        validate_submission(submission, H.suite_lookup, SizeLimits(results_bytes=100), results_file=read)
    other = make_submission(H.make_results_file(tmp_path / "other.json", "lb_fake_runner:good_read"),
                            "lb_fake_runner:good_read", META)
    with pytest.raises(ValueError, match=r"results_file is .*read\.json, but the submission names .*other\.json"):
        validate_submission(other, H.suite_lookup, results_file=read)


def test_truncated_results_file_is_rejected(db_url: str, tmp_path: Path) -> None:
    path = H.make_results_file(tmp_path / "cut.json", "lb_fake_runner:good_cut")
    path.write_text(path.read_text()[:-200])
    before = _snapshot(db_url)
    with pytest.raises(InvalidSubmission, match=r"cut\.json is truncated"):
        _submit(path, "lb_fake_runner:good_cut", db_url)
    assert _snapshot(db_url) == before


@pytest.mark.parametrize(
    ("meta", "message"),
    [
        ({"name": "x" * 65, "track": "A"}, r"metadata.name: String should have at most 64 characters"),
        ({"name": "bad\x1bname", "track": "A"}, r"control character '\\x1b' \(U\+001B\)"),
        ({"name": "ok", "track": "C"}, r"metadata.track: Input should be 'A' or 'B'"),
        ({"name": "ok", "track": "A", "url": "javascript:alert(1)"}, r"must start with http"),
        ({"name": "ok", "track": "A", "description": "d" * 2001}, r"at most 2000 characters"),
    ],
)
def test_bad_metadata_is_rejected(meta: dict, message: str, db_url: str, tmp_path: Path) -> None:
    path = H.make_results_file(tmp_path / "m.json", "lb_fake_runner:good_meta")
    with pytest.raises(InvalidSubmission, match=message):
        _submit(path, "lb_fake_runner:good_meta", db_url, meta)


def test_default_lookup_uses_the_bench_suite_registry(tmp_path: Path) -> None:
    suites = pytest.importorskip("swarmloc.bench.evaluation.suites")
    from swarmloc.bench.evaluation.results import load_results, write_results
    from swarmloc.leaderboard.store.schema import make_submission, validate_submission

    quick = suites.get_suite("quick")
    path = H.make_results_file(tmp_path / "q.json", "lb_fake_runner:good_quick",
                               episodes=list(quick.episodes))
    raw = load_results(path)
    suite_info = raw.suite.model_copy(update={"name": quick.name, "version": quick.version,
                                              "sha256": quick.sha256})
    write_results(path, raw.model_copy(update={"suite": suite_info}))
    submission = make_submission(path, "lb_fake_runner:good_quick", {"name": "q", "track": "A"})
    validated = validate_submission(submission)  # default lookup: swarmloc.bench.evaluation.suites
    assert validated.suite.name == "quick" and len(validated.results.episodes) == len(quick.episodes)


def test_mismatched_claims_are_rejected(db_url: str, tmp_path: Path) -> None:
    path = H.make_results_file(tmp_path / "m.json", "lb_fake_runner:good_claims")
    with pytest.raises(InvalidSubmission) as info:
        _submit(path, "lb_fake_runner:good_other", db_url,
                {"name": "x", "track": "B", "privileged": True}, weights=path)
    text = str(info.value)
    assert "entry point 'lb_fake_runner:good_other' differs from the results file's" in text
    assert "track 'B' differs from the results' 'A'" in text
    assert "privileged=True differs from the results' privileged=False" in text
    assert "weights file SHA-256" in text


def test_duplicate_submission_is_rejected(db_url: str, tmp_path: Path) -> None:
    path = H.make_results_file(tmp_path / "again.json", "lb_fake_runner:good_seed")
    before = _snapshot(db_url)
    with pytest.raises(DuplicateSubmission, match=r"already on the leaderboard for suite "
                                                  r"'tiny-test' version '1' as submission #1"):
        _submit(path, "lb_fake_runner:good_seed", db_url, {"name": "renamed", "track": "A"})
    assert _snapshot(db_url) == before


def test_trust_is_only_for_shipped_methods(db_url: str, tmp_path: Path) -> None:
    path = H.make_results_file(tmp_path / "t.json", "lb_fake_runner:good_trust")
    with pytest.raises(InvalidSubmission, match=r"'lb_fake_runner:good_trust' is not one of them"):
        _submit(path, "lb_fake_runner:good_trust", db_url, trust=True)
    shipped = sorted(store_module.SHIPPED_REFERENCE_METHODS)[0]
    path = H.make_results_file(tmp_path / "s.json", shipped)
    receipt = _submit(path, shipped, db_url, {"name": "shipped", "track": "A"}, trust=True)
    assert receipt.report is None and receipt.entry.trusted and not receipt.entry.verified


def test_submit_reads_the_results_file_once(db_url: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """`swarmloc submit` and ``submit()`` read the file once; the store keeps the text that was validated."""
    import builtins
    import os

    cli_file = H.make_results_file(tmp_path / "cli.json", min(store_module.SHIPPED_REFERENCE_METHODS),
                                   name="read once by the command")
    api_file = H.make_results_file(tmp_path / "api.json", "lb_fake_runner:good_once", name="read once by submit")
    reads: list[Path] = []
    real_open = builtins.open

    def counting_open(file: Any, *args: Any, **kwargs: Any) -> Any:
        if isinstance(file, (str, os.PathLike)) and Path(file) in (cli_file, api_file):
            reads.append(Path(file))
        return real_open(file, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", counting_open)
    monkeypatch.setattr(io, "open", counting_open)  # what pathlib opens with
    monkeypatch.setattr("swarmloc.leaderboard.store.schema.default_suite_lookup", H.suite_lookup)
    console = Console(record=True, width=250, file=io.StringIO())
    # no entry point, no search path: the command takes both from the file
    done = submit_command.run(submit_command.Options(results=cli_file, trust=True, db_url=db_url), console)
    assert done == 0, console.export_text()
    _submit(api_file, "lb_fake_runner:good_once", db_url, {"name": "read once by submit", "track": "A"})
    assert reads == [cli_file, api_file]
    monkeypatch.undo()
    with LeaderboardStore(db_url) as store:
        stored = {e.name: e.results_json for e in store.entries(H.SUITE.name)}
    assert stored["read once by the command"] == cli_file.read_text()
    assert stored["read once by submit"] == api_file.read_text()


def test_shipped_allow_list_matches_the_agents_registry() -> None:
    registry = pytest.importorskip("swarmloc.agents.registry")
    shipped = store_module.SHIPPED_REFERENCE_METHODS
    assert set(registry.REGISTRY) <= shipped
    for name in shipped:
        base = name.removesuffix("+smooth")
        assert base in registry.REGISTRY, f"{name!r} is not a registered method"
        if name.endswith("+smooth"):
            assert registry.REGISTRY[base].track == "A"
        assert parse_entry_point(name).kind == "registered"


def test_nondeterministic_methods_get_a_tolerance(db_url: str, tmp_path: Path) -> None:
    def nudge(t: str, s: int, m: dict) -> None:
        m["rmse"] *= 1 + 1e-5

    strict = H.make_results_file(tmp_path / "d.json", "lb_fake_runner:good_det", metrics_edit=nudge)
    with pytest.raises(VerificationFailed, match="compared with exact equality"):
        _submit(strict, "lb_fake_runner:good_det", db_url, sample_frac=1.0)
    loose = H.make_results_file(tmp_path / "n.json", "lb_fake_runner:good_nondet",
                                metrics_edit=nudge, deterministic=False)
    receipt = _submit(loose, "lb_fake_runner:good_nondet", db_url, sample_frac=1.0)
    assert receipt.report is not None and "relative 0.001" in receipt.report.describe()


# -- verification sandbox ------------------------------------------------------------


def test_every_metric_has_physical_bounds() -> None:
    from swarmloc.bench.evaluation.results import METRIC_NAMES
    from swarmloc.leaderboard.store.schema import METRIC_BOUNDS

    assert set(METRIC_BOUNDS) == set(METRIC_NAMES)
    assert all(low < high for low, high in METRIC_BOUNDS.values())


def test_verification_compares_only_the_metrics_of_the_files_schema() -> None:
    from swarmloc.bench.evaluation import results as R
    from swarmloc.leaderboard.verify.verification import EXACT, compare_episodes

    metrics = R.EpisodeMetrics.of(rmse=1.0, team_return=2.0)
    results = R.make_results(
        R.MethodInfo(name="m", entry_point="pkg:make", privileged=False, track="A", deterministic=True),
        R.SuiteInfo(name="s", version="0", sha256="0" * 64), [{"task": "t", "seed": 1, "metrics": metrics}])
    rerun = [{"task": "t", "seed": 1, "metrics": {**metrics.model_dump(), "recovery_s": 3.5, "recovered": 1.0}}]
    assert [m.metric for m in compare_episodes(results, rerun, [("t", 1)], EXACT)] == ["recovery_s", "recovered"]
    # a schema-2 file holds no recovery metrics (they read as null): the re-run's are not compared
    older = R.Results.model_validate({**results.model_dump(), "schema_version": 2})
    assert compare_episodes(older, rerun, [("t", 1)], EXACT) == []


def test_sampler_is_seeded_and_sized() -> None:
    pool = [(f"t{i % 4}", i) for i in range(95)]
    a = sample_episodes(pool, 0.1, 3, seed=11)
    assert len(a) == 10 and a == sample_episodes(list(reversed(pool)), 0.1, 3, seed=11)
    assert a != sample_episodes(pool, 0.1, 3, seed=12)
    assert len(sample_episodes(pool[:6], 0.1, 3, seed=0)) == 3
    assert len(sample_episodes(pool[:2], 0.1, 3, seed=0)) == 2
    with pytest.raises(ValueError, match=r"sample fraction must be in \(0, 1\], got 0"):
        sample_episodes(pool, 0.0)


def test_out_of_memory_is_recognized_in_its_disguises() -> None:
    import errno

    from swarmloc.bench.evaluation.process_limits import is_out_of_memory

    assert is_out_of_memory(MemoryError())
    assert is_out_of_memory(OSError(errno.ENOMEM, "Cannot allocate memory"))
    assert is_out_of_memory(ImportError("libtorch_cpu.so: failed to map segment from shared object"))
    assert is_out_of_memory(RuntimeError("std::bad_alloc"))
    try:
        try:
            raise MemoryError
        except MemoryError as inner:
            raise RuntimeError("wrapped") from inner
    except RuntimeError as outer:
        assert is_out_of_memory(outer)
    assert not is_out_of_memory(RuntimeError("simulated crash inside the method"))


def test_worker_gets_a_clean_environment(
    db_url: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("SWARMLOC_DB", db_url)
    monkeypatch.setenv("LEAK_CANARY", "1")
    env = worker_environment(tmp_path, ["/x"])
    assert "SWARMLOC_DB" not in env and "LEAK_CANARY" not in env
    assert env["HOME"] == str(tmp_path) and env["PYTHONPATH"] == "/x"
    path = H.make_results_file(tmp_path / "e.json", "lb_fake_runner:envcheck")
    receipt = _submit(path, "lb_fake_runner:envcheck", db_url, {"name": "env", "track": "A"})
    assert receipt.report is not None and receipt.report.ok


def test_file_entry_points_run_from_their_directory(db_url: str, tmp_path: Path) -> None:
    method_file = tmp_path / "methods" / "my_method.py"
    method_file.parent.mkdir()
    method_file.write_text("from lb_fake_runner import Idle\n\ndef good_file():\n    return Idle()\n")
    entry_point = f"{method_file}:good_file"
    path = H.make_results_file(tmp_path / "f.json", entry_point)
    receipt = _submit(path, entry_point, db_url, {"name": "file", "track": "A"})
    assert receipt.entry.entry_point == entry_point
    # The method hash covers the source: editing the file makes a new method.
    method_file.write_text("from lb_fake_runner import Idle\n\ndef good_file():\n    return Idle()  # v2\n")
    receipt2 = _submit(path, entry_point, db_url, {"name": "file v2", "track": "A"})
    assert receipt2.entry.method_hash != receipt.entry.method_hash


# -- the store (the rest runs on SQLite and PostgreSQL in test_leaderboard_store.py) ----


def test_store_location_env_var_and_default(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SWARMLOC_DB", f"sqlite:///{tmp_path / 'env.db'}")
    with LeaderboardStore() as store:
        assert store.url.endswith("env.db")
    assert (tmp_path / "env.db").is_file()
    monkeypatch.delenv("SWARMLOC_DB")
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg"))
    assert store_module.default_db_url() == f"sqlite:///{tmp_path / 'xdg' / 'swarmloc' / 'leaderboard.db'}"
    with pytest.raises(StoreError, match=r"invalid database URL 'not a url'"):
        LeaderboardStore("not a url")


# -- views ---------------------------------------------------------------------------


def test_script_in_name_is_escaped_in_html(db_url: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "swarmloc.bench.reports.plots", None)  # no plot function yet
    evil = '<script>alert("x")</script>'
    path = H.make_results_file(tmp_path / "x.json", "lb_fake_runner:good_xss")
    receipt = _submit(path, "lb_fake_runner:good_xss", db_url, {
        "name": evil, "track": "A", "authors": "<img src=x onerror=alert(1)>",
        "description": "<b>bold</b>\nline 2", "url": "https://example.org/?a=1&b=2",
    })
    site = tmp_path / "site"
    index = views.render_html(LeaderboardStore(db_url), site)
    page = (site / "methods" / f"{receipt.id}.html").read_text()
    for text in (index.read_text(), page):
        assert evil not in text and "<img src=x" not in text
        assert "&lt;script&gt;alert(&quot;x&quot;)&lt;/script&gt;" in text
        assert text.count("<script") == 1  # only our own sorter
        assert "://" not in text.replace("https://example.org/?a=1&amp;b=2", "")  # nothing external
    assert "<b>bold</b>" not in page and "&lt;b&gt;bold&lt;/b&gt;" in page
    assert "<img" not in page  # no plot function: the plot slot is omitted
    assert (site / "results" / f"{receipt.id}.json").read_text() == path.read_text()
    assert f'href="../results/{receipt.id}.json" download' in page


def test_method_page_embeds_plots_when_bench_provides_them(
    db_url: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    calls = []

    def plot_results(results_path: Path, out_dir: Path) -> list[Path]:
        calls.append(Path(results_path))
        target = Path(out_dir) / "rmse by task.png"
        target.write_bytes(b"\x89PNG\r\n\x1a\n")
        return [target]

    monkeypatch.setitem(sys.modules, "swarmloc.bench.reports.plots",
                        types.SimpleNamespace(plot_results=plot_results))
    site = tmp_path / "site"
    views.render_html(LeaderboardStore(db_url), site)
    page = (site / "methods" / "1.html").read_text()
    assert calls == [site / "results" / "1.json"]
    assert '<img src="../plots/1/rmse%20by%20task.png" alt="rmse by task"' in page
    assert (site / "plots" / "1" / "rmse by task.png").is_file()


def test_terminal_view_and_exports(db_url: str, tmp_path: Path) -> None:
    oracle = H.make_results_file(tmp_path / "o.json", "lb_fake_runner:good_o", privileged=True)
    _submit(oracle, "lb_fake_runner:good_o", db_url,
            {"name": "=HYPERLINK(\"x\") [bold]oracle[/bold]", "track": "A", "privileged": True})
    console = Console(record=True, width=100, file=io.StringIO())
    with LeaderboardStore(db_url) as store:
        views.print_leaderboard(store, console=console)
        text = console.export_text()
        assert "seed method" in text and "[bold]oracle[/bold]" in text
        assert text.index("Privileged methods") < text.index("[bold]oracle")
        # no uniform entry in this store, so no score: nothing is ranked (test_leaderboard_views.py ranks)
        assert "No ranked methods" in text and text.index("Partial coverage") < text.index("seed method")
        for header in ("2^S", "95% CI", "Gap", "Tasks", "Ideal", "NLOS"):
            assert header in text
        csv_text = views.export(store, "csv")
        rows = csv_text.splitlines()
        assert rows[0].startswith("id,suite,suite_version,rank,name,")
        assert "rmse[swarmloc/Ideal-v0]" in rows[0] and "times[swarmloc/Ideal-v0]" in rows[0]
        assert len(rows) == 3 and rows[1].startswith("1,tiny-test,1,,seed method")
        assert "'=HYPERLINK" in rows[2]  # formula neutralized
        data = json.loads(views.export(store, "json"))
        assert [(row["rank"], row["table"]) for row in data] == [(None, "partial"), (None, "privileged")]
        assert data[1]["name"].startswith("=HYPERLINK")  # JSON keeps the exact text
        assert set(data[0]["task_aggregates"][H.TASKS[0]]["rmse"]) == {"mean", "iqm", "ci_low", "ci_high"}
        with pytest.raises(ValueError, match="unknown export format 'xml'"):
            views.export(store, "xml")  # type: ignore[arg-type]


def test_cli_commands(db_url: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    console = Console(record=True, width=250, file=io.StringIO())
    assert leaderboard_show.run(leaderboard_show.Options(db_url=db_url), console) == 0
    assert "seed method" in console.export_text()
    assert leaderboard_html.run(leaderboard_html.Options(out=tmp_path / "site", db_url=db_url), console) == 0
    assert (tmp_path / "site" / "index.html").is_file()
    assert leaderboard_export.run(leaderboard_export.Options(format="json", db_url=db_url, shipped=False), console) == 0
    assert json.loads(capsys.readouterr().out)[0]["name"] == "seed method"
    refused = submit_command.run(submit_command.Options(results=tmp_path / "missing.json", entry_point="pkg.mod:make",
                                                        name="x", track="A", db_url=db_url), console)
    assert refused == 1 and "missing.json does not exist" in console.export_text()


def _null_on(task: str, seeds: tuple[int, ...]):
    def edit(t: str, s: int, values: dict[str, Any]) -> None:
        if t == task and s in seeds:
            for name in values:
                values[name] = None
    return edit


def test_partial_coverage_is_accepted_but_half_run_tasks_are_not(tmp_path: Path) -> None:
    """A method that cannot run a task (null on all its seeds) is valid; one that ran some seeds only is not."""
    from swarmloc.leaderboard.store.schema import make_submission, validate_submission

    whole = H.make_results_file(tmp_path / "p.json", metrics_edit=_null_on("swarmloc/NLOS-v0", H.SEEDS))
    validated = validate_submission(make_submission(whole, "lb_fake_runner:good", META), H.suite_lookup)
    assert sum(e.metrics.rmse is None for e in validated.results.episodes) == len(H.SEEDS)
    half = H.make_results_file(tmp_path / "h.json", metrics_edit=_null_on("swarmloc/NLOS-v0", H.SEEDS[:1]))
    with pytest.raises(InvalidSubmission, match="has an RMSE on 2 of its 3 seeds"):
        validate_submission(make_submission(half, "lb_fake_runner:good", META), H.suite_lookup)
    none = H.make_results_file(tmp_path / "n.json", metrics_edit=lambda t, s, v: v.update({k: None for k in v}))
    with pytest.raises(InvalidSubmission, match="ran nothing"):
        validate_submission(make_submission(none, "lb_fake_runner:good", META), H.suite_lookup)


def test_a_forged_score_block_is_refused(tmp_path: Path) -> None:
    from swarmloc.leaderboard.store.schema import make_submission, validate_submission

    def with_uniform(t: str, s: int, values: dict[str, Any]) -> None:
        values["uniform_rmse"] = 2.0 * values["rmse"]

    def forge(raw: dict[str, Any]) -> None:
        raw["score"]["S"] += 1.0

    path = H.make_results_file(tmp_path / "f.json", metrics_edit=with_uniform, edit=forge)
    with pytest.raises(InvalidSubmission, match=r"score\.S is .*, but the episodes give 1\.0"):
        validate_submission(make_submission(path, "lb_fake_runner:good", META), H.suite_lookup)


def test_export_of_a_fresh_store_is_the_shipped_board(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``leaderboard export`` stores the shipped results a store lacks first: a fresh store exports the reference
    board of the suite, runs and privileged training included; a suite without shipped results exports as stored."""
    url = f"sqlite:///{tmp_path / 'lb.db'}"
    assert leaderboard_export.run(leaderboard_export.Options(format="json", db_url=url, suite="standard-v2")) == 0
    rows = json.loads(capsys.readouterr().out)
    by_name = {row["name"]: row for row in rows}
    assert by_name["mappo-set-gru"]["runs"] == 3 and by_name["mappo-set-gru"]["privileged_training"] is True
    assert by_name["cusum"]["privileged_training"] is False and by_name["cusum"]["runs"] == 1
    assert leaderboard_export.run(leaderboard_export.Options(format="json", db_url=url, suite="quick-v2")) == 0
    assert json.loads(capsys.readouterr().out) == []
