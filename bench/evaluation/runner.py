"""The evaluation runner: methods × suite → per-episode metrics → a results file.

One task's seeds run as one batch through the episode loop (``episode.py``: a
``TrustEnvBatch`` for Track A, the task's world for Track B, B = number of seeds), scored
by its metrics observer (``recorder.py``); a suite runs as (method, task, seed-chunk) jobs on an
execution backend, ``serial``, ``process`` or ``ray`` (``backends.py``; the chunks come
back together in ``outcomes.py``). Every random draw is keyed by (seed, step, stream,
index) and methods draw from per-episode keys, so an episode's metrics are identical
alone or batched, in any process, on any backend — which is what lets the leaderboard's
verifier re-run a sample with :func:`run_episodes`.

**The reference.** The score (``score.py``, docs/scoring.md) compares each episode's RMSE
with that of the reference method ``uniform`` (the standard CEKF, α = 1) on the same
(task, seed), run on the fly and recorded as ``uniform_rmse``. A suite evaluation runs it
once per task chunk, as a job of its own (or shares the evaluated method's run) and fills
it in when the task is done; ``evaluate_task`` alone runs it itself, cached per process.
Nothing precomputed is shipped, so a score is always consistent with the code that
produced it.

Privileged methods get the pending measurements' fault labels through
``observe_privileged`` before every ``act``/``step`` (in the episode loop); no other method ever does. A
``PrivilegedInfo`` carries the injected-fault labels (what the detection metrics count)
and the error labels (``swarmloc.envs.world.labels``): on Track A the core's, peer links included
through the neighbour's broadcast estimate, with the systematic error in σ_eff behind them;
on Track B the world's, the measurement's own error only (an estimator's estimates are its
own).
"""

from __future__ import annotations

import hashlib
import os
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from swarmloc.agents.protocols import UnsupportedTask
from swarmloc.agents.registry import REFERENCE_UNIFORM, LoadedMethod, load_method
from swarmloc.bench.evaluation.backends import (
    BACKENDS,
    MAX_WORKERS,
    Backend,
    Job,
    JobFailure,
    check_backend,
    pin_torch_threads,
    run_jobs,
)
from swarmloc.bench.evaluation.episode import fly_episodes, single_threaded_kernels  # noqa: F401 (re-exported)
from swarmloc.bench.evaluation.outcomes import (
    EvaluationFailed,
    Gathered,
    MethodRun,
    TaskOutcome,
    method_info,
    partial_path,
    suite_info,
    write_run,
)
from swarmloc.bench.evaluation.recorder import EpisodeRecorder, MetricsObserver
from swarmloc.bench.evaluation.results import METRIC_NAMES, Results
from swarmloc.bench.evaluation.suites import Suite, require_data
from swarmloc.bench.evaluation.traces import Trace, read_traces, traces_path, write_traces
from swarmloc.bench.scoring.bounds import episode_bounds
from swarmloc.envs.tasks.catalogue import get_spec
from swarmloc.envs.tasks.specs import TaskSpec
from swarmloc.envs.world.sim import validate_seeds

_Recorder = EpisodeRecorder  # former private name, kept for existing imports


# --------------------------------------------------------------------------- rollouts


def rollout(loaded: LoadedMethod, spec: TaskSpec, seeds: Sequence[int],
            trace: bool = False) -> tuple[list[dict[str, float | None]], Trace | None]:
    """Run one method on B episodes of one task (``episode.fly_episodes``) and score them.

    Args:
        loaded: the method (fresh instance; it is reset here).
        spec: the task (may carry overrides such as a shorter duration).
        seeds: ``(B,)`` episode seeds.
        trace: also return the per-step trace of the first seed.

    Returns:
        ``(metrics per seed, trace or None)``; ``uniform_rmse`` and ``bound_rmse`` are None here.
    """
    metrics = MetricsObserver(trace)
    fly_episodes(loaded, spec, seeds, [metrics])
    return metrics.episode_metrics(), metrics.make_trace()


# --------------------------------------------------------------------------- references and tasks

_REFERENCE_CACHE: dict[tuple[str, str, int], float] = {}


def _spec_key(spec: TaskSpec) -> str:
    return hashlib.sha256(spec.model_dump_json().encode()).hexdigest()


