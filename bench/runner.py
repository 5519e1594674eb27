"""The evaluation runner: methods × suite → per-episode metrics → a results file.

One task's seeds run as one batch (a ``LinkTrustCore`` for Track A, a ``World`` for
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
import tempfile
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
from swarmloc.bench import metrics as M
from swarmloc.bench.alignment import align_estimates
from swarmloc.bench.results import METRIC_NAMES, MethodInfo, Results, SuiteInfo, make_results, write_results
from swarmloc.bench.suites import Suite, require_data
from swarmloc.envs.core import LinkTrustCore
from swarmloc.envs.observation import build_observation, kind_one_hot
from swarmloc.envs.reward import standard_reward
from swarmloc.envs.specs import TaskSpec
from swarmloc.envs.tasks import get_spec
from swarmloc.envs.world import World, validate_seeds

MAX_WORKERS = 64


def make_world(spec: TaskSpec, batch_size: int) -> Any:
    """The task's world: ``swarmloc.envs.worlds.make_world`` (simulated or recorded) where available."""
    try:
        from swarmloc.envs.worlds import make_world as _make_world
    except ImportError:  # an envs without recorded worlds: every world is simulated
        return World(spec, batch_size)
    return _make_world(spec, batch_size)


# --------------------------------------------------------------------------- traces


@dataclass
class Trace:
    """Per-step record of one episode, for plots (the first seed of each task).

    Attributes:
        method, task, seed: what ran.
        times: ``(T,)`` update times [s].
        estimate, truth: ``(T, N, 3)`` positions [m].
        applied: ``(T, N, L)`` applied trust, or None (estimator without weights).
        valid, label: ``(T, N, L)`` bool.
        kind: ``(N, L)`` channel kinds.
        scored: ``(N,)`` bool, scored UAVs.
        fault_window: ``(2,)`` the task's fault window (NaN if none).
    """

    method: str
    task: str
    seed: int
    times: np.ndarray
    estimate: np.ndarray
    truth: np.ndarray
    applied: np.ndarray | None
    valid: np.ndarray
    label: np.ndarray
    kind: np.ndarray
    scored: np.ndarray
    fault_window: np.ndarray

    _ARRAYS = ("times", "estimate", "truth", "applied", "valid", "label", "kind", "scored", "fault_window")

    @property
    def errors(self) -> np.ndarray:
        """``(T, N)`` position errors [m]."""
        return M.position_errors(self.estimate, self.truth)

    def to_arrays(self) -> dict[str, np.ndarray]:
        """Flat ``{"<task>|<field>": array}`` for ``np.savez``."""
        out = {f"{self.task}|{name}": getattr(self, name) for name in self._ARRAYS if getattr(self, name) is not None}
        out[f"{self.task}|meta"] = np.array([self.method, str(self.seed)])
        return out

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, np.ndarray]) -> list["Trace"]:
        """Inverse of :meth:`to_arrays` over every task in ``arrays``."""
        tasks = sorted({key.split("|", 1)[0] for key in arrays})
        traces = []
        for task in tasks:
            meta = arrays[f"{task}|meta"]
            fields = {name: arrays.get(f"{task}|{name}") for name in cls._ARRAYS}
            traces.append(cls(method=str(meta[0]), task=task, seed=int(meta[1]), **fields))
        return traces


def traces_path(results_path: str | os.PathLike[str]) -> Path:
    """Where the traces of a results file live: ``<results stem>.traces.npz`` beside it."""
    path = Path(results_path)
    return path.with_name(f"{path.stem}.traces.npz")


def write_traces(path: str | os.PathLike[str], traces: Sequence[Trace]) -> Path:
    """Write traces atomically (temporary file + ``os.replace``)."""
    target = Path(path)
    arrays: dict[str, np.ndarray] = {}
    for tr in traces:
        arrays.update(tr.to_arrays())
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    try:
        umask = os.umask(0)  # mkstemp creates 0600; use what a plain open() would
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        with os.fdopen(fd, "wb") as handle:
            np.savez_compressed(handle, **arrays)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return target


