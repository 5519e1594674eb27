"""The evaluation runner: methods × suite → per-episode metrics → a results file.

One task's seeds run as one batch (a ``TrustEnvBatch`` for Track A, a ``World`` for
Track B, B = number of seeds); tasks run in parallel worker processes (``workers``;
spawn-safe top-level job functions, numba limited to one thread per worker). Every
random draw is keyed by (seed, step, stream, index) and methods draw from per-episode
keys, so an episode's metrics are identical alone or batched, in any process — which is
what lets the leaderboard's verifier re-run a sample with :func:`run_episodes`.

**Normalized score.** Each episode's score compares its RMSE with the RMSE of the two
reference methods, ``uniform`` (score 0) and the privileged ``oracle`` (score 1), run
on the same (task, seed) on the fly (their runs are shared when they are evaluated too,
and cached per process). Nothing precomputed is shipped, so a score is always
consistent with the code that produced it.

Privileged methods get the pending measurements' fault labels through
``observe_privileged`` before every ``act``/``step``; no other method ever does.
"""

from __future__ import annotations

import contextlib
import hashlib
import multiprocessing
import os
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from swarmloc.agents.protocols import (
    EstimatorOutput,
    Measurements,
    PrivilegedInfo,
    TaskFacts,
    TrustInput,
    UnsupportedTask,
    episode_keys,
)
from swarmloc.agents.registry import REFERENCE_ORACLE, REFERENCE_UNIFORM, LoadedMethod, load_method
from swarmloc.bench.evaluation import metrics as M
from swarmloc.bench.evaluation.recorder import EpisodeRecorder
from swarmloc.bench.evaluation.results import METRIC_NAMES, MethodInfo, Results, SuiteInfo, make_results, write_results
from swarmloc.bench.evaluation.suites import Suite, require_data
from swarmloc.bench.evaluation.traces import Trace, read_traces, traces_path, write_traces
from swarmloc.envs.specs import TaskSpec
from swarmloc.envs.tasks import get_spec
from swarmloc.envs.trust_env import TrustEnvBatch
from swarmloc.envs.world import World, validate_seeds

MAX_WORKERS = 64
_Recorder = EpisodeRecorder  # former private name, kept for existing imports


def make_world(spec: TaskSpec, batch_size: int) -> Any:
    """The task's world: ``swarmloc.envs.worlds.make_world`` (simulated or recorded) where available."""
    try:
        from swarmloc.envs.worlds import make_world as _make_world
    except ImportError:  # an envs without recorded worlds: every world is simulated
        return World(spec, batch_size)
    return _make_world(spec, batch_size)


# --------------------------------------------------------------------------- rollouts


def _readonly(arr: np.ndarray) -> np.ndarray:
    view = arr.view()
    view.flags.writeable = False
    return view


def _reset_or_unsupported(loaded: LoadedMethod, spec: TaskSpec, reset: Callable[[], None]) -> None:
    """Call a method's reset; a refusal (ValueError / NotImplementedError) means "cannot run this task"."""
    try:
        reset()
    except UnsupportedTask:
        raise
    except (ValueError, NotImplementedError) as err:
        raise UnsupportedTask(f"{loaded.name} cannot run {spec.task_id}: {err}") from err


def _rollout_policy(loaded: LoadedMethod, spec: TaskSpec, seeds: np.ndarray, trace: bool) -> tuple[EpisodeRecorder, Any]:
    """Run a Track A policy on B episodes through ``TrustEnvBatch``, the env every adapter wraps.

    Observation, reward, FLOPs and delay come from the env's ``step``: the numbers a
    Gymnasium user sees are the numbers the leaderboard records.
    """
    policy = loaded.method
    n_b = len(seeds)
    env = TrustEnvBatch(spec, n_b, policy_flops_per_channel=float(getattr(policy, "flops_per_channel", 0.0)))
    cs = env.reset(seeds)
    layout = env.layout
    _reset_or_unsupported(loaded, spec, lambda: policy.reset(n_b, layout, episode_keys(seeds)))
    obs = None
    rec = EpisodeRecorder(spec, seeds, getattr(env.core.world, "schedule", None), layout.n_channels, True, True, trace)
    for k in range(spec.n_steps):
        obs = env.observation(out=obs)
        inp = TrustInput.view(obs, cs.resid, cs.pred, cs.nis, cs.applied, cs.jerk, cs.valid,
                              (k + 1) * spec.dt, k + 1)
        if loaded.privileged:
            policy.observe_privileged(PrivilegedInfo(labels=_readonly(env.pending_labels().copy())))
        cs, terms = env.step(env.check(policy.act(inp)))
        rec.record(k, cs.estimate, cs.truth, cs.update_valid, cs.label, cs.applied, cs.prev_trust, terms.flops,
                   terms)
    return rec, layout


