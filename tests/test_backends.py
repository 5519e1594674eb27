"""Execution backends: serial, process and Ray give the same numbers; faults; Ctrl-C.

One local 2-CPU Ray cluster serves the module (``ray_cluster``); episodes are shortened
with spec overrides so that the module runs in about a minute.
"""

from __future__ import annotations

import io
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import backend_faults
import pytest
import ray

from swarmloc.agents.registry import WEIGHTS_DIR
from swarmloc.bench.evaluation.backends import (
    Job,
    check_backend,
    local_weights,
    run_jobs,
    weights_bundle,
)
from swarmloc.bench.evaluation.runner import EvaluationFailed, evaluate, evaluate_methods, partial_path
from swarmloc.bench.evaluation.suites import Suite
from swarmloc.leaderboard.errors import VerificationFailed
from swarmloc.leaderboard.verify.ray_rerun import ray_rerun, split_sample
from swarmloc.leaderboard.store.database import LeaderboardStore
from swarmloc.leaderboard.submit.pipeline import submit

TESTS = Path(__file__).resolve().parent
FAULTS = TESTS / "backend_faults.py"
SEEDS = tuple(range(1_000_000, 1_000_008))
SLICE_TASKS = ("swarmloc/NLOS-v0", "swarmloc/CascadedFault-v0", "swarmloc/GradualFault-v0", "swarmloc/Scale4-v0")
#: a slice of standard-v0: four tasks × eight test seeds, 2 s episodes
SLICE = Suite("standard-v0-slice", "0", tuple((t, s) for t in SLICE_TASKS for s in SEEDS))
SHORT = {"duration": 2.0}
#: the fault tests: one three-UAV task and one four-UAV task, two seeds each
SMALL = Suite("small", "0", tuple((t, s) for t in ("swarmloc/GradualFault-v0", "swarmloc/NLOS-v0")
                                  for s in SEEDS[:2]))


@pytest.fixture(scope="module")
def fault_dir(tmp_path_factory: pytest.TempPathFactory):
    """``$SWARMLOC_FAULT_DIR`` for ``backend_faults`` (set before workers or the cluster start)."""
    folder = tmp_path_factory.mktemp("faults")
    os.environ[backend_faults.FAULT_DIR_ENV] = str(folder)
    yield folder
    os.environ.pop(backend_faults.FAULT_DIR_ENV, None)


@pytest.fixture(scope="module")
def ray_cluster(fault_dir: Path):
    """A real local Ray cluster of 2 CPUs for the module (Ray ≥ 2.54 has no local_mode)."""
    ray.init(address="local", num_cpus=2, include_dashboard=False, logging_level="warning",
             object_store_memory=128 * 1024**2)
    yield ray.get_runtime_context().gcs_address
    ray.shutdown()


def _files(runs, suite: Suite) -> dict[str, dict]:
    """Each method's results file as JSON, provenance left out."""
    return {m: json.loads(r.results(suite).model_dump_json(exclude={"provenance"})) for m, r in runs.items()}


def test_serial_process_and_ray_give_identical_results(ray_cluster, tmp_path: Path) -> None:
    weights = tmp_path / "mappo.pt"  # a copy: on Ray it travels through the object store, with its record
    shutil.copy(WEIGHTS_DIR / "mappo.pt", weights)
    shutil.copy(WEIGHTS_DIR / "mappo.json", weights.with_suffix(".json"))
    methods = ["chi2-gate", "pf", "mappo"]
    # two chunks per task: merged back in suite order, the trace taken from the first
    common = dict(weights={"mappo": str(weights)}, seeds_per_job=4, trace=True, progress=False, overrides=SHORT)
    serial = evaluate_methods(methods, SLICE, backend="serial", **common)
    process = evaluate_methods(methods, SLICE, backend="process", workers=2, **common)
    on_ray = evaluate_methods(methods, SLICE, backend="ray", workers=2, **common)
    expected = _files(serial, SLICE)
    assert _files(process, SLICE) == expected
    assert _files(on_ray, SLICE) == expected
    assert expected["mappo"]["method"]["weights_sha256"] is not None
    for runs in (serial, process, on_ray):  # the first seed's trace of every task, from whichever chunk
        assert {(t.task, t.seed) for t in runs["pf"].traces} == {(t, SEEDS[0]) for t in SLICE_TASKS}


def test_split_ci_backbone_gives_identical_results_on_every_backend(ray_cluster) -> None:
    """The v2 backbone (split covariance intersection): serial, two worker processes and Ray, bit for bit."""
    split = {**SHORT, "filter": {"peer_update": "split_ci"}}
    common = dict(seeds_per_job=4, trace=False, progress=False, overrides=split)
    methods = ["uniform", "chi2-gate"]
    serial = evaluate_methods(methods, SLICE, backend="serial", **common)
    expected = _files(serial, SLICE)
    assert _files(evaluate_methods(methods, SLICE, backend="process", workers=2, **common), SLICE) == expected
    assert _files(evaluate_methods(methods, SLICE, backend="ray", workers=2, **common), SLICE) == expected
    point = _files(evaluate_methods(["uniform"], SLICE, backend="serial", **{**common, "overrides": SHORT}), SLICE)
    assert point["uniform"]["episodes"] != expected["uniform"]["episodes"]  # the override took effect


