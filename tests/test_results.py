"""The results file: schema, atomic write, clear errors on bad files."""

from __future__ import annotations

import json
import os
from datetime import datetime, timezone
from pathlib import Path

import pytest

from swarmloc.bench.evaluation import results as R


def _results(n_seeds: int = 3) -> R.Results:
    episodes = [
        {
            "task": task,
            "seed": seed,
            "metrics": R.EpisodeMetrics.of(
                rmse=0.1 * (seed + 1), mean_error=0.05, max_error=1.0, diverged=False,
                delay_ms=1.5, energy_j=0.2, jitter=0.01, team_return=123.0,
            ),
        }
        for task in ("swarmloc/Ideal-v0", "swarmloc/NLOS-v0")
        for seed in range(n_seeds)
    ]
    keys = [(e["task"], e["seed"]) for e in episodes]
    return R.make_results(
        method=R.MethodInfo(name="uniform", entry_point="pkg.mod:make", privileged=False,
                            track="A", deterministic=True),
        suite=R.SuiteInfo(name="tiny", version="1", sha256=R.suite_sha256(keys)),
        episodes=episodes,
    )


def test_results_file_round_trips(tmp_path: Path) -> None:
    res = _results()
    path = R.write_results(tmp_path / "r.json", res)
    back = R.load_results(path)
    assert back == res
    raw = json.loads(path.read_text())
    assert list(raw) == ["schema_version", "method", "suite", "provenance", "episodes", "aggregates", "score"]
    assert list(raw["episodes"][0]) == ["task", "seed", "metrics"]
    assert list(raw["episodes"][0]["metrics"]) == list(R.METRIC_NAMES)
    assert "normalized_score" not in raw["episodes"][0]["metrics"]
    assert "normalized_score" not in raw["aggregates"]["swarmloc/Ideal-v0"]
    assert raw["episodes"][0]["metrics"]["fault_rmse"] is None
    assert list(raw["aggregates"]["swarmloc/Ideal-v0"]["rmse"]) == list(R.AGGREGATE_FIELDS)
    assert raw["aggregates"]["swarmloc/Ideal-v0"]["cep90"] is None
    assert list(raw["provenance"]) == ["package_version", "git_commit", "created_utc",
                                       "python_version", "numpy_version", "torch_version", "machine"]
    assert raw["method"]["track"] == "A"
    # No temporary files are left behind.
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.json"]


def test_older_schema_reads_its_missing_metrics_as_null() -> None:
    raw = json.loads(R.dumps_results(_results()))
    assert raw["schema_version"] == R.SCHEMA_VERSION == 6
    raw["schema_version"] = 2
    for name in ("recovery_s", "recovered"):
        for episode in raw["episodes"]:
            del episode["metrics"][name]
        for per_metric in raw["aggregates"].values():
            del per_metric[name]
    back = R.parse_results(json.dumps(raw))
    assert back.schema_version == 2 and R.SCHEMA_METRICS[2] == R.METRIC_NAMES[:-2]
    assert back.episodes[0].metrics.recovery_s is None and back.aggregates["swarmloc/Ideal-v0"]["recovered"] is None


@pytest.mark.parametrize("version", [1, 2, 3])
def test_an_older_file_loads_with_its_retired_normalized_score_ignored(version: int) -> None:
    """Schema 1–3 files carry the retired v0 ``normalized_score`` (episodes and aggregates): accepted, left out."""
    res = _results()
    raw = json.loads(R.dumps_results(res))
    raw["schema_version"] = version
    for i, episode in enumerate(raw["episodes"]):
        episode["metrics"]["normalized_score"] = 0.25 * i if i % 2 else None
    for per_metric in raw["aggregates"].values():
        per_metric["normalized_score"] = {"mean": 0.5, "iqm": 0.5, "ci_low": 0.0, "ci_high": 1.0}
    back = R.parse_results(json.dumps(raw))
    assert back.schema_version == version
    assert "normalized_score" not in back.episodes[0].metrics.model_dump()
    assert set(back.aggregates["swarmloc/Ideal-v0"]) == set(R.METRIC_NAMES)
    assert back.episodes[1].metrics.rmse == res.episodes[1].metrics.rmse
    # the current schema has no such metric: a version-4 file that carries it is off-schema
    raw["schema_version"] = R.SCHEMA_VERSION
    with pytest.raises(R.ResultsFileError, match="normalized_score: Extra inputs are not permitted"):
        R.parse_results(json.dumps(raw))