def _check_output(out: Any, name: str, shape: tuple[int, int, int]) -> EstimatorOutput:
    n_b, n, n_l = shape
    if not isinstance(out, EstimatorOutput):
        raise TypeError(f"estimator {name!r} returned {type(out).__name__}; expected EstimatorOutput")
    pos = np.asarray(out.positions)
    if pos.shape != (n_b, n, 3):
        raise ValueError(f"estimator {name!r} returned positions of shape {pos.shape}; expected (B, N, 3) = "
                         f"{(n_b, n, 3)}")
    if not np.isfinite(pos).all():
        bad = tuple(np.argwhere(~np.isfinite(pos))[0].tolist())
        raise ValueError(f"estimator {name!r} returned a non-finite position {pos[bad]} at index {bad}")
    if out.weights is not None and np.shape(out.weights) != (n_b, n, n_l):
        raise ValueError(f"estimator {name!r} returned weights of shape {np.shape(out.weights)}; expected "
                         f"(B, N, L) = {(n_b, n, n_l)}")
    if out.flops is not None and np.shape(out.flops) != (n_b, n):
        raise ValueError(f"estimator {name!r} returned flops of shape {np.shape(out.flops)}; expected (B, N) = "
                         f"{(n_b, n)}")
    return out


def _rollout_estimator(loaded: LoadedMethod, spec: TaskSpec, seeds: np.ndarray,
                       trace: bool) -> tuple[EpisodeRecorder, Any]:
    """Run a Track B estimator on B episodes through ``World``."""
    est = loaded.method
    n_b = len(seeds)
    world = make_world(spec, n_b)
    x0 = world.reset(seeds).copy()
    facts = TaskFacts.from_spec(spec, world.layout, x0, episode_keys(seeds), anchors=world.anchors)
    _reset_or_unsupported(loaded, spec, lambda: est.reset(facts, facts.x0))
    shape = (n_b, spec.n_uav, world.layout.n_channels)
    rec: EpisodeRecorder | None = None
    previous: np.ndarray | None = None
    for k in range(spec.n_steps):
        buf = world.sense()
        meas = Measurements.capture(buf.imu, buf.z, buf.valid, (k + 1) * spec.dt, k + 1,
                                    getattr(buf, "velocity", None))
        if loaded.privileged:
            est.observe_privileged(PrivilegedInfo(labels=_readonly(buf.label.copy())))
        out = _check_output(est.step(meas), loaded.name, shape)
        if rec is None:
            rec = EpisodeRecorder(spec, seeds, getattr(world, "schedule", None), shape[2], out.weights is not None, out.flops is not None,
                            trace)
        weights = None if out.weights is None else np.clip(np.asarray(out.weights, dtype=np.float64), 0.0, 1.0)
        if weights is not None and previous is None:
            previous = np.ones(shape)
        flops = None if out.flops is None else np.asarray(out.flops, dtype=np.float64)
        rec.record(k, np.asarray(out.positions, dtype=np.float64), buf.pos, buf.valid, buf.label, weights,
                   previous, flops)
        previous = weights
    assert rec is not None  # n_steps >= 1
    return rec, world.layout


@contextlib.contextmanager
def single_threaded_kernels() -> Iterator[None]:
    """Run numba kernels on one thread inside the block (restored afterwards).

    The runner's batches are small (B = seeds per task): thread launches cost more than
    they save, and on a busy machine spinning threads slow everything down tenfold.
    Parallelism comes from worker processes instead.
    """
    import numba

    previous = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(previous)