def test_chunking_does_not_change_batch_invariant_methods() -> None:
    # mappo is not among them: torch's kernels move its metrics by ~1e-9 with the batch size
    methods = ["random", "chi2-gate", "pf"]
    one = evaluate_methods(methods, SMALL, seeds_per_job=1, trace=False, progress=False, overrides=SHORT)
    whole = evaluate_methods(methods, SMALL, trace=False, progress=False, overrides=SHORT)
    for m in methods:
        assert one[m].episodes == whole[m].episodes


@pytest.mark.parametrize("backend", ["process", "ray"])
def test_a_killed_worker_has_its_job_retried(backend: str, fault_dir: Path, request) -> None:
    if backend == "ray":
        request.getfixturevalue("ray_cluster")
    (fault_dir / backend_faults.MARKER).unlink(missing_ok=True)
    expected = evaluate_methods(["chi2-gate"], SMALL, trace=False, progress=False, overrides=SHORT)["chi2-gate"]
    method = f"{FAULTS}:dies_once"
    run = evaluate_methods([method], SMALL, backend=backend, workers=2, seeds_per_job=1, trace=False,
                           progress=False, overrides=SHORT)[method]
    assert (fault_dir / backend_faults.MARKER).exists(), "no worker was killed"
    assert int((fault_dir / backend_faults.MARKER).read_text()) != os.getpid()
    assert not run.failed
    assert run.episodes == expected.episodes


@pytest.mark.parametrize("backend", ["serial", "process", "ray"])
def test_a_raising_method_fails_its_task_only(backend: str, request) -> None:
    if backend == "ray":
        request.getfixturevalue("ray_cluster")
    expected = evaluate_methods(["chi2-gate"], SMALL, trace=False, progress=False, overrides=SHORT)["chi2-gate"]
    method = f"{FAULTS}:raises_on_three_uavs"
    runs = evaluate_methods([method, "chi2-gate"], SMALL, backend=backend, workers=2, trace=False, progress=False,
                            overrides=SHORT)
    run = runs[method]
    assert run.failed == {"swarmloc/GradualFault-v0": "RuntimeError: this method breaks on three UAVs"}
    assert run.episodes == [e for e in expected.episodes if e["task"] == "swarmloc/NLOS-v0"]
    assert runs["chi2-gate"].episodes == expected.episodes and not runs["chi2-gate"].failed
    with pytest.raises(EvaluationFailed, match="GradualFault-v0: RuntimeError"):
        run.results(SMALL)
    partial = run.partial_results(SMALL)
    assert partial is not None and partial.suite.name == "small-subset"
    assert list(partial.aggregates) == ["swarmloc/NLOS-v0"]


def test_evaluate_writes_only_the_partial_file_when_a_task_fails(tmp_path: Path) -> None:
    out = tmp_path / "r.json"
    suite = Suite("one-each", "0", (("swarmloc/GradualFault-v0", SEEDS[0]), ("swarmloc/Ideal-v0", SEEDS[0])))
    with pytest.raises(EvaluationFailed) as caught:
        evaluate(f"{FAULTS}:raises_on_three_uavs", suite, out, progress=False, trace=False)
    assert not out.exists()
    assert caught.value.written == partial_path(out) == tmp_path / "r.partial.json"
    assert json.loads(partial_path(out).read_text())["suite"]["name"] == "one-each-subset"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


@pytest.mark.parametrize("backend", ["process", "ray"])
def test_ctrl_c_cancels_and_leaves_no_results_file(backend: str, fault_dir: Path, tmp_path: Path, request) -> None:
    hanging = fault_dir / backend_faults.HANGING
    hanging.unlink(missing_ok=True)
    out = tmp_path / "r.json"
    cmd = [str(Path(sys.executable).parent / "swarmloc"), "evaluate", "--method", f"{FAULTS}:hangs", "--suite",
           "quick", "--tasks", "NLOS-v0,CascadedFault-v0", "--workers", "2", "--backend", backend, "--out", str(out),
           "--no-progress"]
    if backend == "ray":
        cmd += ["--address", request.getfixturevalue("ray_cluster")]
    # as from a terminal: SIGINT not ignored, even where the test runner was started in the background
    unignore = ("import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_DFL); "
                "os.execv(sys.argv[1], sys.argv[1:])")
    proc = subprocess.Popen([sys.executable, "-c", unignore, *cmd], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            cwd=tmp_path, text=True)
    try:
        deadline = time.time() + 180
        while not (hanging.exists() and len(hanging.read_text().split()) == 2):  # both jobs are running
            assert proc.poll() is None and time.time() < deadline, proc.stdout.read() if proc.poll() else "timeout"
            time.sleep(0.2)
        proc.send_signal(signal.SIGINT)
        assert proc.wait(60) == 130
    finally:
        proc.kill()
    assert "interrupted" in proc.stdout.read()
    assert sorted(p.name for p in tmp_path.iterdir()) == [], "a results, partial or temporary file was left"
    pids = [int(p) for p in hanging.read_text().split()]
    deadline = time.time() + 30
    while any(_alive(p) for p in pids) and time.time() < deadline:  # cancelled, not left to finish
        time.sleep(0.2)
    assert not any(_alive(p) for p in pids)
    if backend == "ray":  # and their CPUs are free again
        while ray.available_resources().get("CPU", 0) < 2 and time.time() < deadline:
            time.sleep(0.2)
        assert ray.available_resources().get("CPU", 0) == 2


