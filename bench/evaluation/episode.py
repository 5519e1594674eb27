"""The episode loop: one loaded method on B episodes of one task, observed at every step.

:func:`fly_episodes` steps a method's episodes for every part of the bench that runs
one (the runner, the explanations, the paper reproductions). A Track A policy flies
through ``TrustEnvBatch`` (the env every adapter wraps: observation, reward, FLOPs and
delay are the ones a Gymnasium user sees), a Track B estimator through the task's world.
Everything a method is held to happens here, once: a refusal in ``reset`` becomes
``UnsupportedTask``; only a privileged method gets the pending measurements' labels
(``observe_privileged``, before every ``act``/``step``); a trust is validated by the
env's checker (shape, finite, clipped to [0, 1]), an estimator's output by
``_check_output``.

What is done with the episodes belongs to the observers (:class:`StepObserver`): each
gets ``begin`` once with the batch (:class:`EpisodeBatch`) and ``observe`` after every
update with the one :class:`StepRecord` of that update. The metrics (``recorder.MetricsObserver``), the
explanations' recording (``swarmloc.bench.explain.episode``) and the paper reproductions'
per-step errors (``swarmloc.bench.reproduce``) are observers of this loop.

Shapes: B episodes, N UAVs, L channels, F features per channel.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

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
from swarmloc.agents.registry import LoadedMethod
from swarmloc.envs.adapters.trust_env import TrustEnvBatch
from swarmloc.envs.filter.bound import fault_variance
from swarmloc.envs.tasks.channels import ChannelLayout
from swarmloc.envs.tasks.specs import TaskSpec
from swarmloc.envs.world.reward import RewardTerms
from swarmloc.envs.world.sim import validate_seeds
from swarmloc.envs.world.worlds import make_world


@dataclass(frozen=True)
class EpisodeBatch:
    """The B episodes being flown, as observers see them once before the first update.

    Attributes:
        spec: the task (with any overrides).
        seeds: ``(B,)`` int64 episode seeds.
        layout: the task's channel layout.
        world: the world the episodes run in (Track A: the env core's); for the fault
            schedule, a recorded flight's recording, and a diagnosis that reads the truth.
        method: the method's name.
        track: ``"A"`` (a link-trust policy) or ``"B"`` (an estimator).
    """

    spec: TaskSpec
    seeds: np.ndarray
    layout: ChannelLayout
    world: Any
    method: str
    track: str

    @property
    def schedule(self) -> Any:
        """The world's fault schedule (None for a world without one, e.g. a recorded flight)."""
        return getattr(self.world, "schedule", None)


class StepRecord:
    """One update of every episode, as observers see it (one instance, refilled every step).

    The arrays are the loop's, the env's or the world's buffers: valid during ``observe``
    only; an observer that keeps one copies it.

    Attributes:
        k: the update's index, 0-based (the update at t = (k + 1)·dt).
        t: its time [s].
        estimate, truth: ``(B, N, 3)`` posterior position and true position [m].
        covariance: ``(B, N, 3, 3)`` the posterior position covariance the method holds (Track A:
            the env's filter; Track B: the estimator's ``cov``, None when it reports none).
        valid: ``(B, N, L)`` measurements present in the update.
        label: ``(B, N, L)`` their injected-fault labels (analysis only, never a method's).
        applied: ``(B, N, L)`` trust applied in the update (Track A: the env's; Track B: the
            estimator's weights clipped to [0, 1], or None when it reports none).
        previous: ``(B, N, L)`` trust applied in the update before (None with ``applied``).
        flops: ``(B, N)`` FLOPs of the step (None when an estimator reports none).
        terms: the reward terms as the env scored the update (Track A; None on Track B).
        method_s: wall time of the method's ``act``/``step`` call [s].
        features: Track A: the ``TrustInput`` the policy saw (obs, resid, pred, nis, applied,
            jerk, valid of the pending update), kept through the update only when an
            observer sets ``wants_features``; else None.
        trust: Track A: the trust the policy returned, validated (``(B, N, L)`` in [0, 1]).
        measurements: Track B: the ``Measurements`` the estimator was given.
        output: Track B: the ``EstimatorOutput`` it returned (checked, unclipped).
    """

    __slots__ = ("applied", "covariance", "estimate", "features", "flops", "k", "label", "measurements", "method_s",
                 "output", "previous", "t", "terms", "trust", "truth", "valid")

    def __init__(self) -> None:
        self.k, self.t, self.method_s = 0, 0.0, 0.0
        self.estimate = self.truth = self.valid = self.label = np.empty(0)
        self.covariance: np.ndarray | None = None
        self.applied: np.ndarray | None = None
        self.previous: np.ndarray | None = None
        self.flops: np.ndarray | None = None
        self.terms: RewardTerms | None = None
        self.features: TrustInput | None = None
        self.trust: np.ndarray | None = None
        self.measurements: Measurements | None = None
        self.output: EstimatorOutput | None = None


class StepObserver(Protocol):
    """What the loop calls: ``begin`` once, ``observe`` after every update.

    An observer may set ``wants_features = True`` to find a policy's features in
    ``StepRecord.features`` (the loop then keeps them through the update).
    """

    def begin(self, batch: EpisodeBatch) -> None:
        """The batch is about to fly (the method is reset; no update yet)."""

    def observe(self, record: StepRecord) -> None:
        """Update ``record.k`` of every episode is done."""


# --------------------------------------------------------------------------- validation


@contextlib.contextmanager
def single_threaded_kernels() -> Iterator[None]:
    """Run numba kernels on one thread inside the block (restored afterwards).

    The runner's batches are small (B = seeds per task): thread launches cost more than
    they save, and on a busy machine spinning threads slow everything down tenfold.
    Parallelism comes from worker processes instead (``backends.pin_torch_threads`` puts
    torch on one thread in a pool worker once a job has loaded it).
    """
    import numba

    previous = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(previous)


def _readonly(arr: np.ndarray) -> np.ndarray:
    view = arr.view()
    view.flags.writeable = False
    return view


def _reset_or_unsupported(loaded: LoadedMethod, spec: TaskSpec, reset: Callable[[], None]) -> None:
    """Call a method's reset; a refusal (ValueError / NotImplementedError) means "cannot run this task".

    Raises:
        UnsupportedTask: the method refused the task (its message names method and task).
    """
    try:
        reset()
    except UnsupportedTask:
        raise
    except (ValueError, NotImplementedError) as err:
        raise UnsupportedTask(f"{loaded.name} cannot run {spec.task_id}: {err}") from err


def _check_output(out: Any, name: str, shape: tuple[int, int, int]) -> EstimatorOutput:
    """An estimator's answer, checked: positions ``(B, N, 3)`` finite, weights ``(B, N, L)``, flops ``(B, N)``.

    Args:
        out: what ``step`` returned.
        name: the method's name (for messages).
        shape: ``(B, N, L)``.

    Returns:
        ``out`` unchanged.

    Raises:
        TypeError: not an ``EstimatorOutput``.
        ValueError: a wrong shape or a non-finite position (named with its index).
    """
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


# --------------------------------------------------------------------------- the loop


def fly_episodes(loaded: LoadedMethod, spec: TaskSpec, seeds: Sequence[int] | np.ndarray,
                 observers: Sequence[StepObserver]) -> EpisodeBatch:
    """Fly one method on B episodes of one task, calling every observer at every update.

    Numba kernels run on one thread (``single_threaded_kernels``).

    Args:
        loaded: the method (a fresh instance; it is reset here). Track A flies through
            ``TrustEnvBatch``, Track B through the task's world (``make_world``).
        spec: the task (may carry overrides such as a shorter duration).
        seeds: ``(B,)`` episode seeds.
        observers: called in order: ``begin`` once after the method's reset, ``observe``
            after each of the ``spec.n_steps`` updates.

    Returns:
        The batch the observers began with.

    Raises:
        UnsupportedTask: the method refused the task in ``reset``.
        TypeError, ValueError: the method answered out of contract (see ``_check_output``
            and ``TrustEnvBatch.check``).
    """
    seeds = validate_seeds(list(seeds))
    fly = _fly_policy if loaded.track == "A" else _fly_estimator
    with single_threaded_kernels():
        return fly(loaded, spec, seeds, observers)


def _fly_policy(loaded: LoadedMethod, spec: TaskSpec, seeds: np.ndarray,
                observers: Sequence[StepObserver]) -> EpisodeBatch:
    """Track A: the policy's trust steps ``TrustEnvBatch``."""
    policy = loaded.method
    n_b = len(seeds)
    env = TrustEnvBatch(spec, n_b, policy_flops_per_channel=float(getattr(policy, "flops_per_channel", 0.0)))
    cs = env.reset(seeds)
    layout = env.layout
    _reset_or_unsupported(loaded, spec, lambda: policy.reset(n_b, layout, episode_keys(seeds)))
    batch = EpisodeBatch(spec, seeds, layout, env.core.world, loaded.name, "A")
    for o in observers:
        o.begin(batch)
    # the env's feature buffers are the next update's once it has stepped: an observer that reads what the
    # policy saw gets a copy, taken before the policy acts (and the policy sees that copy)
    keep = any(getattr(o, "wants_features", False) for o in observers)
    kept = tuple(np.zeros_like(a) for a in (cs.resid, cs.pred, cs.nis, cs.applied, cs.jerk, cs.valid)) if keep else ()
    rec = StepRecord()
    obs = None
    for k in range(spec.n_steps):
        obs = env.observation(out=obs)
        t = (k + 1) * spec.dt
        if keep:
            for dst, src in zip(kept, (cs.resid, cs.pred, cs.nis, cs.applied, cs.jerk, cs.valid)):
                np.copyto(dst, src)
            inp = TrustInput.view(obs, *kept, t, k + 1)
        else:
            inp = TrustInput.view(obs, cs.resid, cs.pred, cs.nis, cs.applied, cs.jerk, cs.valid, t, k + 1)
        if loaded.privileged:
            policy.observe_privileged(PrivilegedInfo(
                labels=_readonly(env.pending_labels().copy()),
                error_labels=_readonly(env.pending_error_labels().copy()),
                systematic_sigmas=_readonly(env.pending_systematic_sigmas().copy())))
        started = time.perf_counter()
        alpha = policy.act(inp)
        rec.method_s = time.perf_counter() - started
        trust = env.check(alpha)
        cs, terms = env.step(trust)
        rec.k, rec.t, rec.features, rec.trust = k, t, inp if keep else None, trust
        rec.estimate, rec.truth, rec.valid, rec.label = cs.estimate, cs.truth, cs.update_valid, cs.label
        rec.covariance = env.core.P[..., :3, :3]
        rec.applied, rec.previous, rec.flops, rec.terms = cs.applied, cs.prev_trust, terms.flops, terms
        for o in observers:
            o.observe(rec)
    return batch


def _fly_estimator(loaded: LoadedMethod, spec: TaskSpec, seeds: np.ndarray,
                   observers: Sequence[StepObserver]) -> EpisodeBatch:
    """Track B: the estimator steps on the world's measurements."""
    est = loaded.method
    n_b = len(seeds)
    world = make_world(spec, n_b)
    x0 = world.reset(seeds).copy()
    facts = TaskFacts.from_spec(spec, world.layout, x0, episode_keys(seeds), anchors=world.anchors)
    _reset_or_unsupported(loaded, spec, lambda: est.reset(facts, facts.x0))
    batch = EpisodeBatch(spec, seeds, world.layout, world, loaded.name, "B")
    for o in observers:
        o.begin(batch)
    shape = (n_b, spec.n_uav, world.layout.n_channels)
    rec = StepRecord()
    previous: np.ndarray | None = None
    # the IMU-fault windows as the information bound knows them (privileged: which UAV, when, how large)
    fault = None
    if loaded.privileged and facts.imu_faults and getattr(world, "schedule", None) is not None:
        fault = fault_variance(world.schedule, spec.dt, spec.n_steps, spec.n_uav)
    for k in range(spec.n_steps):
        buf = world.sense()
        t = (k + 1) * spec.dt
        meas = Measurements.capture(buf.imu, buf.z, buf.valid, t, k + 1, getattr(buf, "velocity", None))
        if loaded.privileged:
            est.observe_privileged(PrivilegedInfo(labels=_readonly(buf.label.copy()),
                                                  error_labels=_readonly(buf.error_label.copy()),
                                                  imu_fault_variance=None if fault is None else _readonly(fault[k])))
        started = time.perf_counter()
        answer = est.step(meas)
        rec.method_s = time.perf_counter() - started
        out = _check_output(answer, loaded.name, shape)
        weights = None if out.weights is None else np.clip(np.asarray(out.weights, dtype=np.float64), 0.0, 1.0)
        if weights is not None and previous is None:
            previous = np.ones(shape)
        rec.k, rec.t, rec.measurements, rec.output = k, t, meas, out
        rec.estimate, rec.truth, rec.valid, rec.label = np.asarray(out.positions, dtype=np.float64), buf.pos, \
            buf.valid, buf.label
        rec.covariance = None if out.cov is None else np.asarray(out.cov, dtype=np.float64)
        rec.applied, rec.previous = weights, previous
        rec.flops = None if out.flops is None else np.asarray(out.flops, dtype=np.float64)
        for o in observers:
            o.observe(rec)
        previous = weights
    return batch


__all__ = ["EpisodeBatch", "StepObserver", "StepRecord", "fly_episodes", "single_threaded_kernels"]