def rollout(loaded: LoadedMethod, spec: TaskSpec, seeds: Sequence[int],
            trace: bool = False) -> tuple[list[dict[str, float | None]], Trace | None]:
    """Run one method on B episodes of one task.

    Args:
        loaded: the method (fresh instance; it is reset here).
        spec: the task (may carry overrides such as a shorter duration).
        seeds: ``(B,)`` episode seeds.
        trace: also return the per-step trace of the first seed.

    Returns:
        ``(metrics per seed, trace or None)``; ``normalized_score`` is None here.
    """
    seeds = validate_seeds(list(seeds))
    run = _rollout_policy if loaded.track == "A" else _rollout_estimator
    with single_threaded_kernels():
        rec, layout = run(loaded, spec, seeds, trace)
    return [rec.episode_metrics(b) for b in range(len(seeds))], rec.make_trace(loaded.name, layout.kind)


# --------------------------------------------------------------------------- references and tasks

_REFERENCE_CACHE: dict[tuple[str, str, int], float] = {}


def _spec_key(spec: TaskSpec) -> str:
    return hashlib.sha256(spec.model_dump_json().encode()).hexdigest()


def reference_rmse(name: str, spec: TaskSpec, seeds: Sequence[int]) -> list[float]:
    """RMSE of a reference method (``uniform`` or ``oracle``) per seed, cached per process."""
    key = _spec_key(spec)
    missing = [int(s) for s in seeds if (name, key, int(s)) not in _REFERENCE_CACHE]
    if missing:
        metrics, _ = rollout(load_method(name), spec, missing)
        for seed, m in zip(missing, metrics):
            _REFERENCE_CACHE[(name, key, seed)] = float(m["rmse"])  # type: ignore[arg-type]
    return [_REFERENCE_CACHE[(name, key, int(s))] for s in seeds]


@dataclass
class TaskOutcome:
    """Per-episode results of several methods on one task's seeds.

    Attributes:
        task: task ID; seeds: the seeds, in order.
        episodes: method → one metrics dict per seed.
        traces: method → trace of the first seed (when requested).
        unsupported: method → why it cannot run this task (its metrics are all null).
        cpu_seconds: method → CPU time of its rollout (references excluded).
    """

    task: str
    seeds: list[int]
    episodes: dict[str, list[dict[str, float | None]]] = field(default_factory=dict)
    traces: dict[str, Trace] = field(default_factory=dict)
    unsupported: dict[str, str] = field(default_factory=dict)
    cpu_seconds: dict[str, float] = field(default_factory=dict)


def evaluate_task(methods: Sequence[str], task: str | TaskSpec, seeds: Sequence[int], *,
                  weights: Mapping[str, str | None] | None = None, trace: bool = False) -> TaskOutcome:
    """Evaluate methods on one task's seeds (one batch per method), normalized scores included.

    Args:
        methods: method names or entry points (see ``load_method``).
        task: task ID or a spec (e.g. ``get_spec(id, duration=10)`` in tests).
        seeds: the episode seeds.
        weights: optional method → weights file.
        trace: keep the trace of the first seed of each method.

    Returns:
        The ``TaskOutcome``.
    """
    spec = get_spec(task) if isinstance(task, str) else task
    seeds = [int(s) for s in validate_seeds(list(seeds))]
    outcome = TaskOutcome(task=spec.task_id, seeds=seeds)
    weights = weights or {}
    for text in methods:
        loaded = load_method(text, weights.get(text))
        started = time.process_time()
        try:
            metrics, tr = rollout(loaded, spec, seeds, trace=trace)
        except UnsupportedTask as err:
            outcome.unsupported[text] = str(err)
            outcome.episodes[text] = [{name: None for name in METRIC_NAMES} for _ in seeds]
            continue
        finally:
            outcome.cpu_seconds[text] = time.process_time() - started
        outcome.episodes[text] = metrics
        if tr is not None:
            outcome.traces[text] = tr
        if text in (REFERENCE_UNIFORM, REFERENCE_ORACLE):
            key = _spec_key(spec)
            for seed, m in zip(seeds, metrics):
                _REFERENCE_CACHE[(text, key, seed)] = float(m["rmse"])  # type: ignore[arg-type]
    uniform = reference_rmse(REFERENCE_UNIFORM, spec, seeds)
    oracle = reference_rmse(REFERENCE_ORACLE, spec, seeds)
    for metrics in outcome.episodes.values():
        for m, u, o in zip(metrics, uniform, oracle):
            if m["rmse"] is not None:
                m["normalized_score"] = M.normalized_score(m["rmse"], u, o)  # type: ignore[arg-type]
    return outcome


