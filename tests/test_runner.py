"""The runner: batching invariance, results round trip, parallel == serial, bad methods rejected."""

from __future__ import annotations

import numpy as np
import pytest

from swarmloc.agents.estimators.dead_reckoning import DeadReckoning
from swarmloc.agents.protocols import EstimatorOutput, Measurements
from swarmloc.agents.registry import LoadedMethod, load_method
from swarmloc.bench.evaluation.results import METRIC_NAMES, load_results
from swarmloc.bench.evaluation.runner import (
    evaluate,
    evaluate_methods,
    evaluate_task,
    read_traces,
    rollout,
    run_episodes,
    traces_path,
)
from swarmloc.bench.evaluation.suites import Suite
from swarmloc.envs.tasks.catalogue import get_spec

EPISODES = [("swarmloc/NLOS-v0", 1_000_001), ("swarmloc/CascadedFaultRandom-v0", 1_000_002),
            ("NLOS-v0", 1_000_000), ("swarmloc/CascadedFaultRandom-v0", 1_000_000)]


@pytest.mark.parametrize("method", ["random", "chi2-gate"])
def test_run_episodes_single_equals_batched(method):
    batched = run_episodes(method, EPISODES)
    assert [(e["task"], e["seed"]) for e in batched] == [
        ("swarmloc/NLOS-v0", 1_000_001), ("swarmloc/CascadedFaultRandom-v0", 1_000_002),
        ("swarmloc/NLOS-v0", 1_000_000), ("swarmloc/CascadedFaultRandom-v0", 1_000_000)]
    for episode, expected in zip(EPISODES, batched):
        alone = run_episodes(method, [episode])[0]
        assert alone == expected
    assert set(batched[0]["metrics"]) == set(METRIC_NAMES)


def test_metric_definitions_per_task():
    out = evaluate_task(["uniform"], get_spec("swarmloc/Ideal-v0", duration=3.0), [1_000_000]).episodes["uniform"]
    m = out[0]
    assert m["fault_rmse"] is None and m["healthy_rmse"] is None and m["anomaly_detection_rate"] is None
    assert "normalized_score" not in m  # the retired v0 score
    assert m["uniform_rmse"] == m["rmse"]  # uniform is its own reference
    assert m["recovery_s"] is None and m["recovered"] is None  # no IMU fault
    assert m["jitter"] == 0.0 and m["diverged"] == 0.0
    assert m["delay_ms"] > 0 and m["energy_j"] > 0
    rnd = evaluate_task(["uniform"], get_spec("swarmloc/CascadedFaultRandom-v0", duration=30.0),
                        [1_000_000, 1_000_001]).episodes["uniform"]
    assert all(e["healthy_rmse"] is not None and e["fault_rmse"] is not None for e in rnd)


def test_per_episode_healthy_scoring_scores_exactly_the_healthy_uavs():
    from swarmloc.envs.world.sim import World

    spec = get_spec("swarmloc/CascadedFaultRandom-v0", duration=41.0, scoring={"nodes_from_schedule": "healthy"})
    seeds = [1_000_000, 1_000_001]
    world = World(spec, len(seeds))
    world.reset(np.array(seeds))
    faulty = world.schedule.faulty_nodes
    batched, _ = rollout(load_method("chi2-soft"), spec, seeds)
    for b, seed in enumerate(seeds):
        alone, trace = rollout(load_method("chi2-soft"), spec, [seed], trace=True)
        assert alone[0] == batched[b]  # bit for bit, though the batch's episodes score different UAVs
        healthy = ~faulty[b]
        assert (trace.scored == healthy).all() and healthy.sum() == 2
        e = np.linalg.norm(trace.estimate - trace.truth, axis=-1)  # (T, N)
        assert alone[0]["rmse"] == pytest.approx(np.sqrt(np.mean(e[:, healthy] ** 2)), rel=1e-12)
        assert alone[0]["max_error"] == pytest.approx(e[:, healthy].max(), rel=1e-12)
        assert alone[0]["recovery_s"] is not None and alone[0]["recovered"] in (0.0, 1.0)
    every, _ = rollout(load_method("chi2-soft"), get_spec("swarmloc/CascadedFaultRandom-v0", duration=41.0), seeds)
    for m, v0 in zip(batched, every):  # only the scored set differs from v0's scoring
        assert m["healthy_rmse"] == v0["healthy_rmse"] and m["recovery_s"] == v0["recovery_s"]
        assert m["rmse"] != v0["rmse"]


def _tiny_suite() -> Suite:
    return Suite("tiny", "0", (("swarmloc/Ideal-v0", 1_000_000), ("swarmloc/Ideal-v0", 1_000_001),
                               ("swarmloc/GradualFault-v0", 1_000_000)))