def reference_rmse(name: str, spec: TaskSpec, seeds: Sequence[int]) -> list[float]:
    """RMSE of the reference method (``uniform``) per seed, cached per process."""
    key = _spec_key(spec)
    missing = [int(s) for s in seeds if (name, key, int(s)) not in _REFERENCE_CACHE]
    if missing:
        metrics, _ = rollout(load_method(name, version=spec.version), spec, missing)
        for seed, m in zip(missing, metrics):
            _REFERENCE_CACHE[(name, key, seed)] = float(m["rmse"])  # type: ignore[arg-type]
    return [_REFERENCE_CACHE[(name, key, int(s))] for s in seeds]


def evaluate_task(methods: Sequence[str], task: str | TaskSpec, seeds: Sequence[int], *,
                  weights: Mapping[str, str | None] | None = None, trace: bool = False,
                  references: bool = True) -> TaskOutcome:
    """Evaluate methods on one task's seeds (one batch per method), the reference's RMSE included.

    Args:
        methods: method names or entry points (see ``load_method``).
        task: task ID or a spec (e.g. ``get_spec(id, duration=10)`` in tests).
        seeds: the episode seeds.
        weights: optional method → weights file.
        trace: keep the trace of the first seed of each method.
        references: run the reference here (cached per process) and fill in
            ``uniform_rmse``; False leaves it None for the caller (``evaluate_methods`` runs
            the reference once per task chunk, as a job of its own).

    Returns:
        The ``TaskOutcome``.
    """
    spec = get_spec(task) if isinstance(task, str) else task
    seeds = [int(s) for s in validate_seeds(list(seeds))]
    outcome = TaskOutcome(task=spec.task_id, seeds=seeds)
    weights = weights or {}
    for text in methods:
        loaded = load_method(text, weights.get(text), version=spec.version)
        pin_torch_threads()  # a pool worker's first torch method has just imported torch
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
        if text == REFERENCE_UNIFORM:
            key = _spec_key(spec)
            for seed, m in zip(seeds, metrics):
                _REFERENCE_CACHE[(text, key, seed)] = float(m["rmse"])  # type: ignore[arg-type]
    # the information bound on the same scored steps and UAVs as ``rmse`` (cached per task spec and seed)
    bounds = [b.rmse for b in episode_bounds(spec, seeds)]
    for metrics in outcome.episodes.values():
        for m, bound in zip(metrics, bounds):
            if m["rmse"] is not None:
                m["bound_rmse"] = bound
    if references:
        fill_reference(outcome.episodes.values(), reference_rmse(REFERENCE_UNIFORM, spec, seeds))
    return outcome


def fill_reference(episodes: Any, uniform: Sequence[float]) -> None:
    """Fill in ``uniform_rmse`` (the reference of the score, ``swarmloc.bench.scoring.score``) of metrics dicts.

    Args:
        episodes: per method, one metrics dict per seed (an iterable of lists), changed in place.
        uniform: the reference's RMSE per seed, in the same order.
    """
    for metrics in episodes:
        for m, u in zip(metrics, uniform, strict=True):
            if m["rmse"] is not None:
                m["uniform_rmse"] = u


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


# --------------------------------------------------------------------------- suites, on a backend



def _task_job(job: Job, weights: str | None) -> TaskOutcome:
    """The runner's job function (top level, so that workers unpickle it): one method on a chunk of seeds."""
    spec = get_spec(job.task, **(job.overrides or {}))
    return evaluate_task([job.method], spec, job.seeds, weights={job.method: weights}, trace=job.trace,
                         references=False)


def _task_cost(task: str, n_seeds: int) -> float:
    s = get_spec(task)
    return float(s.n_steps * s.n_uav * (s.n_channels + 4) * n_seeds)