def run_episodes(method: str, episodes: list[tuple[str, int]], weights: str | None = None) -> list[dict]:
    """Re-run some episodes of one method (the leaderboard verifier's entry point).

    Episodes of the same task run as one batch; results do not depend on the batching.

    Args:
        method: registered name or entry point.
        episodes: ``(task ID, seed)`` pairs.
        weights: optional weights file for the method.

    Returns:
        ``[{"task", "seed", "metrics": {...}}]`` in the order of ``episodes``.
    """
    by_task: dict[str, list[int]] = {}
    for task, seed in episodes:
        by_task.setdefault(get_spec(task).task_id, [])
        if int(seed) not in by_task[get_spec(task).task_id]:
            by_task[get_spec(task).task_id].append(int(seed))
    found: dict[tuple[str, int], dict[str, float | None]] = {}
    for task, seeds in by_task.items():
        outcome = evaluate_task([method], task, seeds, weights={method: weights})
        for seed, m in zip(seeds, outcome.episodes[method]):
            found[(task, seed)] = m
    return [{"task": get_spec(t).task_id, "seed": int(s), "metrics": found[(get_spec(t).task_id, int(s))]}
            for t, s in episodes]


# --------------------------------------------------------------------------- suites, in parallel


def _worker_init() -> None:
    """Spawned workers run numba single-threaded: the parallelism is across tasks."""
    import numba

    numba.set_num_threads(1)


def _task_job(methods: list[str], task: str, seeds: list[int], weights: dict[str, str | None],
              trace: bool) -> TaskOutcome:
    """Top-level (picklable) job: some methods on one task's seeds."""
    return evaluate_task(methods, task, seeds, weights=weights, trace=trace)


def _task_cost(task: str, n_seeds: int) -> float:
    s = get_spec(task)
    return float(s.n_steps * s.n_uav * (s.n_channels + 4) * n_seeds)


def _merge(into: TaskOutcome, part: TaskOutcome) -> None:
    """Add a job's methods to the task's outcome."""
    into.episodes.update(part.episodes)
    into.traces.update(part.traces)
    into.unsupported.update(part.unsupported)
    into.cpu_seconds.update(part.cpu_seconds)


@dataclass
class MethodRun:
    """One method's evaluation on a suite.

    Attributes:
        loaded: the method's metadata (and an instance, unused after loading).
        episodes: ``[{"task", "seed", "metrics"}]`` in suite order.
        traces: first-seed traces per task.
        weights: the weights file, if any.
        unsupported: task → why the method cannot run it (null metrics there).
        cpu_seconds: CPU time of its rollouts over the suite.
    """

    loaded: LoadedMethod
    episodes: list[dict[str, Any]]
    traces: list[Trace]
    weights: str | None = None
    unsupported: dict[str, str] = field(default_factory=dict)
    cpu_seconds: float = 0.0

    def results(self, suite: Suite) -> Results:
        """Assemble the results file (aggregates, provenance) of this run."""
        return make_results(method_info(self.loaded, self.weights), suite_info(suite), self.episodes)


def method_info(loaded: LoadedMethod, weights: str | None = None) -> MethodInfo:
    """The results-file description of a loaded method."""
    digest = None
    if weights is not None:
        digest = hashlib.sha256(Path(weights).read_bytes()).hexdigest()
    return MethodInfo(name=loaded.name, entry_point=loaded.entry_point, weights_sha256=digest,
                      privileged=loaded.privileged, track=loaded.track, deterministic=loaded.deterministic)


def suite_info(suite: Suite) -> SuiteInfo:
    """The results-file description of a suite."""
    return SuiteInfo(name=suite.name, version=suite.version, sha256=suite.sha256)