def test_results_file_round_trip(tmp_path):
    out = tmp_path / "r.json"
    results = evaluate("chi2-soft", _tiny_suite(), out, progress=False)
    loaded = load_results(out)
    assert loaded == results
    assert loaded.method.name == "chi2-soft" and loaded.method.track == "A" and not loaded.method.privileged
    assert loaded.suite.sha256 == _tiny_suite().sha256
    assert loaded.episode_keys() == list(_tiny_suite().episodes)
    traces = read_traces(traces_path(out))
    assert {t.task for t in traces} == {"swarmloc/Ideal-v0", "swarmloc/GradualFault-v0"}
    ideal = next(t for t in traces if t.task == "swarmloc/Ideal-v0")
    assert ideal.seed == 1_000_000 and ideal.estimate.shape == (400, 4, 3)
    # the trace is the episode: its RMSE is the file's
    assert np.sqrt(np.mean(ideal.errors**2)) == pytest.approx(loaded.episodes[0].metrics.rmse, rel=1e-12)


def test_parallel_workers_equal_serial():
    suite = Suite("tiny2", "0", (("swarmloc/GradualFault-v0", 1_000_000), ("swarmloc/CascadedFault-v0", 1_000_003)))
    serial = evaluate_methods(["random", "oracle"], suite, workers=1, trace=False, progress=False)
    parallel = evaluate_methods(["random", "oracle"], suite, workers=2, trace=False, progress=False)
    for name in ("random", "oracle"):
        assert serial[name].episodes == parallel[name].episodes


def test_a_suite_runs_each_reference_once_per_task_and_scores_as_evaluate_task(monkeypatch):
    import swarmloc.bench.evaluation.runner as runner

    ran: list[tuple[str, str, tuple[int, ...]]] = []
    real_rollout = runner.rollout

    def counting(loaded, spec, seeds, trace=False):
        ran.append((loaded.name, spec.task_id, tuple(int(s) for s in seeds)))
        return real_rollout(loaded, spec, seeds, trace)

    monkeypatch.setattr(runner, "rollout", counting)
    monkeypatch.setattr(runner, "_REFERENCE_CACHE", {})  # nothing cached by earlier tests
    short = {"duration": 8.0}
    suite = Suite("tiny3", "0", (("swarmloc/NLOS-v0", 1_000_000), ("swarmloc/NLOS-v0", 1_000_001),
                                 ("swarmloc/CascadedFault-v0", 1_000_003)))
    runs = evaluate_methods(["chi2-gate", "random", "uniform"], suite, seeds_per_job=1, trace=False,
                            progress=False, overrides=short)
    # one rollout per (method, chunk): uniform, the only reference, is shared with the evaluated method
    assert sorted(ran) == sorted((m, t, (s,)) for t, s in suite.episodes
                                 for m in ("chi2-gate", "random", "uniform"))
    for task in suite.tasks:
        alone = evaluate_task(["chi2-gate", "random", "uniform"], get_spec(task, **short), suite.seeds(task))
        for m in ("chi2-gate", "random", "uniform"):
            assert [e["metrics"] for e in runs[m].episodes if e["task"] == task] == alone.episodes[m]
    assert all(e["metrics"]["uniform_rmse"] is not None for e in runs["random"].episodes)
    # a later evaluation in this process takes the references from the process cache
    ran.clear()
    huber = evaluate_methods(["huber"], suite, seeds_per_job=1, trace=False, progress=False, overrides=short)["huber"]
    assert sorted(ran) == sorted(("huber", t, (s,)) for t, s in suite.episodes)
    assert [e["metrics"]["uniform_rmse"] for e in huber.episodes] == \
        [e["metrics"]["rmse"] for e in runs["uniform"].episodes]


@pytest.mark.parametrize("suite_name", ["standard-v0", "standard-v1"])
def test_a_suite_evaluation_runs_no_oracle(monkeypatch, suite_name):
    """The only reference job is uniform's, on v0 suites too: the v0 score's oracle is never run."""
    import swarmloc.bench.evaluation.runner as runner
    from swarmloc.bench.evaluation.suites import get_suite

    class Stop(Exception):
        pass

    jobs: list = []

    def record(fn, all_jobs, **kwargs):
        jobs.extend(all_jobs)
        raise Stop

    monkeypatch.setattr(runner, "run_jobs", record)
    monkeypatch.setattr(runner, "_REFERENCE_CACHE", {})
    suite = get_suite(suite_name)
    with pytest.raises(Stop):
        evaluate_methods(["chi2-soft"], suite, trace=False, progress=False)
    assert {j.method for j in jobs} == {"chi2-soft", "uniform"}
    assert not any("oracle" in j.method for j in jobs)
    assert sorted((j.task, s) for j in jobs if j.method == "uniform" for s in j.seeds) == sorted(suite.episodes)