def test_the_shipped_results_files_load_without_the_retired_metric() -> None:
    from swarmloc.bench.evaluation.shipped import shipped_results

    for path in shipped_results():
        raw = json.loads(path.read_text(encoding="utf-8"))
        results = R.load_results(path)
        assert raw["schema_version"] < R.SCHEMA_VERSION or "normalized_score" not in raw["episodes"][0]["metrics"]
        assert "normalized_score" not in results.episodes[0].metrics.model_dump()
        assert [e.metrics.rmse for e in results.episodes] == [e["metrics"]["rmse"] for e in raw["episodes"]]


def test_write_is_atomic_on_failure(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = R.write_results(tmp_path / "r.json", _results())
    before = path.read_bytes()

    def boom(src: str, dst: str) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(OSError, match="disk full"):
        R.write_results(path, _results(n_seeds=4))
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.json"]


@pytest.mark.parametrize("keep", [0.5, 0.9, 0.999])
def test_truncated_file_is_rejected_clearly(tmp_path: Path, keep: float) -> None:
    path = R.write_results(tmp_path / "r.json", _results())
    text = path.read_text().rstrip()
    start = int(len(text) * keep)
    for cut in range(start, min(start + 40, len(text))):
        path.write_text(text[:cut])
        with pytest.raises(R.ResultsFileError, match=r"r\.json is truncated \(the JSON ends early\)"):
            R.load_results(path)


@pytest.mark.parametrize(
    ("content", "expected"),
    [
        (b"", "is empty"),
        (b"\xff\xfe garbage", "not UTF-8"),
        (b'{"schema_version": 1,, }', r"corrupted \(invalid JSON\): .* \(line 1, column 22\)"),
        (b"[1, 2]", "must hold a JSON object, got list"),
        (b'{"schema_version": 7}', "schema_version 7; this swarmloc reads schema versions 1, 2, 3, 4, 5, 6 \\(the file was written by a newer swarmloc: upgrade"),
    ],
)
def test_corrupted_file_is_rejected_clearly(tmp_path: Path, content: bytes, expected: str) -> None:
    path = tmp_path / "bad.json"
    path.write_bytes(content)
    with pytest.raises(R.ResultsFileError, match=rf"bad\.json .*{expected}"):
        R.load_results(path)


def test_schema_violations_name_the_field(tmp_path: Path) -> None:
    raw = json.loads(R.dumps_results(_results()))
    raw["episodes"][1]["metrics"]["rmse"] = "0.3"
    raw["episodes"][2]["metrics"]["speed"] = 1.0
    del raw["episodes"][3]["metrics"]["jitter"]
    raw["method"]["track"] = "C"
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(raw))
    with pytest.raises(R.ResultsFileError) as info:
        R.load_results(path)
    message = str(info.value)
    assert "bad.json does not match the results schema (4 problem(s))" in message
    assert "episodes.1.metrics.rmse: Value error, expected a number or null, got the string '0.3'" in message
    assert "episodes.2.metrics.speed: Extra inputs are not permitted" in message
    assert "episodes.3.metrics.jitter: Field required" in message
    assert "method.track: Input should be 'A' or 'B'" in message


def test_duplicate_episodes_and_aggregate_mismatch_are_rejected() -> None:
    raw = json.loads(R.dumps_results(_results()))
    dup = dict(raw, episodes=raw["episodes"] + raw["episodes"][:1])
    with pytest.raises(R.ResultsFileError, match=r"listed more than once .*'swarmloc/Ideal-v0', 0"):
        R.parse_results(json.dumps(dup))
    no_agg = dict(raw, aggregates={"swarmloc/Ideal-v0": raw["aggregates"]["swarmloc/Ideal-v0"]})
    with pytest.raises(R.ResultsFileError, match=r"missing \['swarmloc/NLOS-v0'\]"):
        R.parse_results(json.dumps(no_agg))


def test_missing_file_and_size_limit(tmp_path: Path) -> None:
    with pytest.raises(R.ResultsFileError, match=r"nope\.json does not exist"):
        R.load_results(tmp_path / "nope.json")
    path = R.write_results(tmp_path / "r.json", _results())
    with pytest.raises(R.ResultsFileError, match=r"r\.json is \d+ bytes; the limit is 100 bytes"):
        R.load_results(path, max_bytes=100)



