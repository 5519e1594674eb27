"""The batched world: truth, sensors and faults for B episodes of one task.

``World.reset(seeds)`` starts B episodes; ``World.sense(k)`` advances them to step k
(time ``k·dt``) and fills the step buffers: truth, the IMU reading that drives the
prediction from step k−1 to k, every channel's measurement, its validity mask, the
ground-truth fault labels (v0, and v1 of the measurement's own error: ``labels.py``), the
injected error and the signed systematic error. The world holds no filter: the CEKF
backbone (Track A) or a method's own estimator (Track B) consumes what it senses.

Batch layout: ``(B, N, ...)``; channel buffers ``(B, N, L, ...)``; measurements are
3-vectors with scalar ranges in component 0.
"""

from __future__ import annotations

import math

from dataclasses import dataclass

import numpy as np

from swarmloc.envs.tasks.channels import ChannelLayout, build_layout
from swarmloc.envs.world.faults import FaultSchedule, build_schedule
from swarmloc.envs.world.labels import label_thresholds
from swarmloc.envs.tasks.specs import TaskSpec
from swarmloc.envs.world.trajectories import N_PARAMS, trajectory_kind, trajectory_params
from swarmloc.envs.world.sim_kernel import WorldInputs, reset_episodes, sense_kernel


def validate_seeds(seeds: np.ndarray | list[int]) -> np.ndarray:
    """Check episode seeds: a 1-D array of integers in [0, 2**63)."""
    arr = np.asarray(seeds)
    if arr.ndim != 1 or arr.size == 0:
        raise ValueError(f"seeds must be a non-empty 1-D sequence, got shape {arr.shape}")
    if not np.issubdtype(arr.dtype, np.integer):
        raise TypeError(f"seeds must be integers, got dtype {arr.dtype}")
    if (arr < 0).any():
        raise ValueError(f"seeds must be >= 0, got {arr[arr < 0][:3].tolist()}")
    return arr.astype(np.int64)


def reset_indices(seeds: np.ndarray | list[int], mask: np.ndarray | None,
                  batch_size: int) -> tuple[np.ndarray, np.ndarray]:
    """Validate a (partial) reset request; returns the seeds and the episode indices to reset.

    Args:
        seeds: ``(B,)`` episode seeds.
        mask: optional ``(B,)`` bool of the episodes to reset (None: all).
        batch_size: B.
    """
    seeds = validate_seeds(seeds)
    if seeds.shape[0] != batch_size:
        raise ValueError(f"expected {batch_size} seeds, got {seeds.shape[0]}")
    if mask is None:
        return seeds, np.arange(batch_size)
    mask = np.asarray(mask, dtype=bool)
    if mask.shape != (batch_size,):
        raise ValueError(f"mask must have shape ({batch_size},), got {mask.shape}")
    return seeds, np.nonzero(mask)[0]


@dataclass
class SenseBuffers:
    """Step buffers the world fills (views are reused between steps).

    Attributes:
        pos, vel: ``(B, N, 3)`` truth at the current step.
        imu: ``(B, N, 3)`` accelerometer reading for the last interval [m/s²].
        z: ``(B, N, L, 3)`` measurements (ranges in component 0).
        valid: ``(B, N, L)`` measurement present.
        label: ``(B, N, L)`` injected-fault label: the channel carries a fault the scenario
            injected (a range error above ``sim_kernel.INJECTED_FAULT_SIGMAS`` nominal σ, a
            drifting GPS fix, a peer link to an IMU-faulty neighbour); what the detection
            metrics count (``anomaly_detection_rate``, ``fault_rmse`` without a fault window).
        injected: ``(B, N, L)`` magnitude of the injected (non-noise) error [m].
        error_label: ``(B, N, L)`` error label of the measurement's own systematic error
            (``labels.py``; the link-trust core adds the neighbour-estimate part of peer links).
        systematic: ``(B, N, L, 3)`` signed systematic error: range bias in component 0, GPS
            drift + heavy-tail excess per axis, zeros for landmarks and relative positions [m].
        velocity: ``(B, N, 3)`` visual-odometry velocity [m/s] (world frame, per-axis noise
            ``sensors.velocity_sigma`` plus a constant per-episode bias); None when the task
            has no VO sensor.
    """

    pos: np.ndarray
    vel: np.ndarray
    imu: np.ndarray
    z: np.ndarray
    valid: np.ndarray
    label: np.ndarray
    injected: np.ndarray
    error_label: np.ndarray
    systematic: np.ndarray
    velocity: np.ndarray | None = None