def make_jobs(methods: Sequence[str], suite: Suite, seeds_per_job: int | None = None, trace: bool = True,
              overrides: Mapping[str, Any] | None = None) -> list[Job]:
    """The jobs of a suite evaluation: every method on every chunk of every task's seeds, costliest task first.

    A chunk is one batch. Most methods give the same numbers at any batch size; those
    that do not (torch's matrix kernels block differently by batch size, which moves
    ``mappo``'s metrics by ~1e-9) reproduce bit for bit only at the same chunking, so
    the default is one chunk per task, as a whole-task batch has always been.

    Args:
        methods: method names or entry points.
        suite: the suite.
        seeds_per_job: seeds per chunk, at least 1 (None: all of a task's seeds).
        trace: mark each task's first chunk to keep the trace of the task's first seed.
        overrides: task-spec overrides for every job (None: the registered tasks).

    Returns:
        The jobs, in the order to start them.
    """
    if seeds_per_job is not None and seeds_per_job < 1:
        raise ValueError(f"seeds_per_job must be at least 1 (or None: a task's seeds), got {seeds_per_job}")
    jobs = []
    for task in sorted(suite.tasks, key=lambda t: -_task_cost(t, len(suite.seeds(t)))):
        seeds = suite.seeds(task)
        size = seeds_per_job or len(seeds)
        for start in range(0, len(seeds), size):
            chunk = tuple(seeds[start:start + size])
            jobs += [Job(task, m, chunk, trace and start == 0, overrides) for m in methods]
    return jobs


def evaluate_methods(methods: Sequence[str], suite: Suite, *, workers: int = 1, backend: Backend | None = None,
                     address: str | None = None, seeds_per_job: int | None = None,
                     weights: Mapping[str, str | None] | None = None, trace: bool = True, progress: bool = True,
                     on_task: Callable[[TaskOutcome], None] | None = None,
                     overrides: Mapping[str, Any] | None = None) -> dict[str, MethodRun]:
    """Evaluate several methods on a suite: (method, task, seed-chunk) jobs on an execution backend.

    Every backend gives identical per-episode metrics (see ``backends``). A job that
    fails is reported (``MethodRun.failed``) and the other jobs go on.

    Args:
        methods: method names or entry points.
        suite: the suite.
        workers: worker processes (``process``) or CPUs of a local Ray cluster, in [1, 64].
        backend: ``serial``, ``process`` or ``ray``; default ``serial`` for one worker, else ``process``.
        address: Ray cluster to join, ``auto`` or ``HOST:PORT`` (``ray`` only; default: a local one).
        seeds_per_job: seeds per job, one batch each (None: a task's seeds; see ``make_jobs``).
        weights: optional method → weights file.
        trace: keep first-seed traces for plots.
        progress: show a progress bar (tqdm, on stderr).
        on_task: called with each task's outcome once all its jobs are done.
        overrides: task-spec overrides for every task (shortened episodes in tests; the
            results are then not the suite's).

    Returns:
        method → ``MethodRun``, episodes in suite order.
    """
    backend = check_backend(backend, workers, address)
    if not methods:
        raise ValueError("no method to evaluate")
    from tqdm.auto import tqdm

    weights = {m: (str(w) if w is not None else None) for m, w in (weights or {}).items()}
    loaded = {m: load_method(m, weights.get(m)) for m in methods}  # fail fast, before any work
    require_data(suite)  # a recorded task whose data is not imported here: say so before any work
    # one job per (method, task, seed chunk): the workers balance methods of very different
    # cost. The reference of the score runs once per chunk, as a job of its own (or as the
    # evaluated method itself), and is filled in here when a task's jobs are done
    extra = [r for r in (REFERENCE_UNIFORM,) if r not in methods]
    keys = {task: _spec_key(get_spec(task, **(overrides or {}))) for task in suite.tasks}
    jobs: list[Job] = []
    for job in make_jobs(methods, suite, seeds_per_job, trace, overrides):
        if job.method == methods[0]:  # a chunk's first job: the chunk's reference goes just before it
            jobs += [Job(job.task, ref, job.seeds, False, overrides) for ref in extra
                     if any((ref, keys[job.task], s) not in _REFERENCE_CACHE for s in job.seeds)]
        jobs.append(job)
    left = {task: sum(j.task == task for j in jobs) for task in suite.tasks}
    gathered = Gathered()
    label = methods[0] if len(methods) == 1 else f"{len(methods)} methods"
    bar = tqdm(total=len(jobs), desc=f"evaluating {label} on {suite.name} ({backend})", unit="job",
               disable=not progress)

    def finished(job: Job) -> None:
        left[job.task] -= 1
        bar.update(1)
        bar.set_postfix_str(job.task.removeprefix("swarmloc/"))
        if left[job.task] == 0:
            _score_task(gathered, job.task, suite.seeds(job.task), methods, keys[job.task])
            if on_task is not None:
                on_task(gathered.outcome(job.task, suite.seeds(job.task), methods))

    def on_result(job: Job, part: TaskOutcome) -> None:
        gathered.add(job, part)
        finished(job)

    def on_failure(failure: JobFailure) -> None:
        job = failure.job
        gathered.failed.setdefault((job.method, job.task), failure.error)
        bar.write(f"failed: {job.method} on {job.task} (seeds {job.seeds[0]}…{job.seeds[-1]}): {failure.error}")
        finished(job)

    try:
        run_jobs(_task_job, jobs, backend=backend, workers=workers, weights=weights, address=address,
                 on_result=on_result, on_failure=on_failure)
    finally:
        bar.close()
    return {m: gathered.run(m, loaded[m], suite, weights.get(m)) for m in methods}