def read_traces(path: str | os.PathLike[str]) -> list[Trace]:
    """Read traces written by :func:`write_traces`."""
    with np.load(path, allow_pickle=False) as data:
        return Trace.from_arrays({key: data[key] for key in data.files})


# --------------------------------------------------------------------------- per-episode recording


class _Recorder:
    """Collects what the metrics need while B episodes of one task run.

    Args:
        spec: the task; seeds: ``(B,)``; schedule: the world's fault schedule (None for a
            world without one, e.g. a recorded flight).
        with_trust: the method exposes the trust it applied.
        with_flops: the method reports FLOPs.
        trace: keep a per-step record of episode 0.
    """

    def __init__(self, spec: TaskSpec, seeds: np.ndarray, schedule: Any, n_channels: int,
                 with_trust: bool, with_flops: bool, trace: bool) -> None:
        n_t, n_b, n = spec.n_steps, len(seeds), spec.n_uav
        self.spec, self.seeds, self.schedule = spec, seeds, schedule
        self.times = spec.dt * np.arange(1, n_t + 1)
        self.scored_steps = self.times >= spec.scoring.start - 1e-9
        self.nodes = np.zeros(n, dtype=bool)
        self.nodes[list(spec.scored_nodes)] = True
        self.errors = np.zeros((n_t, n_b, n))
        # anchor-free tasks are scored after a yaw + translation alignment (bench/alignment.py),
        # which needs the whole episode: keep the positions and align once at the end
        self.align = spec.scoring.align_first_seconds > 0
        self._positions = (np.zeros((n_t, n_b, n, 3)), np.zeros((n_t, n_b, n, 3))) if self.align else None
        self.team = np.zeros((n_t, n_b))
        self.delay_ms = np.zeros(n_b)
        self.energy_j = np.zeros(n_b)
        self.label_steps = np.zeros((n_t, n_b), dtype=bool)
        self.with_trust, self.with_flops = with_trust, with_flops
        self.stats = M.ChannelStats(n_b, self.nodes) if with_trust else None
        self.trace = None
        if trace:
            self.trace = {"estimate": np.zeros((n_t, n, 3)), "truth": np.zeros((n_t, n, 3)),
                          "applied": np.ones((n_t, n, n_channels), dtype=np.float32) if with_trust else None,
                          "valid": np.zeros((n_t, n, n_channels), dtype=bool),
                          "label": np.zeros((n_t, n, n_channels), dtype=bool)}

    def record(self, k: int, estimate: np.ndarray, truth: np.ndarray, valid: np.ndarray, label: np.ndarray,
               applied: np.ndarray | None, previous: np.ndarray | None, flops: np.ndarray | None) -> None:
        """Record update k (0-based) of every episode (``(B, N, ...)`` arrays)."""
        s = self.spec
        self.errors[k] = M.position_errors(estimate, truth)
        if self._positions is not None:
            self._positions[0][k], self._positions[1][k] = estimate, truth
        self.label_steps[k] = label[:, self.nodes].any(axis=(1, 2))
        # the reward counts every valid channel as used when the method exposes no trust
        a = applied if applied is not None else np.ones(valid.shape)
        p = previous if previous is not None else a
        terms = standard_reward(estimate, truth, a, p, valid, s.filter.alpha_th,
                                flops if flops is not None else np.zeros(estimate.shape[:2]))
        self.team[k] = terms.reward.mean(axis=1)
        if self.scored_steps[k]:
            if flops is not None:
                self.delay_ms += terms.delay_ms[:, self.nodes].mean(axis=1)
                self.energy_j += terms.energy_j[:, self.nodes].mean(axis=1)
            if self.stats is not None and applied is not None and previous is not None:
                self.stats.add(applied, previous, valid, label)
        if self.trace is not None:
            tr = self.trace
            tr["estimate"][k], tr["truth"][k] = estimate[0], truth[0]
            tr["valid"][k], tr["label"][k] = valid[0], label[0]
            if tr["applied"] is not None and applied is not None:
                tr["applied"][k] = applied[0]

    def _healthy(self, b: int) -> tuple[np.ndarray, np.ndarray] | None:
        """Healthy UAVs and the steps they are scored on, or None where undefined."""
        s, steps_ok = self.spec, self.scored_steps
        sched = self.schedule
        if s.scoring.healthy_nodes:
            healthy = np.zeros(s.n_uav, dtype=bool)
            healthy[list(s.scoring.healthy_nodes)] = True
            if s.scoring.fault_window is not None:
                return healthy, M.window_steps(self.times, s.scoring.fault_window) & steps_ok
            span = sched.imu_fault_span()[b] if sched is not None else np.full(2, np.nan)
            window = None if np.isnan(span).any() else (float(span[0]), float(span[1]))
            return healthy, (M.window_steps(self.times, window) if window else steps_ok) & steps_ok
        if s.faults.imu_cascade_random is not None and sched is not None:
            healthy = ~sched.faulty_nodes[b]
            span = sched.imu_fault_span()[b]
            return healthy, M.window_steps(self.times, (float(span[0]), float(span[1]))) & steps_ok
        return None

    def _apply_alignment(self) -> None:
        """Replace the errors by those after the task's scoring alignment (once, at the end)."""
        if self._positions is not None:
            estimate, truth = self._positions
            self.errors = M.position_errors(align_estimates(self.spec, self.times, estimate, truth), truth)
            self._positions = None

    def episode_metrics(self, b: int) -> dict[str, float | None]:
        """Every metric of episode b except ``normalized_score`` (None here)."""
        self._apply_alignment()
        s = self.spec
        steps = self.scored_steps
        e = self.errors[steps][:, b][:, self.nodes]
        if s.scoring.fault_window is not None:
            fault_steps = M.window_steps(self.times, s.scoring.fault_window)[steps]
        else:
            fault_steps = self.label_steps[steps, b]
        healthy = self._healthy(b)
        n_scored = max(int(steps.sum()), 1)
        out: dict[str, float | None] = {
            "rmse": M.rmse(e),
            "mean_error": M.mean_error(e),
            "median_error": M.median_error(e),
            "max_error": M.max_error(e),
            "cep90": M.cep90(e),
            "fault_rmse": M.fault_rmse(e, fault_steps),
            "healthy_rmse": None if healthy is None else M.healthy_rmse(self.errors[:, b], *healthy),
            "diverged": M.diverged(e),
            "delay_ms": float(self.delay_ms[b] / n_scored) if self.with_flops else None,
            "energy_j": float(self.energy_j[b]) if self.with_flops else None,
            "jitter": self.stats.jitter(b) if self.stats is not None else None,
            "weight_var": self.stats.weight_var(b) if self.stats is not None else None,
            "anomaly_detection_rate": self.stats.anomaly_detection_rate(b) if self.stats is not None else None,
            "team_return": M.team_return(self.team[:, b]),
            "normalized_score": None,
        }
        return out

    def make_trace(self, method: str, layout_kind: np.ndarray) -> Trace | None:
        """The trace of episode 0 (None if not kept)."""
        if self.trace is None:
            return None
        window = self.spec.scoring.fault_window
        if window is None and self.spec.faults.imu_cascade_random is not None and self.schedule is not None:
            window = tuple(self.schedule.imu_fault_span()[0])
        return Trace(method=method, task=self.spec.task_id, seed=int(self.seeds[0]), times=self.times.copy(),
                     kind=np.asarray(layout_kind), scored=self.nodes.copy(),
                     fault_window=np.array(window if window is not None else (np.nan, np.nan), dtype=float),
                     **self.trace)


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