def test_a_failed_reference_fails_its_task_for_every_method(monkeypatch):
    import swarmloc.bench.evaluation.runner as runner

    real_rollout = runner.rollout

    def broken_uniform(loaded, spec, seeds, trace=False):
        if loaded.name == "uniform" and spec.task_id == "swarmloc/NLOS-v0":
            raise RuntimeError("no reference today")
        return real_rollout(loaded, spec, seeds, trace)

    monkeypatch.setattr(runner, "rollout", broken_uniform)
    monkeypatch.setattr(runner, "_REFERENCE_CACHE", {})
    suite = Suite("tiny2", "0", (("swarmloc/NLOS-v0", 1_000_000), ("swarmloc/Ideal-v0", 1_000_000)))
    run = evaluate_methods(["random"], suite, trace=False, progress=False, overrides={"duration": 3.0})["random"]
    assert list(run.failed) == ["swarmloc/NLOS-v0"]
    assert run.failed["swarmloc/NLOS-v0"].startswith("the reference uniform failed on this task: RuntimeError")
    assert [e["task"] for e in run.episodes] == ["swarmloc/Ideal-v0"]


class _BadShape(DeadReckoning):
    def step(self, meas: Measurements) -> EstimatorOutput:
        return EstimatorOutput(positions=np.zeros((1, 2, 3)))


class _NonFinite(DeadReckoning):
    def step(self, meas: Measurements) -> EstimatorOutput:
        out = super().step(meas)
        out.positions[0, 0, 0] = np.nan
        return out


def _as_loaded(method, track="B") -> LoadedMethod:
    return LoadedMethod(type(method).__name__, "test", track, False, True, method)


def test_bad_estimator_output_rejected():
    spec = get_spec("swarmloc/Ideal-v0", duration=0.5)
    with pytest.raises(ValueError, match=r"positions of shape \(1, 2, 3\); expected \(B, N, 3\) = \(2, 4, 3\)"):
        rollout(_as_loaded(_BadShape()), spec, [1, 2])
    with pytest.raises(ValueError, match="non-finite position"):
        rollout(_as_loaded(_NonFinite()), spec, [1, 2])


class _WrongTrust:
    privileged = False
    flops_per_channel = 0.0

    def reset(self, batch_size, layout, keys):
        pass

    def act(self, inp):
        return np.ones(inp.valid.shape[:-1])


def test_bad_policy_output_rejected():
    spec = get_spec("swarmloc/Ideal-v0", duration=0.5)
    with pytest.raises(ValueError, match=r"must have shape \(B, N, L\)"):
        rollout(_as_loaded(_WrongTrust(), "A"), spec, [1])


def test_bad_arguments():
    with pytest.raises(ValueError, match="workers must be in"):
        evaluate_methods(["uniform"], _tiny_suite(), workers=0)
    with pytest.raises(KeyError, match="unknown method"):
        evaluate_methods(["nope"], _tiny_suite())
    with pytest.raises(ValueError, match="seeds must be >= 0"):
        rollout(load_method("uniform"), get_spec("swarmloc/Ideal-v0", duration=0.5), [-1])


class _NeedsGps(DeadReckoning):
    def reset(self, facts, x0):
        raise ValueError("this estimator needs GPS")


def test_unsupported_task_gives_null_metrics(monkeypatch):
    import swarmloc.bench.evaluation.runner as runner

    real_load = runner.load_method
    monkeypatch.setattr(runner, "load_method",
                        lambda text, weights=None, version=None: (_as_loaded(_NeedsGps()) if text == "needs-gps"
                                                                  else real_load(text, version=version)))
    out = evaluate_task(["needs-gps"], get_spec("swarmloc/Ideal-v0", duration=0.5), [1, 2])
    assert out.unsupported["needs-gps"].endswith("this estimator needs GPS")
    assert all(v is None for m in out.episodes["needs-gps"] for v in m.values())


def _python_ok(code: str) -> None:
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr


def test_pool_workers_run_numba_and_torch_on_one_thread():
    """A worker starts without torch; a job's method imports it, the runner pins it to one thread.
    Outside a pool worker (the serial backend, in the caller's process) too: a threaded matrix product
    may sum in a thread-dependent order, and a learned method must act the same on every backend."""
    _python_ok("import sys, numba\n"
               "from swarmloc.bench.evaluation.backends import pin_torch_threads, worker_init\n"
               "worker_init()\n"
               "assert numba.get_num_threads() == 1 and 'torch' not in sys.modules\n"
               "import torch\n"
               "torch.set_num_threads(2)\n"
               "pin_torch_threads()\n"
               "assert torch.get_num_threads() == 1, torch.get_num_threads()\n")
    _python_ok("import torch\n"
               "from swarmloc.bench.evaluation.backends import pin_torch_threads\n"
               "torch.set_num_threads(2)\n"
               "pin_torch_threads()\n"
               "assert torch.get_num_threads() == 1, torch.get_num_threads()\n")


def test_evaluate_task_pins_torch_after_loading_the_method(monkeypatch):
    """The runner calls pin_torch_threads between loading a method and running it."""
    import swarmloc.bench.evaluation.runner as runner

    calls = []
    real_load = runner.load_method
    monkeypatch.setattr(runner, "load_method",
                        lambda text, weights=None, version=None: calls.append("load") or real_load(text, version=version))
    monkeypatch.setattr(runner, "pin_torch_threads", lambda: calls.append("pin"))
    evaluate_task(["uniform"], get_spec("swarmloc/Ideal-v0", duration=0.5), [1])
    assert calls[:2] == ["load", "pin"]