def test_weights_bundle_round_trip(tmp_path: Path) -> None:
    (tmp_path / "w.pt").write_bytes(b"weights")
    (tmp_path / "w.json").write_text("{}")
    path = Path(local_weights(weights_bundle(tmp_path / "w.pt"), "w.pt"))
    assert path.read_bytes() == b"weights" and path.with_suffix(".json").read_text() == "{}"
    assert path.parent != tmp_path


def test_bad_backend_options_are_refused() -> None:
    assert check_backend(None, 1, None) == "serial" and check_backend(None, 2, None) == "process"
    with pytest.raises(ValueError, match="one of serial, process, ray"):
        check_backend("dask", 2, None)
    with pytest.raises(ValueError, match="needs backend='ray'"):
        check_backend("process", 2, "auto")
    with pytest.raises(ValueError, match=r"workers must be in \[1, 64\]"):
        check_backend("ray", 0, None)
    with pytest.raises(ValueError, match="needs backend='ray'"):
        run_jobs(print, [Job("swarmloc/Ideal-v0", "uniform", (1,))], backend="serial", address="auto",
                 on_result=print, on_failure=print)


# -- leaderboard verification on Ray ---------------------------------------------------


def test_split_sample_keeps_tasks_whole_and_balances() -> None:
    sample = [("a", 1), ("a", 2), ("a", 3), ("b", 1), ("c", 1), ("c", 2)]
    chunks = split_sample(sample, 2)
    assert sorted(map(sorted, chunks)) == [[("a", 1), ("a", 2), ("a", 3)], [("b", 1), ("c", 1), ("c", 2)]]
    assert split_sample(sample, 8) == [[("a", 1), ("a", 2), ("a", 3)], [("c", 1), ("c", 2)], [("b", 1)]]


def test_submit_runs_the_sandboxed_verification_as_ray_tasks(ray_cluster, tmp_path: Path, monkeypatch) -> None:
    import lb_helpers as H

    # a failed chunk must not cancel its siblings: a cancellation racing a finishing task aborts
    # the driver in Ray 2.60 (it killed a pytest worker); the verification waits for every chunk
    cancelled: list = []
    monkeypatch.setattr(ray, "cancel", lambda ref, **kw: cancelled.append(ref))

    url = f"sqlite:///{tmp_path / 'lb.db'}"
    options = H.submit_options(url) | {"sample_frac": 1.0, "rerun": ray_rerun()}
    good = H.make_results_file(tmp_path / "good.json", "lb_fake_runner:good_ray")
    receipt = submit(good, "lb_fake_runner:good_ray", {"name": "on ray", "track": "A"}, **options)
    assert receipt.report.ok and len(receipt.report.episodes) == len(H.SUITE.episodes)
    crash = H.make_results_file(tmp_path / "crash.json", "lb_fake_runner:crash")
    with pytest.raises(VerificationFailed, match="simulated crash"):
        submit(crash, "lb_fake_runner:crash", {"name": "crash", "track": "A"}, **options)
    assert cancelled == []
    with LeaderboardStore(url) as store:
        assert [e.name for e in store.entries()] == ["on ray"]


def test_submit_command_refuses_an_address_without_ray(tmp_path: Path) -> None:
    from rich.console import Console

    from swarmloc.cli import submit as submit_command

    console = Console(record=True, width=200, file=io.StringIO())
    opts = submit_command.Options(results=tmp_path / "r.json", address="auto", db_url=f"sqlite:///{tmp_path / 'x.db'}")
    assert submit_command.run(opts, console) == 1
    assert "needs --backend ray" in console.export_text()


def test_speed_rows_of_the_backends(ray_cluster) -> None:
    from swarmloc.bench.speed.evaluation import measure_evaluation, measure_rows

    suite = Suite("one", "0", (("swarmloc/GradualFault-v0", SEEDS[0]),))
    rows = measure_evaluation(suite, backends=("process", "ray"), workers=(2,))
    assert [(r["impl"], r["B"]) for r in rows] == [("evaluate-process", 2), ("evaluate-ray", 2)]
    assert all(r["episodes_per_s"] > 0 and r["env_steps_per_s"] == pytest.approx(300 * r["episodes_per_s"]) for r in rows)
    assert {"slowdown_vs_process", "overhead_s_per_task"} <= set(rows[1])
    assert measure_rows(quick=True) == []  # pools and clusters are not started in a smoke test
