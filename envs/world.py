"""The batched world: truth, sensors and faults for B episodes of one task.

``World.reset(seeds)`` starts B episodes; ``World.sense(k)`` advances them to step k
(time ``k·dt``) and fills the step buffers: truth, the IMU reading that drives the
prediction from step k−1 to k, every channel's measurement, its validity mask, the
ground-truth fault label and the injected error. The world holds no filter: the CEKF
backbone (Track A) or a method's own estimator (Track B) consumes what it senses.

Batch layout: ``(B, N, ...)``; channel buffers ``(B, N, L, ...)``; measurements are
3-vectors with scalar ranges in component 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from .channels import ANCHOR, GPS, LANDMARK, PEER, PEER_REL, ChannelLayout, build_layout
from .faults import BIAS_UNIFORM, FaultSchedule, build_schedule
from .rng import Stream, normal, student_t, uniform
from .specs import TaskSpec
from .trajectories import N_PARAMS, trajectory_kind, trajectory_params, truth_at

LABEL_SIGMAS = 3.0  # an injected error above this many nominal σ is labelled a fault


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
        label: ``(B, N, L)`` ground-truth fault label.
        injected: ``(B, N, L)`` magnitude of the injected (non-noise) error [m].
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
    velocity: np.ndarray | None = None


@njit(cache=True, inline="always")
def _in_window(t: float, t0: float, t1: float) -> bool:
    return t0 <= t < t1


@njit(cache=True, parallel=True)
def _sense_kernel(
    steps, dt, seeds, traj_kind, traj_prm, anchors, landmarks,
    kind, target, linked, sigma, imu_sigma, imu_const_bias, cam_range, peer_range,
    bias_time, bias_param, bias_mask, imu_time, imu_bias, imu_nodes, imu_drop,
    outage_time, outage_nodes, drift_time, drift_rate, drift_nodes,
    gm_mask, gm_param, hybrid_nodes, hybrid_param, packet_loss,
    gm_bias, gm_left,
    pos, vel, imu, z, valid, label, injected,
):
    n_b, n, n_l = z.shape[0], z.shape[1], z.shape[2]
    for b in prange(n_b):
        seed = seeds[b]
        k = steps[b]
        t = k * dt
        a_tmp = np.empty(3)
        # ---- truth and IMU (u = Δv/dt: the mean acceleration over the interval)
        for i in range(n):
            v_prev0, v_prev1, v_prev2 = vel[b, i, 0], vel[b, i, 1], vel[b, i, 2]
            truth_at(traj_kind, traj_prm[i], t, seed, i, pos[b, i], vel[b, i], a_tmp)
            for d in range(3):
                v_prev = v_prev0 if d == 0 else (v_prev1 if d == 1 else v_prev2)
                u = (vel[b, i, d] - v_prev) / dt + imu_const_bias[b, i, d]
                for w in range(imu_time.shape[1]):
                    if imu_nodes[b, w, i] and _in_window(t, imu_time[b, w, 0], imu_time[b, w, 1]):
                        u += imu_bias[b, w, d]
                imu[b, i, d] = u + imu_sigma * normal(seed, k, Stream.IMU, i * 3 + d)
        # ---- channels
        for i in range(n):
            blind = False
            for w in range(imu_time.shape[1]):
                if imu_drop[b, w] and imu_nodes[b, w, i] and _in_window(t, imu_time[b, w, 0], imu_time[b, w, 1]):
                    blind = True
            vision_out = False
            for w in range(outage_time.shape[1]):
                if outage_nodes[b, w, i] and _in_window(t, outage_time[b, w, 0], outage_time[b, w, 1]):
                    vision_out = True
            for l in range(n_l):
                ch = kind[i, l]
                j = target[i, l]
                idx = i * n_l + l
                sg = sigma[i, l]
                ok = linked[i, l]
                err = 0.0
                lab = False
                if ch == ANCHOR or ch == PEER:
                    if ch == ANCHOR:
                        dx = pos[b, i, 0] - anchors[j, 0]
                        dy = pos[b, i, 1] - anchors[j, 1]
                        dz = pos[b, i, 2] - anchors[j, 2]
                    else:
                        dx = pos[b, i, 0] - pos[b, j, 0]
                        dy = pos[b, i, 1] - pos[b, j, 1]
                        dz = pos[b, i, 2] - pos[b, j, 2]
                    rng = math.sqrt(dx * dx + dy * dy + dz * dz)
                    if ch == PEER and rng > peer_range:
                        ok = False
                    # scheduled / uniform NLOS windows
                    for w in range(bias_time.shape[1]):
                        if bias_mask[b, w, i, l] and _in_window(t, bias_time[b, w, 0], bias_time[b, w, 1]):
                            if bias_param[b, w, 0] == BIAS_UNIFORM:
                                u = uniform(seed, k, Stream.NLOS_UNIFORM, idx * 8 + w)
                                err += bias_param[b, w, 1] + (bias_param[b, w, 2] - bias_param[b, w, 1]) * u
                            else:
                                err += bias_param[b, w, 1]
                    # Gauss–Markov NLOS episodes
                    if gm_mask[i, l]:
                        if gm_left[b, i, l] <= 0.0:
                            gm_bias[b, i, l] = 0.0
                            p_on = 1.0 - math.exp(-gm_param[0] * dt)
                            if uniform(seed, k, Stream.NLOS_ONSET, 2 * idx) < p_on:
                                u = uniform(seed, k, Stream.NLOS_ONSET, 2 * idx + 1)
                                gm_left[b, i, l] = max(1.0, -gm_param[1] * math.log(u) / dt)
                                bb = gm_param[2] + gm_param[3] * normal(seed, k, Stream.NLOS_PROCESS, idx)
                                gm_bias[b, i, l] = min(max(bb, 0.0), gm_param[5])
                        else:
                            # b ← μ + φ(b − μ) + σ√(1−φ²)·n, φ = exp(−dt/τ)
                            phi = math.exp(-dt / gm_param[4])
                            bb = gm_param[2] + phi * (gm_bias[b, i, l] - gm_param[2]) + gm_param[3] * math.sqrt(
                                1.0 - phi * phi) * normal(seed, k, Stream.NLOS_PROCESS, idx)
                            gm_bias[b, i, l] = min(max(bb, 0.0), gm_param[5])
                            gm_left[b, i, l] -= 1.0
                        if gm_left[b, i, l] > 0.0:
                            err += gm_bias[b, i, l]
                    stream = Stream.ANCHOR if ch == ANCHOR else Stream.PEER
                    z[b, i, l, 0] = rng + err + sg * normal(seed, k, stream, idx)
                    z[b, i, l, 1] = 0.0
                    z[b, i, l, 2] = 0.0
                    lab = err > LABEL_SIGMAS * sg
                    if ch == PEER:
                        lab = lab or _node_faulty(b, j, t, imu_time, imu_nodes)
                elif ch == LANDMARK:
                    dist2 = 0.0
                    for d in range(3):
                        rel = landmarks[j, d] - pos[b, i, d]
                        dist2 += rel * rel
                        z[b, i, l, d] = rel + sg * normal(seed, k, Stream.LANDMARK, idx * 3 + d)
                    if vision_out or dist2 > cam_range * cam_range:
                        ok = False
                elif ch == PEER_REL:
                    for d in range(3):
                        z[b, i, l, d] = pos[b, j, d] - pos[b, i, d] + sg * normal(seed, k, Stream.PEER, idx * 3 + d)
                    lab = _node_faulty(b, j, t, imu_time, imu_nodes)
                else:  # GPS
                    drift2 = 0.0
                    for d in range(3):
                        drift = 0.0
                        for w in range(drift_time.shape[1]):
                            if drift_nodes[b, w, i] and t >= drift_time[b, w, 0]:
                                drift += drift_rate[b, w, d] * (min(t, drift_time[b, w, 1]) - drift_time[b, w, 0])
                        drift2 += drift * drift
                        if hybrid_nodes[i]:
                            # v = a·t_ν(σ_t) + (1 − a)·N(0, σ_g²), ν uniform in [ν_lo, ν_hi] (imm-arkf eq. 1)
                            ratio = hybrid_param[0]
                            lo, hi = int(hybrid_param[3]), int(hybrid_param[4])
                            nu = lo + int(uniform(seed, k, Stream.HYBRID_MIX, idx * 3 + d) * (hi - lo + 1))
                            noise = ratio * hybrid_param[1] * student_t(seed, k, Stream.GPS, idx * 3 + d, nu) \
                                + (1.0 - ratio) * hybrid_param[2] * normal(seed, k, Stream.GPS, 1_000_000 + idx * 3 + d)
                        else:
                            noise = sg * normal(seed, k, Stream.GPS, idx * 3 + d)
                        z[b, i, l, d] = pos[b, i, d] + drift + noise
                    err = math.sqrt(drift2)
                    lab = drift2 > 0.0  # a drifting fix is faulty from the first centimetre
                if blind:
                    ok = False
                if ok and packet_loss > 0.0 and uniform(seed, k, Stream.PACKET_LOSS, idx) < packet_loss:
                    ok = False
                valid[b, i, l] = ok
                label[b, i, l] = lab and ok
                injected[b, i, l] = err


@njit(cache=True, inline="always")
def _node_faulty(b, j, t, imu_time, imu_nodes) -> bool:
    for w in range(imu_time.shape[1]):
        if imu_nodes[b, w, j] and imu_time[b, w, 0] <= t < imu_time[b, w, 1]:
            return True
    return False


@njit(cache=True)
def _velocity_kernel(steps, seeds, sigma, vel, bias, out):
    """Visual odometry: v_vo = v + b + σ n, n ~ N(0, 1) keyed by (seed, step, VELOCITY, uav·3 + axis).

    Serial: 3·N draws per episode cost less than waking a thread pool.
    """
    n_b, n = vel.shape[0], vel.shape[1]
    for b in range(n_b):
        for i in range(n):
            for d in range(3):
                out[b, i, d] = vel[b, i, d] + bias[b, i, d] + sigma * normal(seeds[b], steps[b], Stream.VELOCITY,
                                                                             i * 3 + d)


@njit(cache=True)
def _velocity_bias_kernel(seeds, sigma, out):
    """Per-episode constant VO bias b ~ N(0, σ²) per UAV and axis (drawn at step 0)."""
    for b in range(out.shape[0]):
        for i in range(out.shape[1]):
            for d in range(3):
                out[b, i, d] = sigma * normal(seeds[b], 0, Stream.VELOCITY, 1_000_000 + i * 3 + d)


@njit(cache=True, parallel=True)
def _reset_kernel(seeds, traj_kind, traj_prm, imu_bias_sigma, init_pos_sigma, init_vel_sigma,
                  pos, vel, imu_const_bias, x0):
    n_b, n = pos.shape[0], pos.shape[1]
    for b in prange(n_b):
        seed = seeds[b]
        a_tmp = np.empty(3)
        for i in range(n):
            truth_at(traj_kind, traj_prm[i], 0.0, seed, i, pos[b, i], vel[b, i], a_tmp)
            for d in range(3):
                imu_const_bias[b, i, d] = imu_bias_sigma * normal(seed, 0, Stream.INIT, 100 + i * 3 + d)
                # initial prior: truth perturbed by the stated initial uncertainty
                x0[b, i, d] = pos[b, i, d] + init_pos_sigma * normal(seed, 0, Stream.INIT, 10_000 + i * 6 + d)
                x0[b, i, 3 + d] = vel[b, i, d] + init_vel_sigma * normal(seed, 0, Stream.INIT, 10_003 + i * 6 + d)


class World:
    """Truth, sensors and faults of B episodes of one task (no estimator).

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
        self._traj_kind = trajectory_kind(spec)
        self._traj_prm = np.ascontiguousarray(trajectory_params(spec)).reshape(spec.n_uav, N_PARAMS)
        self.anchors = np.asarray(spec.anchors, dtype=float).reshape(-1, 3)
        self.landmarks = np.asarray(spec.landmarks, dtype=float).reshape(-1, 3)
        n_b, n, n_l = batch_size, spec.n_uav, self.layout.n_channels
        self.buffers = SenseBuffers(
            pos=np.zeros((n_b, n, 3)), vel=np.zeros((n_b, n, 3)), imu=np.zeros((n_b, n, 3)),
            z=np.zeros((n_b, n, n_l, 3)), valid=np.zeros((n_b, n, n_l), dtype=np.bool_),
            label=np.zeros((n_b, n, n_l), dtype=np.bool_), injected=np.zeros((n_b, n, n_l)),
        )
        self.seeds = np.zeros(n_b, dtype=np.int64)
        self.schedule: FaultSchedule = build_schedule(spec, self.layout, self.seeds)
        self.imu_const_bias = np.zeros((n_b, n, 3))
        self.x0 = np.zeros((n_b, n, 6))
        self._gm_bias = np.zeros((n_b, n, n_l))
        self._gm_left = np.zeros((n_b, n, n_l))
        self.steps = np.zeros(n_b, dtype=np.int64)
        # visual odometry and UWB outages act after the sensing kernel (additive; kernel unchanged)
        vo = spec.sensors.velocity_sigma
        self.velocity_bias = np.zeros((n_b, n, 3))
        if vo is not None:
            self.buffers.velocity = np.zeros((n_b, n, 3))
        out = spec.faults.uwb_outage
        self._outage_windows = np.asarray(out.windows if out is not None else (), dtype=float).reshape(-1, 2)
        self._outage_mask = np.zeros((n, n_l), dtype=np.bool_)
        if out is not None:
            kinds = [ANCHOR] * ("anchor" in out.targets) + [PEER, PEER_REL] * ("peer" in out.targets)
            rows = np.zeros(n, dtype=np.bool_)
            rows[list(out.nodes) if out.nodes else slice(None)] = True
            self._outage_mask = np.isin(self.layout.kind, kinds) & rows[:, None]

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
        sub = build_schedule(self.spec, self.layout, self.seeds[idx])
        if mask is None:
            self.schedule = sub
        else:
            for name, value in vars(sub).items():
                if isinstance(value, np.ndarray) and value.ndim and value.shape[0] == len(idx) and name not in (
                        "gm_mask", "gm_param", "hybrid_nodes", "hybrid_param"):
                    getattr(self.schedule, name)[idx] = value
        self._gm_bias[idx] = 0.0
        self._gm_left[idx] = 0.0
        self.steps[idx] = 0
        f = self.spec.filter
        buf = self.buffers
        pos, vel = buf.pos[idx], buf.vel[idx]
        bias, x0 = self.imu_const_bias[idx], self.x0[idx]
        _reset_kernel(self.seeds[idx], self._traj_kind, self._traj_prm, self.spec.sensors.imu_bias_sigma,
                      f.init_pos_sigma, f.init_vel_sigma, pos, vel, bias, x0)
        buf.pos[idx], buf.vel[idx], self.imu_const_bias[idx], self.x0[idx] = pos, vel, bias, x0
        # nothing of the previous episode may leak into the next (the first jerk feature
        # is ‖u(1) − u(0)‖ with u(0) = 0)
        buf.imu[idx] = 0.0
        buf.z[idx] = 0.0
        buf.injected[idx] = 0.0
        buf.valid[idx] = False
        buf.label[idx] = False
        if buf.velocity is not None:
            bias = np.zeros((idx.size, self.spec.n_uav, 3))
            _velocity_bias_kernel(self.seeds[idx], self.spec.sensors.velocity_bias_sigma, bias)
            self.velocity_bias[idx] = bias
            buf.velocity[idx] = buf.vel[idx] + bias
        return self.x0

    def sense(self) -> SenseBuffers:
        """Advance every episode by one step and fill the step buffers."""
        self.steps += 1
        s, sc, buf, lay = self.spec, self.schedule, self.buffers, self.layout
        _sense_kernel(
            self.steps, s.dt, self.seeds, self._traj_kind, self._traj_prm, self.anchors, self.landmarks,
            lay.kind, lay.target, lay.linked, lay.sigma, s.sensors.imu_sigma, self.imu_const_bias,
            s.sensors.camera_max_range, s.sensors.peers.max_range,
            sc.bias_time, sc.bias_param, sc.bias_mask, sc.imu_time, sc.imu_bias, sc.imu_nodes, sc.imu_drop,
            sc.outage_time, sc.outage_nodes, sc.drift_time, sc.drift_rate, sc.drift_nodes,
            sc.gm_mask, sc.gm_param, sc.hybrid_nodes, sc.hybrid_param, sc.packet_loss,
            self._gm_bias, self._gm_left,
            buf.pos, buf.vel, buf.imu, buf.z, buf.valid, buf.label, buf.injected,
        )
        if buf.velocity is not None:
            _velocity_kernel(self.steps, self.seeds, float(s.sensors.velocity_sigma), buf.vel, self.velocity_bias,
                             buf.velocity)
        if self._outage_windows.size:
            # same half-open test as the kernel's windows: start <= k·dt < end
            t = self.steps * s.dt
            w = self._outage_windows
            inside = ((t[:, None] >= w[None, :, 0]) & (t[:, None] < w[None, :, 1])).any(axis=1)
            if inside.any():
                lost = inside[:, None, None] & self._outage_mask[None]
                buf.valid &= ~lost
                buf.label &= ~lost
        return buf
