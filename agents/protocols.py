"""Method protocols: the two ways a method takes part (docs/architecture.md, Track A and B).

**Track A — link trust** (:class:`LinkTrustPolicy`). Each step the policy receives, for
all B episodes at once, the per-channel observation ``(B, N, L, F)`` built by
``swarmloc.envs.world.observation.build_observation`` plus the raw fields it is built from
(:class:`TrustInput`), and returns the raw trust ``α_raw`` ``(B, N, L)`` in [0, 1]. The
environment's CEKF applies it (``R = R0 / max(α, α_min)``; channels with ``α ≤ α_th``
are skipped). A policy declares ``flops_per_channel`` (its cost per present channel per
step, used by the delay and energy terms) and ``privileged``.

**Track B — estimator** (:class:`Estimator`). ``reset(facts, x0)`` with the task's
public facts (:class:`TaskFacts`), then ``step(meas)`` once per filter step with the
batched measurements (:class:`Measurements`) → :class:`EstimatorOutput` (positions,
optionally covariances, applied channel weights and FLOPs). Every link-trust policy is
also an estimator through ``swarmloc.agents.estimators.trust_estimator.TrustEstimator``.

**No truth, no labels.** :class:`TaskFacts`, :class:`Measurements` and
:class:`TrustInput` are frozen dataclasses with ``__slots__`` and no field for the true
state or the fault labels, so reading one (``meas.truth``) raises ``AttributeError``
and adding one is impossible; their arrays are read-only. The privileged oracle is the
only consumer of labels, and it receives them through a separate, explicit channel:
a method whose ``privileged`` attribute is True must implement
``observe_privileged(info: PrivilegedInfo)``, which the runner calls before each
``act``/``step``; for every other method the runner never builds a ``PrivilegedInfo``.
Results of privileged methods are shown apart and never ranked.

**Randomness.** A method that draws random numbers derives them from the per-episode
``keys`` it is given (``(B,)`` non-negative int64, one per episode, a one-way hash of
the episode seed) — e.g. with ``swarmloc.envs.tasks.rng.uniform(key, step, Stream.POLICY, i)``
— never from a global generator, so an episode gives the same result alone or batched.

Shapes: B episodes, N UAVs, L channels, F features; arrays are numpy, float64 unless
stated. Arrays handed to a method are valid for the current call only (the caller reuses
its buffers): copy what you keep.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from swarmloc.envs.tasks.channels import ChannelLayout
from swarmloc.envs.tasks.specs import TaskSpec


def _frozen_array(value: np.ndarray | float, dtype=None) -> np.ndarray:
    """A read-only array view (copying only when a dtype change is needed)."""
    arr = np.asarray(value, dtype=dtype)
    view = arr.view()
    view.flags.writeable = False
    return view


def episode_keys(seeds: np.ndarray | list[int]) -> np.ndarray:
    """Per-episode random keys of methods: a one-way hash of each episode seed.

    Methods get keys instead of seeds so that their random streams are decorrelated from
    the world's (which are keyed by the seed itself).

    Args:
        seeds: ``(B,)`` non-negative episode seeds.

    Returns:
        ``(B,)`` int64 keys in [0, 2**63).
    """
    out = np.empty(len(seeds), dtype=np.int64)
    for b, seed in enumerate(np.asarray(seeds).tolist()):
        digest = hashlib.sha256(f"swarmloc-method-key|{int(seed)}".encode()).digest()
        out[b] = int.from_bytes(digest[:8], "little") >> 1
    return out


# --------------------------------------------------------------------------- Track B data


@dataclass(frozen=True, slots=True)
class TaskFacts:
    """Public facts of a task that an estimator may use (no truth, no fault schedule).

    Attributes:
        task_id: registered ID, e.g. ``swarmloc/NLOS-v0``.
        dt: filter step [s].
        n_steps: filter steps per episode (T).
        duration: episode length [s] (= T·dt).
        n_uav: N.
        kind, target, linked, sigma: ``(N, L)`` static channel layout (see
            ``swarmloc.envs.tasks.channels``): kind id, anchor/UAV/landmark index, whether the
            topology links the slot, nominal noise std per scalar row [m].
        anchors: ``(A, 3)`` anchor positions [m]; landmarks: ``(M, 3)`` landmark positions.
        imu_sigma: nominal accelerometer noise std [m/s²].
        x0: ``(B, N, 6)`` initial prior mean [p, v].
        init_pos_sigma, init_vel_sigma: std of the initial prior [m], [m/s].
        alpha_th, alpha_min: the CEKF's activity threshold and trust floor.
        keys: ``(B,)`` per-episode random keys (see :func:`episode_keys`).
        velocity_sigma: nominal visual-odometry velocity std per axis [m/s], None when the
            task has no VO sensor (then ``Measurements.velocity`` is None).
        peer_nis_neighbour_cov: a peer channel's observed NIS includes the neighbour's
            broadcast covariance (``TaskSpec.peer_nis_neighbour_cov``: v1 tasks).
        imu_bias_sigma: std of the constant per-episode accelerometer bias the world draws per UAV
            and axis [m/s²] (``Sensors.imu_bias_sigma``; 0: none).
        imu_faults: the task injects IMU faults (``faults.imu_cascades`` or ``imu_cascade_random``);
            which UAVs and when is privileged (``PrivilegedInfo.imu_fault_variance``).
        peer_update: the task's CEKF peer update (``FilterSettings.peer_update``: ``"point"``,
            ``"ci"`` or ``"split_ci"``), for an estimator that runs the task's backbone.
    """

    task_id: str
    dt: float
    n_steps: int
    duration: float
    n_uav: int
    kind: np.ndarray
    target: np.ndarray
    linked: np.ndarray
    sigma: np.ndarray
    anchors: np.ndarray
    landmarks: np.ndarray
    imu_sigma: float
    x0: np.ndarray
    init_pos_sigma: float
    init_vel_sigma: float
    alpha_th: float
    alpha_min: float
    keys: np.ndarray
    velocity_sigma: float | None = None
    peer_nis_neighbour_cov: bool = False
    imu_bias_sigma: float = 0.0
    imu_faults: bool = False
    peer_update: str = "point"

    @property
    def batch_size(self) -> int:
        """B."""
        return int(self.x0.shape[0])

    @property
    def n_channels(self) -> int:
        """L."""
        return int(self.kind.shape[1])

    @property
    def layout(self) -> ChannelLayout:
        """The channel layout as a ``ChannelLayout``."""
        return ChannelLayout(kind=self.kind, target=self.target, linked=self.linked, sigma=self.sigma)

    @classmethod
    def from_spec(cls, spec: TaskSpec, layout: ChannelLayout, x0: np.ndarray, keys: np.ndarray,
                  anchors: np.ndarray | None = None) -> "TaskFacts":
        """Collect the public facts of ``spec`` for a batch of episodes.

        Args:
            spec: the task.
            layout: its channel layout.
            x0: ``(B, N, 6)`` initial prior means.
            keys: ``(B,)`` per-episode random keys.
            anchors: ``(A, 3)`` the world's anchor positions (pass ``world.anchors``: a
                recorded task's survey comes from its data folder and its spec holds
                placeholders); default: ``spec.anchors``.

        Returns:
            Frozen facts with read-only arrays.
        """
        x0 = np.array(x0, dtype=np.float64)
        if x0.ndim != 3 or x0.shape[1:] != (spec.n_uav, 6):
            raise ValueError(f"x0 must have shape (B, {spec.n_uav}, 6), got {x0.shape}")
        if np.shape(keys) != (x0.shape[0],):
            raise ValueError(f"keys must have shape ({x0.shape[0]},), got {np.shape(keys)}")
        spec_anchors = np.asarray(spec.anchors, dtype=float).reshape(-1, 3)
        anchors = spec_anchors if anchors is None else np.array(anchors, dtype=np.float64)
        if anchors.shape != spec_anchors.shape:
            raise ValueError(f"anchors must have shape {spec_anchors.shape} (one per anchor channel of "
                             f"{spec.task_id}), got {anchors.shape}")
        return cls(
            task_id=spec.task_id, dt=float(spec.dt), n_steps=spec.n_steps, duration=spec.n_steps * spec.dt,
            n_uav=spec.n_uav, kind=_frozen_array(layout.kind), target=_frozen_array(layout.target),
            linked=_frozen_array(layout.linked), sigma=_frozen_array(layout.sigma),
            anchors=_frozen_array(anchors),
            landmarks=_frozen_array(np.asarray(spec.landmarks, dtype=float).reshape(-1, 3)),
            imu_sigma=float(spec.sensors.imu_sigma), x0=_frozen_array(x0),
            init_pos_sigma=float(spec.filter.init_pos_sigma), init_vel_sigma=float(spec.filter.init_vel_sigma),
            alpha_th=float(spec.filter.alpha_th), alpha_min=float(spec.filter.alpha_min),
            keys=_frozen_array(np.array(keys, dtype=np.int64)),
            velocity_sigma=None if spec.sensors.velocity_sigma is None else float(spec.sensors.velocity_sigma),
            peer_nis_neighbour_cov=bool(spec.peer_nis_neighbour_cov), imu_bias_sigma=float(spec.sensors.imu_bias_sigma),
            imu_faults=bool(spec.faults.imu_cascades or spec.faults.imu_cascade_random is not None),
            peer_update=spec.filter.peer_update,
        )


@dataclass(frozen=True, slots=True)
class Measurements:
    """What every UAV senses in one filter step (all B episodes step in lockstep).

    Attributes:
        imu: ``(B, N, 3)`` accelerometer reading over the last interval [m/s²].
        z: ``(B, N, L, 3)`` channel measurements (ranges in component 0; landmark: the
            landmark relative to the UAV; GPS: the fix; relative position: the
            neighbour relative to the UAV).
        valid: ``(B, N, L)`` bool, measurement present.
        t: time of the step [s] (= step·dt).
        step: step index k, 1-based (the k-th filter step of the episode).
        velocity: ``(B, N, 3)`` visual-odometry velocity [m/s] (world frame), or None when
            the task has no VO sensor (``TaskFacts.velocity_sigma`` is None).
    """

    imu: np.ndarray
    z: np.ndarray
    valid: np.ndarray
    t: float
    step: int
    velocity: np.ndarray | None = None

    @classmethod
    def capture(cls, imu: np.ndarray, z: np.ndarray, valid: np.ndarray, t: float, step: int,
                velocity: np.ndarray | None = None) -> "Measurements":
        """Snapshot the given buffers into read-only copies (``velocity``: the world's VO buffer, if any)."""
        return cls(imu=_frozen_array(imu.copy()), z=_frozen_array(z.copy()), valid=_frozen_array(valid.copy()),
                   t=float(t), step=int(step),
                   velocity=None if velocity is None else _frozen_array(np.array(velocity, dtype=np.float64)))


@dataclass(frozen=True, slots=True)
class EstimatorOutput:
    """An estimator's answer for one step.

    Attributes:
        positions: ``(B, N, 3)`` position estimates [m] (required, finite).
        cov: optional ``(B, N, 3, 3)`` position covariances.
        weights: optional ``(B, N, L)`` trust the estimator applied to each channel, in
            [0, 1] (enables jitter, weight variance and anomaly-detection metrics).
        flops: optional ``(B, N)`` FLOPs spent per UAV this step (enables delay and energy).
    """

    positions: np.ndarray
    cov: np.ndarray | None = None
    weights: np.ndarray | None = None
    flops: np.ndarray | None = None


# --------------------------------------------------------------------------- Track A data


@dataclass(frozen=True, slots=True)
class TrustInput:
    """What a link-trust policy sees for the pending update of every episode.

    Attributes:
        obs: ``(B, N, L, F)`` float32 features in [0, 1] (``build_observation``).
        resid: ``(B, N, L)`` innovation magnitude ‖y‖ at the prior [m] (0 if absent).
        pred: ``(B, N, L)`` predicted distance to the channel's target [m].
        nis: ``(B, N, L)`` normalised innovation squared with the nominal R0 (v1 tasks: a
            peer channel's includes the neighbour's broadcast covariance, docs/world.md).
        applied: ``(B, N, L)`` trust applied at the previous update (1 after reset).
        jerk: ``(B, N)`` IMU jerk ‖u(k) − u(k−1)‖ [m/s²].
        valid: ``(B, N, L)`` bool, measurement present.
        t: time of the pending update [s].
        step: index k of the pending update, 1-based.
    """

    obs: np.ndarray
    resid: np.ndarray
    pred: np.ndarray
    nis: np.ndarray
    applied: np.ndarray
    jerk: np.ndarray
    valid: np.ndarray
    t: float
    step: int

    @classmethod
    def view(cls, obs: np.ndarray, resid: np.ndarray, pred: np.ndarray, nis: np.ndarray, applied: np.ndarray,
             jerk: np.ndarray, valid: np.ndarray, t: float, step: int) -> "TrustInput":
        """Wrap the caller's buffers in read-only views (no copy)."""
        f = _frozen_array
        return cls(obs=f(obs), resid=f(resid), pred=f(pred), nis=f(nis), applied=f(applied), jerk=f(jerk),
                   valid=f(valid), t=float(t), step=int(step))


@dataclass(frozen=True, slots=True)
class PrivilegedInfo:
    """Privileged information, handed only to methods marked ``privileged = True``.

    Attributes:
        labels: ``(B, N, L)`` bool injected-fault labels of the pending measurements (a fault
            the scenario injected: what the detection metrics count, ``SenseBuffers.label``).
        error_labels: ``(B, N, L)`` bool error labels (``swarmloc.envs.world.labels``: systematic
            error above k·σ_eff). Track A: the core's, peer links included through the
            neighbour's broadcast estimate; Track B: the world's, the measurement's own
            error only (an estimator's estimates are its own). None where not provided.
        systematic_sigmas: ``(B, N, L)`` the systematic error in units of σ_eff behind
            ``error_labels`` (Track A only; None otherwise), for oracles at another k.
        imu_fault_variance: ``(B, N)`` per UAV, σ_f² = ‖β‖²/3 of the IMU-fault bias β acting on
            the coming step's accelerometer reading, 0 outside a fault window
            (``envs.filter.bound.fault_variance``: what the information bound knows); Track B, on
            tasks with IMU faults; None otherwise.
    """

    labels: np.ndarray
    error_labels: np.ndarray | None = None
    systematic_sigmas: np.ndarray | None = None
    imu_fault_variance: np.ndarray | None = None


# --------------------------------------------------------------------------- protocols


@runtime_checkable
class LinkTrustPolicy(Protocol):
    """A Track A method: per-channel trust for the environment's CEKF.

    Attributes:
        privileged: True if the method reads fault labels (it then also implements
            ``observe_privileged(info: PrivilegedInfo) -> None``).
        flops_per_channel: FLOPs the policy spends per present channel per step.
    """

    privileged: bool
    flops_per_channel: float

    def reset(self, batch_size: int, layout: ChannelLayout, keys: np.ndarray) -> None:
        """Start B new episodes.

        Args:
            batch_size: B.
            layout: the task's static channel layout (kind, target, linked, sigma ``(N, L)``).
            keys: ``(B,)`` per-episode random keys (see the module docstring).
        """
        ...

    def act(self, inp: TrustInput) -> np.ndarray:
        """Raw trust for the pending update.

        Args:
            inp: features and raw fields of the pending update.

        Returns:
            ``(B, N, L)`` trust α in [0, 1] (finite; values outside are clipped by the CEKF).
        """
        ...


@runtime_checkable
class Estimator(Protocol):
    """A Track B method: a full estimator fed with measurements and public facts.

    Attributes:
        privileged: True if the method reads fault labels (it then also implements
            ``observe_privileged(info: PrivilegedInfo) -> None``).
    """

    privileged: bool

    def reset(self, facts: TaskFacts, x0: np.ndarray) -> None:
        """Start B new episodes.

        Args:
            facts: the task's public facts.
            x0: ``(B, N, 6)`` initial prior mean (the same array as ``facts.x0``).
        """
        ...

    def step(self, meas: Measurements) -> EstimatorOutput:
        """Process one step of measurements and return the estimates.

        Args:
            meas: the step's batched measurements.

        Returns:
            The step's ``EstimatorOutput``.
        """
        ...


class UnsupportedTask(ValueError):
    """A method cannot run a task at all (e.g. an IMM filter on a task without GPS).

    Raise it from ``reset`` (the runner also treats a ``ValueError`` or
    ``NotImplementedError`` raised by ``reset`` this way); the runner then records the
    task's episodes with null metrics and reports the reason, instead of aborting.
    """


def is_privileged(method: object) -> bool:
    """Whether ``method`` declares itself privileged (``privileged`` attribute, default False)."""
    return bool(getattr(method, "privileged", False))


def is_deterministic(method: object) -> bool:
    """Whether re-running an episode reproduces it exactly (``deterministic`` attribute, default True)."""
    return bool(getattr(method, "deterministic", True))


__all__ = [
    "Estimator",
    "EstimatorOutput",
    "LinkTrustPolicy",
    "Measurements",
    "PrivilegedInfo",
    "TaskFacts",
    "TrustInput",
    "UnsupportedTask",
    "episode_keys",
    "is_deterministic",
    "is_privileged",
]
