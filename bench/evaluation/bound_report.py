"""The information bound against the shipped results, and what it costs.

Prints, reproducibly:

(a) per standard-v0 task, the task-mean bound (32 test seeds) beside the task-mean metric of
    every shipped method (``leaderboard/results/*.json``): ``rmse``, and on the tasks that
    define it (CascadedFault, CascadedFaultRandom) ``healthy_rmse`` against the bound on the
    same healthy UAVs and steps; any method below the bound is listed as a violation;
(b) Ideal-v0: uniform / bound;
(c) the time to compute the bounds of the whole suite (no cache) against the time to
    evaluate ``uniform`` on it (``runner.evaluate``, one worker), both on one thread, as the
    median of ``--repeats`` runs (CPU seconds and wall seconds).

Run: ``python -m swarmloc.bench.evaluation.bound_report [--repeats 3] [--no-timing]``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

from swarmloc.bench.evaluation.bounds import Bound, suite_bounds
from swarmloc.bench.evaluation.suites import get_suite

RESULTS_DIR = Path(__file__).resolve().parents[2] / "leaderboard" / "results"


def shipped_episodes(results_dir: Path = RESULTS_DIR) -> dict[str, dict[tuple[str, int], dict[str, float]]]:
    """method → (task, seed) → {``rmse``, ``healthy_rmse``} (those present) of the shipped results files."""
    out: dict[str, dict[tuple[str, int], dict[str, float]]] = {}
    for path in sorted(results_dir.glob("*.json")):
        data = json.loads(path.read_text(encoding="utf-8"))
        out[data["method"]["name"]] = {
            (ep["task"], int(ep["seed"])): {m: float(ep["metrics"][m]) for m in ("rmse", "healthy_rmse")
                                            if ep["metrics"].get(m) is not None}
            for ep in data["episodes"]}
    return out


def shipped_task_means(episodes: dict[str, dict[tuple[str, int], dict[str, float]]]
                       ) -> dict[str, dict[str, dict[str, float]]]:
    """method → task → metric → mean over the task's episodes."""
    out: dict[str, dict[str, dict[str, float]]] = {}
    for method, eps in episodes.items():
        values: dict[str, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
        for (task, _), metrics in eps.items():
            for metric, v in metrics.items():
                values[task][metric].append(v)
        out[method] = {t: {m: float(np.mean(v)) for m, v in ms.items()} for t, ms in values.items()}
    return out


def episodes_below(bounds: dict[tuple[str, int], Bound], episodes: dict) -> dict[str, int]:
    """method → number of its episodes whose ``rmse`` is below that episode's own bound (luck is allowed)."""
    out = {}
    for method, eps in episodes.items():
        out[method] = sum(1 for key, m in eps.items()
                          if key in bounds and bounds[key].rmse is not None and "rmse" in m
                          and m["rmse"] < bounds[key].rmse)
    return out


def bound_task_means(bounds: dict[tuple[str, int], Bound]) -> dict[str, dict[str, float | None]]:
    """task → metric → mean bound over its seeds (None where any seed has none)."""
    by_task: dict[str, list[Bound]] = defaultdict(list)
    for (task, _), b in bounds.items():
        by_task[task].append(b)
    out: dict[str, dict[str, float | None]] = {}
    for task, bs in by_task.items():
        out[task] = {}
        for metric in ("rmse", "healthy_rmse"):
            vals = [b.for_metric(metric) for b in bs]
            out[task][metric] = None if any(v is None for v in vals) else float(np.mean(vals))
    return out


def compare(bounds: dict[tuple[str, int], Bound], shipped: dict) -> tuple[list[str], list[str]]:
    """Table lines of (a) and the violations (a method's task mean below the bound's)."""
    means = bound_task_means(bounds)
    header = (f"{'task':34s} {'metric':12s} {'bound':>8s} {'best shipped':>29s} {'uniform':>8s} "
              f"{'best/bound':>10s}")
    lines = [header]
    violations = []
    for task, m in means.items():
        metric = "healthy_rmse" if m["healthy_rmse"] is not None else "rmse"
        for metric_shown in dict.fromkeys((metric, "rmse")):
            bound = m[metric_shown]
            if bound is None:
                reason = next(b.reason for (t, _), b in bounds.items() if t == task)
                lines.append(f"{task:34s} {metric_shown:12s} {'—':>8s}  ({reason})")
                continue
            rows = {name: res[task][metric_shown] for name, res in shipped.items()
                    if task in res and metric_shown in res[task]}
            if not rows:
                continue
            best = min(rows, key=rows.get)
            uniform = rows.get("uniform", float("nan"))
            lines.append(f"{task:34s} {metric_shown:12s} {bound:8.4f} {best:>20s} {rows[best]:8.4f} {uniform:8.4f} "
                         f"{rows[best] / bound:9.2f}×")
            violations += [f"{name} on {task} ({metric_shown}): {v:.4f} m < bound {bound:.4f} m"
                           for name, v in rows.items() if v < bound]
    return lines, violations


def time_bounds(suite) -> tuple[float, float, float, dict[str, tuple[float, float]]]:
    """(CPU s, wall s, CPU s of the world simulation alone, task → (world, recursion) CPU s) of every
    bound of ``suite``, on one thread.

    Nothing cached: each task's world is simulated (``record_inputs``) and the recursion run
    (``bounds_from_inputs``), as ``suite_bounds`` does on a cold cache. The world part is what
    a runner that records the inputs from its own uniform rollout (``BoundRecorder``) saves.
    """
    import numba

    from swarmloc.bench.evaluation.bounds import bounds_from_inputs
    from swarmloc.envs.bound import record_inputs, unsupported_reason
    from swarmloc.envs.tasks import get_spec

    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        per_task = {}
        cpu, wall = time.process_time(), time.perf_counter()
        for task in suite.tasks:
            spec, seeds = get_spec(task), suite.seeds(task)
            if unsupported_reason(spec) is not None:
                continue
            started = time.process_time()
            inputs, world = record_inputs(spec, seeds)
            recorded = time.process_time()
            bounds_from_inputs(spec, seeds, inputs, world.schedule)
            per_task[task] = (recorded - started, time.process_time() - recorded)
        world_cpu = sum(w for w, _ in per_task.values())
        return time.process_time() - cpu, time.perf_counter() - wall, world_cpu, per_task
    finally:
        numba.set_num_threads(threads)


def time_uniform(suite) -> tuple[float, float]:
    """(CPU s, wall s) of ``runner.evaluate("uniform", suite, workers=1)`` (its own reference runs included)."""
    from swarmloc.bench.evaluation import runner

    runner._REFERENCE_CACHE.clear()  # a fresh evaluation, as in a new process
    cpu, wall = time.process_time(), time.perf_counter()
    runner.evaluate("uniform", suite, workers=1, progress=False, trace=False)
    return time.process_time() - cpu, time.perf_counter() - wall


def warm_up() -> None:
    """Load the compiled kernels of both measurements once (not part of either time)."""
    from swarmloc.bench.evaluation import runner
    from swarmloc.bench.evaluation.bounds import compute_bounds
    from swarmloc.envs.tasks import get_spec

    spec = get_spec("swarmloc/Scale2-v0", duration=1.0)
    compute_bounds(spec, [1])
    runner.evaluate_task(["uniform"], spec, [1])


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--suite", default="standard-v0")
    parser.add_argument("--repeats", type=int, default=3, help="timing runs of each side (median reported)")
    parser.add_argument("--no-timing", action="store_true", help="skip (c)")
    args = parser.parse_args(argv)
    suite = get_suite(args.suite)

    warm_up()
    bounds = suite_bounds(suite)
    episodes = shipped_episodes()
    shipped = shipped_task_means(episodes)
    lines, violations = compare(bounds, shipped)
    print(f"(a) task-mean bound vs shipped methods ({args.suite}, {len(suite.episodes)} episodes; on CascadedFault* "
          "the scored metric is healthy_rmse, against the bound on the same healthy UAVs and steps)")
    print("\n".join(lines))
    print("task means below the bound: " + ("none" if not violations else "\n  " + "\n  ".join(violations)))
    below = {m: c for m, c in episodes_below(bounds, episodes).items() if c}
    print("single episodes below their own bound (rmse): " + (", ".join(f"{m} {c}" for m, c in below.items())
                                                             if below else "none"))
    ideal = bound_task_means(bounds).get("swarmloc/Ideal-v0", {}).get("rmse")
    if ideal is not None and "uniform" in shipped:
        u = shipped["uniform"]["swarmloc/Ideal-v0"]["rmse"]
        print(f"\n(b) Ideal-v0: uniform {u:.4f} m / bound {ideal:.4f} m = {u / ideal:.3f}×")

    if args.no_timing:
        return
    bound_runs, uniform_runs = [], []
    for _ in range(args.repeats):  # alternate, so that a change of machine load hits both sides
        bound_runs.append(time_bounds(suite))
        uniform_runs.append(time_uniform(suite))
    b_cpu, b_wall, b_world = (statistics.median(r[i] for r in bound_runs) for i in (0, 1, 2))
    u_cpu, u_wall = (statistics.median(r[i] for r in uniform_runs) for i in (0, 1))
    print(f"\n(c) cost on {args.suite}, median of {args.repeats} (one thread each):")
    print(f"    bounds  : {b_cpu:7.1f} s CPU {b_wall:7.1f} s wall   runs {[round(r[0], 1) for r in bound_runs]}"
          f"   of which world simulation {b_world:.1f} s CPU")
    print(f"    uniform : {u_cpu:7.1f} s CPU {u_wall:7.1f} s wall   runs {[round(r[0], 1) for r in uniform_runs]}")
    print(f"    ratio   : {b_cpu / u_cpu:7.1%} CPU {b_wall / u_wall:7.1%} wall (target ≤ 20 %); "
          f"without the world simulation (inputs recorded from the uniform rollout): {(b_cpu - b_world) / u_cpu:.1%} CPU")
    print("    bound CPU s per task (world simulation + recursion), last run:")
    for task, (w, r) in sorted(bound_runs[-1][3].items(), key=lambda kv: -sum(kv[1])):
        print(f"      {task:34s} {w:6.2f} + {r:6.2f}")


if __name__ == "__main__":
    main()