class World:
    """Truth, sensors and faults of B episodes of one task (no estimator).

    The arrays live in ``inputs`` (a ``WorldInputs``) and ``schedule`` (a ``FaultSchedule``),
    the world kernel's two arguments; ``buffers`` and the attributes below are views of them.

    Args:
        spec: the task.
        batch_size: B, the number of episodes simulated side by side.
    """

    def __init__(self, spec: TaskSpec, batch_size: int):
        if batch_size < 1:
            raise ValueError(f"batch_size must be >= 1, got {batch_size}")
        if spec.trajectory.kind == "recorded":
            raise ValueError(f"{spec.task_id} replays a recorded flight, it is not simulated; build its world "
                             "with swarmloc.envs.make_world(spec, batch_size)")
        self.spec = spec
        self.batch_size = batch_size
        self.layout: ChannelLayout = build_layout(spec)
        #: ``(N, L)`` error-label threshold per channel (``labels.label_thresholds``)
        self.label_threshold = label_thresholds(self.layout.kind)
        self.anchors = np.asarray(spec.anchors, dtype=float).reshape(-1, 3)
        self.landmarks = np.asarray(spec.landmarks, dtype=float).reshape(-1, 3)
        n_b, n, n_l = batch_size, spec.n_uav, self.layout.n_channels
        self.seeds = np.zeros(n_b, dtype=np.int64)
        self.steps = np.zeros(n_b, dtype=np.int64)
        #: the episodes' fault windows; updated in place by ``reset``
        self.schedule: FaultSchedule = build_schedule(spec, self.layout, self.seeds)
        self.x0 = np.zeros((n_b, n, 6))
        s, lay = spec.sensors, self.layout
        per_uav = lambda: np.zeros((n_b, n, 3))  # noqa: E731
        per_channel = lambda dtype=np.float64: np.zeros((n_b, n, n_l), dtype=dtype)  # noqa: E731
        self.inputs = WorldInputs(
            dt=float(spec.dt), traj_kind=trajectory_kind(spec),
            traj_prm=np.ascontiguousarray(trajectory_params(spec)).reshape(n, N_PARAMS),
            anchors=self.anchors, landmarks=self.landmarks, kind=lay.kind, target=lay.target, linked=lay.linked,
            sigma=lay.sigma, imu_sigma=float(s.imu_sigma), camera_range=float(s.camera_max_range),
            camera_fov_cos=math.cos(math.radians(s.camera_fov_deg) / 2.0),
            peer_range=float(s.peers.max_range), anchor_range=float(s.anchor_max_range),
            has_velocity=s.velocity_sigma is not None,
            velocity_sigma=float(s.velocity_sigma or 0.0), gps_tau=float(s.gps_correlation_time),
            label_threshold=self.label_threshold, seeds=self.seeds, steps=self.steps,
            imu_const_bias=per_uav(), velocity_bias=per_uav(), gm_bias=per_channel(), gm_left=per_channel(),
            gps_error=per_uav(),
            pos=per_uav(), vel=per_uav(), acc=per_uav(), imu=per_uav(), z=np.zeros((n_b, n, n_l, 3)),
            valid=per_channel(np.bool_), label=per_channel(np.bool_), injected=per_channel(),
            systematic=np.zeros((n_b, n, n_l, 3)), error_label=per_channel(np.bool_), velocity=per_uav(),
        )
        w = self.inputs
        self.buffers = SenseBuffers(pos=w.pos, vel=w.vel, imu=w.imu, z=w.z, valid=w.valid, label=w.label,
                                    injected=w.injected, error_label=w.error_label, systematic=w.systematic,
                                    velocity=w.velocity if w.has_velocity else None)
        self._everyone = np.ones(n_b, dtype=np.bool_)
        self._sense = sense_kernel(n_b)

    @property
    def imu_const_bias(self) -> np.ndarray:
        """``(B, N, 3)`` constant accelerometer bias of each episode [m/s²]."""
        return self.inputs.imu_const_bias

    @property
    def velocity_bias(self) -> np.ndarray:
        """``(B, N, 3)`` constant visual-odometry bias of each episode [m/s] (zeros without the sensor)."""
        return self.inputs.velocity_bias

    @property
    def times(self) -> np.ndarray:
        """``(B,)`` current time of each episode [s]."""
        return self.steps * self.spec.dt

    def reset(self, seeds: np.ndarray | list[int], mask: np.ndarray | None = None) -> np.ndarray:
        """Start episodes; returns the initial prior means ``(B, N, 6)`` [p, v].

        Args:
            seeds: ``(B,)`` episode seeds (entries outside ``mask`` are ignored).
            mask: optional ``(B,)`` bool: reset only these episodes (partial reset); the
                others keep running untouched.

        The truth buffers hold step 0 of the reset episodes; their prior mean is the truth
        perturbed by the task's stated initial uncertainty (``spec.filter.init_*_sigma``).
        """
        seeds, idx = reset_indices(seeds, mask, self.batch_size)
        if idx.size == 0:
            return self.x0
        self.seeds[idx] = seeds[idx]
        self.schedule.assign(idx, build_schedule(self.spec, self.layout, self.seeds[idx]))
        s, f = self.spec.sensors, self.spec.filter
        reset_episodes(self.inputs, idx, s.imu_bias_sigma, s.velocity_bias_sigma, f.init_pos_sigma,
                       f.init_vel_sigma, self.x0)
        return self.x0

    def sense(self) -> SenseBuffers:
        """Advance every episode by one step and fill the step buffers."""
        self._sense(self.inputs, self.schedule, self._everyone)
        return self.buffers