def evaluate_methods(methods: Sequence[str], suite: Suite, *, workers: int = 1,
                     weights: Mapping[str, str | None] | None = None, trace: bool = True,
                     progress: bool = True,
                     on_task: Callable[[TaskOutcome], None] | None = None) -> dict[str, MethodRun]:
    """Evaluate several methods on a suite, (task, method) runs in parallel.

    Args:
        methods: method names or entry points.
        suite: the suite.
        workers: worker processes (1 = run here, no pool), in [1, 64].
        weights: optional method → weights file.
        trace: keep first-seed traces for plots.
        progress: show a progress bar (tqdm, on stderr).
        on_task: called with each task's outcome once all its methods are done.

    Returns:
        method → ``MethodRun``, episodes in suite order.
    """
    if not 1 <= workers <= MAX_WORKERS:
        raise ValueError(f"workers must be in [1, {MAX_WORKERS}], got {workers}")
    if not methods:
        raise ValueError("no method to evaluate")
    from tqdm.auto import tqdm

    weights = {m: (str(w) if w is not None else None) for m, w in (weights or {}).items()}
    loaded = {m: load_method(m, weights.get(m)) for m in methods}  # fail fast, before any work
    require_data(suite)  # a recorded task whose data is not imported here: say so before any work
    # one job per (task, method): the pool balances methods of very different cost; the
    # references of the normalized score are cached per worker process
    tasks = sorted(suite.tasks, key=lambda t: -_task_cost(t, len(suite.seeds(t))))
    jobs = [(task, m) for task in tasks for m in methods] if workers > 1 else [(task, None) for task in tasks]
    outcomes = {task: TaskOutcome(task=task, seeds=suite.seeds(task)) for task in suite.tasks}
    pending = {task: len(methods) for task in suite.tasks}
    label = methods[0] if len(methods) == 1 else f"{len(methods)} methods"
    bar = tqdm(total=len(suite.tasks) * len(methods), desc=f"evaluating {label} on {suite.name}",
               unit="run", disable=not progress)

    def done(part: TaskOutcome) -> None:
        _merge(outcomes[part.task], part)
        pending[part.task] -= len(part.episodes)
        bar.update(len(part.episodes))
        bar.set_postfix_str(part.task.removeprefix("swarmloc/"))
        if on_task is not None and pending[part.task] == 0:
            on_task(outcomes[part.task])

    try:
        if workers == 1:
            for task, _ in jobs:
                done(_task_job(list(methods), task, suite.seeds(task), weights, trace))
        else:
            ctx = multiprocessing.get_context("spawn")
            with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_worker_init) as pool:
                futures = [pool.submit(_task_job, [m], task, suite.seeds(task), weights, trace) for task, m in jobs]
                for future in as_completed(futures):
                    done(future.result())
    finally:
        bar.close()
    runs = {}
    for m in methods:
        episodes = []
        traces = []
        for task in suite.tasks:
            out = outcomes[task]
            episodes += [{"task": task, "seed": s, "metrics": met} for s, met in zip(out.seeds, out.episodes[m])]
            if m in out.traces:
                traces.append(out.traces[m])
        unsupported = {t: outcomes[t].unsupported[m] for t in suite.tasks if m in outcomes[t].unsupported}
        runs[m] = MethodRun(loaded=loaded[m], episodes=episodes, traces=traces, weights=weights.get(m),
                            unsupported=unsupported,
                            cpu_seconds=sum(outcomes[t].cpu_seconds.get(m, 0.0) for t in suite.tasks))
    return runs


def evaluate(method: str, suite: Suite, out: str | os.PathLike[str] | None = None, *, workers: int = 1,
             weights: str | None = None, progress: bool = True, trace: bool = True) -> Results:
    """Evaluate one method on a suite and (optionally) write the results file.

    Args:
        method: registered name or entry point.
        suite: the suite.
        out: results file to write atomically (traces go to ``<stem>.traces.npz`` beside it).
        workers: worker processes.
        weights: optional weights file.
        progress: show a progress bar.
        trace: keep first-seed traces (written only with ``out``).

    Returns:
        The validated ``Results``.
    """
    run = evaluate_methods([method], suite, workers=workers, weights={method: weights}, trace=trace,
                           progress=progress)[method]
    results = run.results(suite)
    if out is not None:
        write_results(out, results)
        if run.traces:
            write_traces(traces_path(out), run.traces)
    return results


__all__ = [
    "MethodRun",
    "TaskOutcome",
    "Trace",
    "evaluate",
    "evaluate_methods",
    "evaluate_task",
    "read_traces",
    "reference_rmse",
    "rollout",
    "run_episodes",
    "traces_path",
    "write_traces",
]