def _rollout_policy(loaded: LoadedMethod, spec: TaskSpec, seeds: np.ndarray, trace: bool) -> tuple[_Recorder, Any]:
    """Run a Track A policy on B episodes through ``LinkTrustCore``."""
    policy = loaded.method
    n_b = len(seeds)
    core = LinkTrustCore(spec, n_b)
    cs = core.reset(seeds)
    layout = core.layout
    _reset_or_unsupported(loaded, spec, lambda: policy.reset(n_b, layout, episode_keys(seeds)))
    one_hot = kind_one_hot(layout.kind)
    obs = None
    fpc = float(getattr(policy, "flops_per_channel", 0.0))
    rec = _Recorder(spec, seeds, getattr(core.world, "schedule", None), layout.n_channels, True, True, trace)
    for k in range(spec.n_steps):
        obs = build_observation(cs, one_hot, out=obs)
        inp = TrustInput.view(obs, cs.resid, cs.pred, cs.nis, cs.applied, cs.jerk, cs.valid,
                              (k + 1) * spec.dt, k + 1)
        if loaded.privileged:
            policy.observe_privileged(PrivilegedInfo(labels=_readonly(core.world.buffers.label.copy())))
        alpha = policy.act(inp)
        valid = cs.valid.copy()
        cs = core.step(alpha)
        flops = cs.flops + fpc * valid.sum(axis=-1)
        rec.record(k, cs.estimate, cs.truth, valid, cs.label, cs.applied, cs.prev_trust, flops)
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
                       trace: bool) -> tuple[_Recorder, Any]:
    """Run a Track B estimator on B episodes through ``World``."""
    est = loaded.method
    n_b = len(seeds)
    world = make_world(spec, n_b)
    x0 = world.reset(seeds).copy()
    facts = TaskFacts.from_spec(spec, world.layout, x0, episode_keys(seeds), anchors=world.anchors)
    _reset_or_unsupported(loaded, spec, lambda: est.reset(facts, facts.x0))
    shape = (n_b, spec.n_uav, world.layout.n_channels)
    rec: _Recorder | None = None
    previous: np.ndarray | None = None
    for k in range(spec.n_steps):
        buf = world.sense()
        meas = Measurements.capture(buf.imu, buf.z, buf.valid, (k + 1) * spec.dt, k + 1,
                                    getattr(buf, "velocity", None))
        if loaded.privileged:
            est.observe_privileged(PrivilegedInfo(labels=_readonly(buf.label.copy())))
        out = _check_output(est.step(meas), loaded.name, shape)
        if rec is None:
            rec = _Recorder(spec, seeds, getattr(world, "schedule", None), shape[2], out.weights is not None, out.flops is not None,
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
    """Top-level (picklable) job: one task, every method."""
    return evaluate_task(methods, task, seeds, weights=weights, trace=trace)


def _task_cost(task: str, n_seeds: int) -> float:
    s = get_spec(task)
    return float(s.n_steps * s.n_uav * (s.n_channels + 4) * n_seeds)


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
    """Evaluate several methods on a suite, tasks in parallel.

    Args:
        methods: method names or entry points.
        suite: the suite.
        workers: worker processes (1 = run here, no pool), in [1, 64].
        weights: optional method → weights file.
        trace: keep first-seed traces for plots.
        progress: show a progress bar (tqdm, on stderr).
        on_task: called with each finished task's outcome.

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
    jobs = sorted(suite.tasks, key=lambda t: -_task_cost(t, len(suite.seeds(t))))
    outcomes: dict[str, TaskOutcome] = {}
    label = methods[0] if len(methods) == 1 else f"{len(methods)} methods"
    bar = tqdm(total=len(jobs), desc=f"evaluating {label} on {suite.name}", unit="task", disable=not progress)

    def done(outcome: TaskOutcome) -> None:
        outcomes[outcome.task] = outcome
        bar.update(1)
        bar.set_postfix_str(outcome.task.removeprefix("swarmloc/"))
        if on_task is not None:
            on_task(outcome)

    try:
        if workers == 1:
            for task in jobs:
                done(_task_job(list(methods), task, suite.seeds(task), weights, trace))
        else:
            ctx = multiprocessing.get_context("spawn")
            with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_worker_init) as pool:
                futures = [pool.submit(_task_job, list(methods), task, suite.seeds(task), weights, trace)
                           for task in jobs]
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