def test_read_results_file_keeps_the_exact_text(tmp_path: Path) -> None:
    path = tmp_path / "r.json"
    text = R.dumps_results(_results()).replace("\n", "\r\n")  # any layout: the text is kept as it is
    path.write_bytes(text.encode("utf-8"))
    read = R.read_results_file(path, max_bytes=len(text))
    assert (read.path, read.text, read.size) == (path, text, len(text))
    assert read.results == R.load_results(path) == _results().model_copy(update={"provenance": read.results.provenance})
    with pytest.raises(R.ResultsFileError, match=r"is not a regular file"):
        R.read_results_file(tmp_path)
    with pytest.raises(R.ResultsFileError, match=r"r\.json/x\.json cannot be read: Not a directory"):
        R.read_results_file(path / "x.json")
    with pytest.raises(R.ResultsFileError, match=r"is \d+ bytes; the limit is \d+ bytes"):
        R.read_results_file(path, max_bytes=len(text) - 1)

def test_metric_helpers() -> None:
    with pytest.raises(ValueError, match=r"unknown metric name\(s\) \['accuracy'\]"):
        R.EpisodeMetrics.of(accuracy=1.0)
    assert R.suite_sha256([("b", 1), ("a", 2)]) == R.suite_sha256([("a", 2), ("b", 1)])
    assert R.suite_sha256([("a", 1)]) != R.suite_sha256([("a", 2)])
    prov = R.collect_provenance()
    assert prov.created_utc.tzinfo is not None
    assert prov.created_utc <= datetime.now(timezone.utc)
    assert prov.machine.cpu_count >= 1


def test_results_module_stays_light() -> None:
    import subprocess
    import sys

    code = (
        "import sys, swarmloc.bench.evaluation.results as r; "
        "r.collect_provenance(); "
        "print(sorted(m for m in ('torch', 'numpy', 'numba', 'swarmloc.leaderboard') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_score_block_summarizes_the_episodes() -> None:
    """The results file's ``score`` block is the score of its own episodes (2^S, coverage, per-task gains)."""
    from swarmloc.bench.scoring import score as S
    def ep(task: str, seed: int, rmse: float | None, uniform: float) -> dict:
        return {"task": task, "seed": seed, "metrics": R.EpisodeMetrics.of(rmse=rmse, uniform_rmse=uniform).model_dump()}

    method = R.MethodInfo(name="m", entry_point="m", privileged=False, track="A", deterministic=True)
    suite = R.SuiteInfo(name="s", version="0", sha256="0" * 64)
    results = R.make_results(method, suite, [ep("A", 0, 1.0, 2.0), ep("A", 1, 1.0, 4.0), ep("B", 0, None, 1.0)])
    block = results.score
    assert block is not None and (block.covered, block.total) == (1, 2)
    assert block.tasks["A"].gain == 1.5 and block.S == 1.5 and block.times == 2.0 ** 1.5
    assert block.S == S.suite_score([e.model_dump() for e in results.episodes]).S
    again = R.parse_results(R.dumps_results(results))
    assert again.score == block


def test_how_the_method_was_made_is_in_the_method_block(tmp_path: Path) -> None:
    """Schema 6: privileged_training from the registry, the run from the weights' training record, the FLOPs the
    method declares; an older file reads them as null (not declared)."""
    from swarmloc.agents.registry import load_method
    from swarmloc.bench.evaluation.outcomes import method_info, training_run

    info = method_info(load_method("chi2-soft"))
    assert (info.privileged_training, info.run, info.flops_per_channel) == (False, None, 5.0)
    assert method_info(load_method("supervised-trust")).privileged_training is True
    weights = tmp_path / "w.seed3.pt"
    weights.write_bytes(b"weights")
    assert training_run(weights) is None  # no record beside it
    weights.with_suffix(".json").write_text(json.dumps({"config": {"seed": 3}}))
    assert training_run(weights) == 3
    weights.with_suffix(".json").write_text(json.dumps({"config": {"seed": "3"}}))
    with pytest.raises(ValueError, match="config.seed must be a non-negative integer .* got '3'"):
        training_run(weights)
    raw = json.loads(R.dumps_results(_results()))
    assert raw["method"]["privileged_training"] is False and raw["method"]["run"] is None
    raw["schema_version"] = 5
    for key in ("privileged_training", "run", "flops_per_channel"):
        del raw["method"][key]
    assert R.parse_results(json.dumps(raw)).method.privileged_training is None
    raw["schema_version"] = 6
    raw["method"] |= {"privileged_training": True, "run": True}
    with pytest.raises(R.ResultsFileError, match="method.run"):
        R.parse_results(json.dumps(raw))