def _score_task(gathered: Gathered, task: str, seeds: Sequence[int], methods: Sequence[str], key: str) -> None:
    """Fill in the reference's RMSE of a finished task's episodes; a failed reference fails the task for all.

    The reference comes from this evaluation's runs (kept in the process cache, for the next
    evaluation here) or, where it ran none, from that cache.
    """
    ref = REFERENCE_UNIFORM
    if (ref, task) in gathered.failed or (ref, task) in gathered.unsupported:
        why = gathered.failed.get((ref, task)) or gathered.unsupported[(ref, task)]
        for m in methods:
            gathered.failed.setdefault((m, task), f"the reference {ref} failed on this task: {why}")
        return
    for s in seeds:
        run = gathered.metrics.get((ref, task, s))
        if run is not None:
            _REFERENCE_CACHE[(ref, key, s)] = float(run["rmse"])  # type: ignore[arg-type]
    scored = [m for m in methods if (m, task) not in gathered.failed]
    fill_reference(([gathered.metrics[(m, task, s)] for s in seeds] for m in scored),
                   [_REFERENCE_CACHE[(ref, key, s)] for s in seeds])


def evaluate(method: str, suite: Suite, out: str | os.PathLike[str] | None = None, *, workers: int = 1,
             backend: Backend | None = None, address: str | None = None, seeds_per_job: int | None = None,
             weights: str | None = None, progress: bool = True, trace: bool = True) -> Results:
    """Evaluate one method on a suite and (optionally) write the results file.

    The file is written atomically once every job is done: an interrupted evaluation
    (Ctrl-C) leaves no results file, a failed one leaves only ``<stem>.partial.json``.

    Args:
        method: registered name or entry point.
        suite: the suite.
        out: results file to write atomically (traces go to ``<stem>.traces.npz`` beside it).
        workers: worker processes (or CPUs of a local Ray cluster).
        backend: ``serial``, ``process`` or ``ray`` (see ``evaluate_methods``).
        address: Ray cluster to join (``ray`` only).
        seeds_per_job: seeds per job (None: a task's seeds; see ``make_jobs``).
        weights: optional weights file.
        progress: show a progress bar.
        trace: keep first-seed traces (written only with ``out``).

    Returns:
        The validated ``Results``.

    Raises:
        EvaluationFailed: a job failed; the other tasks' results are in its ``partial``
            (and, with ``out``, written to ``partial_path(out)``).
    """
    run = evaluate_methods([method], suite, workers=workers, backend=backend, address=address,
                           seeds_per_job=seeds_per_job, weights={method: weights}, trace=trace,
                           progress=progress)[method]
    if run.failed:
        partial = run.partial_results(suite)
        written = None
        if out is not None and partial is not None:
            written = write_run(partial_path(out), partial, run.traces)
        raise EvaluationFailed(run.loaded.name, run.failed, partial, written)
    results = run.results(suite)
    if out is not None:
        write_run(out, results, run.traces)
    return results


__all__ = [
    "BACKENDS",
    "MAX_WORKERS",
    "EvaluationFailed",
    "Job",
    "MethodRun",
    "TaskOutcome",
    "Trace",
    "evaluate",
    "evaluate_methods",
    "evaluate_task",
    "make_jobs",
    "method_info",
    "partial_path",
    "read_traces",
    "reference_rmse",
    "rollout",
    "run_episodes",
    "suite_info",
    "traces_path",
    "write_traces",
]
