"""The world kernel: one step of truth, IMU, channels and faults per episode.

``WorldInputs`` names the task, the episode state and the step buffers, the
``FaultSchedule`` (``faults.py``) the episodes' fault windows. ``sense_episodes(w, fs, go,
lo, hi)`` advances a range of episodes by one step on the calling thread (the link-trust
core calls it inside its own step kernel), ``sense_batch`` the whole batch (and
``sense_batch_threaded`` with threads over blocks of episodes), and
``reset_episodes`` starts episodes at step 0. Every fault acts inside the kernel: range
biases, Gauss–Markov NLOS, IMU cascades, camera and UWB outages, GPS drift, hybrid GPS
noise, packet loss (and GNSS noise correlated in time, a Gauss–Markov error per axis); visual odometry is sensed beside the truth. All draws come from the
counter-based RNG (``rng.py``) keyed by (seed, step, stream, index), so the numbers do not
depend on the batch, the thread or the order of evaluation. A TDOA channel senses the range
difference of its anchor pair with the anchor ranges' noise stream; its NLOS bias (scheduled
windows and Gauss–Markov episodes act per channel, as on a range) delays the pair's second
anchor, so it adds to the range difference.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from swarmloc.envs.tasks.channels import ANCHOR, LANDMARK, PEER, PEER_REL, TDOA
from swarmloc.envs.world.faults import BIAS_RAMP, BIAS_UNIFORM, HYBRID_MIXTURE, FaultSchedule
from swarmloc.envs.world.labels import own_sigmas
from swarmloc.envs.tasks.rng import Stream, normal_at, stream_key, student_t_at, uniform_at
from swarmloc.envs.world.trajectories import truth_at

#: injected-fault label (``SenseBuffers.label``): a range error above this many nominal σ is a fault
INJECTED_FAULT_SIGMAS = 3.0


class WorldInputs(NamedTuple):
    """Inputs, state and step buffers of the world kernel for B episodes of one task.

    Shapes: B episodes, N UAVs, L channel slots per UAV, A anchors, M landmarks,
    ``N_PARAMS`` trajectory parameters. The fault windows are the kernel's second argument,
    a ``FaultSchedule``. Measurements are 3-vectors with scalar ranges in component 0.

    Task (constant):
        dt: step length [s].
        traj_kind: trajectory kind id (``trajectories.py``); traj_prm ``(N, N_PARAMS)``.
        anchors: ``(A, 3)``; landmarks ``(M, 3)`` [m].
        kind, target: ``(N, L)`` int64 channel kind and the anchor / UAV / landmark it refers to.
        linked: ``(N, L)`` bool, the topology connects the slot.
        sigma: ``(N, L)`` nominal noise σ per scalar row [m].
        imu_sigma: accelerometer noise σ [m/s²].
        camera_range, peer_range, anchor_range: landmark, peer and anchor ranging radius [m].
        camera_fov_cos: cosine of half the camera's field of view; the camera looks along the
            UAV's velocity (−1: omnidirectional, every landmark in range is seen).
        has_velocity: the task has a visual-odometry sensor; velocity_sigma its noise σ [m/s].
        gps_tau: time constant τ of the GNSS error [s] (``Sensors.gps_correlation_time``); 0: white.
        label_threshold: ``(N, L)`` error-label threshold on the systematic error in σ_eff
            (``labels.label_thresholds``).

    Episode state (changed by ``reset_episodes`` and ``sense_episodes``):
        seeds, steps: ``(B,)`` int64 episode seed and current step k (time k·dt).
        imu_const_bias: ``(B, N, 3)`` constant accelerometer bias [m/s²].
        velocity_bias: ``(B, N, 3)`` constant visual-odometry bias [m/s].
        gm_bias, gm_left: ``(B, N, L)`` Gauss–Markov NLOS bias [m] and steps left in the episode.
        gps_error: ``(B, N, 3)`` Gauss–Markov GNSS error per axis in units of the fix's σ (unit
            stationary variance; used when gps_tau > 0).

    Step buffers (written by ``sense_episodes`` for step k):
        pos, vel, acc: ``(B, N, 3)`` truth [m, m/s, m/s²].
        imu: ``(B, N, 3)`` accelerometer reading for the interval (k−1, k] [m/s²].
        z: ``(B, N, L, 3)`` measurements; valid, label ``(B, N, L)`` bool present / injected fault.
        injected: ``(B, N, L)`` magnitude of the injected (non-noise) error [m].
        systematic: ``(B, N, L, 3)`` signed systematic error of the measurement (``labels.py``):
            range bias in component 0, GPS drift + heavy-tail excess per axis, 0 otherwise [m].
        error_label: ``(B, N, L)`` bool error label of the measurement's own error (present and
            ``own_sigmas > label_threshold``; the core adds the neighbour-estimate part).
        velocity: ``(B, N, 3)`` visual-odometry velocity [m/s] (zeros without the sensor).
    """

    dt: float
    traj_kind: int
    traj_prm: np.ndarray
    anchors: np.ndarray
    landmarks: np.ndarray
    kind: np.ndarray
    target: np.ndarray
    linked: np.ndarray
    sigma: np.ndarray
    imu_sigma: float
    camera_range: float
    camera_fov_cos: float
    peer_range: float
    anchor_range: float
    has_velocity: bool
    velocity_sigma: float
    gps_tau: float
    label_threshold: np.ndarray
    seeds: np.ndarray
    steps: np.ndarray
    imu_const_bias: np.ndarray
    velocity_bias: np.ndarray
    gm_bias: np.ndarray
    gm_left: np.ndarray
    gps_error: np.ndarray
    pos: np.ndarray
    vel: np.ndarray
    acc: np.ndarray
    imu: np.ndarray
    z: np.ndarray
    valid: np.ndarray
    label: np.ndarray
    injected: np.ndarray
    systematic: np.ndarray
    error_label: np.ndarray
    velocity: np.ndarray


@njit(cache=True, inline="always")
def _inside(t: float, start: float, end: float) -> bool:
    """t lies in the half-open window [start, end)."""
    return start <= t < end


@njit(cache=True, inline="always")
def _imu_faulty(imu_time: np.ndarray, imu_nodes: np.ndarray, b: int, j: int, t: float) -> bool:
    """UAV j of episode b is inside one of its IMU-fault windows at time t."""
    for wi in range(imu_time.shape[1]):
        if imu_nodes[b, wi, j] and _inside(t, imu_time[b, wi, 0], imu_time[b, wi, 1]):
            return True
    return False


@njit(cache=True, inline="always")
def _range_difference(pos: np.ndarray, anchors: np.ndarray, b: int, i: int, code: int) -> float:
    """‖p − a_j‖ − ‖p − a_i‖ of UAV i of episode b for the TDOA pair code ``i·A + j`` (``channels.tdoa_pair``)."""
    n_a = anchors.shape[0]
    ia, ib = code // n_a, code % n_a
    e0, e1, e2 = pos[b, i, 0] - anchors[ib, 0], pos[b, i, 1] - anchors[ib, 1], pos[b, i, 2] - anchors[ib, 2]
    f0, f1, f2 = pos[b, i, 0] - anchors[ia, 0], pos[b, i, 1] - anchors[ia, 1], pos[b, i, 2] - anchors[ia, 2]
    return math.sqrt(e0 * e0 + e1 * e1 + e2 * e2) - math.sqrt(f0 * f0 + f1 * f1 + f2 * f2)


#: below this batch size the kernels run on the calling thread: a parallel region over a
#: handful of episodes costs more than it saves, and on a busy machine OpenMP workers that
#: spin-wait for their turn can make one step take tens of milliseconds
SERIAL_BELOW = 32

#: episodes per parallel block. The prange body only calls a compiled function on its
#: block: numba (0.68) loses writes made through a named tuple's fields directly in a
#: prange body, and refuses nested tuples there.
BLOCK = 16


@njit(cache=True, inline="always")
def block_bounds(block: int, n: int) -> tuple[int, int]:
    """Episodes [lo, hi) of parallel block ``block`` out of a batch of n."""
    return block * BLOCK, min((block + 1) * BLOCK, n)


@njit(cache=True, inline="always")
def _in_view(landmarks, pos, vel, b, i, j, fov_cos) -> bool:
    """Landmark j lies inside UAV i's forward camera cone (the camera looks along the velocity).

    A UAV at rest (speed below 1 mm/s) has no defined heading: it sees every landmark in range.
    """
    dot, rr, vv = 0.0, 0.0, 0.0
    for d in range(3):
        rel = landmarks[j, d] - pos[b, i, d]
        dot += rel * vel[b, i, d]
        rr += rel * rel
        vv += vel[b, i, d] * vel[b, i, d]
    if vv < 1e-6:
        return True
    return dot >= fov_cos * math.sqrt(rr * vv)


# The kernel passes helpers only arrays and scalars: handing a named tuple of arrays to a
# helper (inlined or not) costs an atomic reference count per field and call, which numba
# cannot prune. Division by zero cannot occur (dt, τ > 0); error_model="numpy" keeps
# exception paths, which also block that pruning, out of the loop.
@njit(cache=True, error_model="numpy")
def sense_episodes(w: WorldInputs, fs: FaultSchedule, go: np.ndarray, lo: int, hi: int) -> None:
    """Advance the episodes b in [lo, hi) with ``go[b]`` by one step, on the calling thread.

    Per episode: truth and IMU (u = Δv/dt + biases + noise, the mean acceleration over the
    interval), visual odometry, then every channel with its faults.
    """
    # The arrays are bound once: numba reference-counts every array read from a named tuple,
    # with an atomic operation, and keeps the pair when the read sits in a branch.
    pos, vel, acc, imu, z, velocity = w.pos, w.vel, w.acc, w.imu, w.z, w.velocity
    valid, label, injected, systematic, error_label = w.valid, w.label, w.injected, w.systematic, w.error_label
    anchors, landmarks, traj_prm = w.anchors, w.landmarks, w.traj_prm
    kind, target, linked, sigma, label_threshold = w.kind, w.target, w.linked, w.sigma, w.label_threshold
    seeds, steps, imu_const_bias, velocity_bias, gm_bias, gm_left = (w.seeds, w.steps, w.imu_const_bias,
                                                                      w.velocity_bias, w.gm_bias, w.gm_left)
    gps_error = w.gps_error
    bias_time, bias_param, bias_mask = fs.bias_time, fs.bias_param, fs.bias_mask
    imu_time, imu_bias, imu_nodes, imu_drop = fs.imu_time, fs.imu_bias, fs.imu_nodes, fs.imu_drop
    outage_time, outage_nodes, uwb_time, uwb_mask = fs.outage_time, fs.outage_nodes, fs.uwb_time, fs.uwb_mask
    drift_time, drift_rate, drift_nodes = fs.drift_time, fs.drift_rate, fs.drift_nodes
    gm_mask, gm_key, hybrid_nodes = fs.gm_mask, fs.gm_key, fs.hybrid_nodes
    landmark_offset = fs.landmark_offset
    gm_params = fs.gm_param  # (B, 7) [onset_rate, mean_duration, mean_bias, bias_sigma, tau, max_bias, ramp]
    hybrid_params = fs.hybrid_param  # (B, 6) [ratio, t_scale, gauss_sigma, dof_low, dof_high, model]
    n, n_l = z.shape[1], z.shape[2]
    # GNSS error as a first-order Gauss–Markov process in units of σ: ε ← φ ε + √(1−φ²) n,
    # φ = exp(−dt/τ) (specs.Sensors); white (the v0/v1 draw, bit for bit) when τ = 0
    gps_markov = w.gps_tau > 0.0
    gps_phi = math.exp(-w.dt / w.gps_tau) if gps_markov else 0.0
    gps_step = math.sqrt(1.0 - gps_phi * gps_phi)
    # truth_at writes whole 3-vectors: into these, not into views of the batch arrays
    p, v, a = np.empty(3), np.empty(3), np.empty(3)
    for b in range(lo, hi):
        if not go[b]:
            continue
        steps[b] += 1
        k = steps[b]
        t = k * w.dt
        seed = seeds[b]
        # one hash prefix per stream and step (rng.stream_key): each draw then costs one round
        key_imu = stream_key(seed, k, Stream.IMU)
        key_anchor = stream_key(seed, k, Stream.ANCHOR)
        key_peer = stream_key(seed, k, Stream.PEER)
        key_landmark = stream_key(seed, k, Stream.LANDMARK)
        key_gps = stream_key(seed, k, Stream.GPS)
        key_mix = stream_key(seed, k, Stream.HYBRID_MIX)
        key_loss = stream_key(seed, k, Stream.PACKET_LOSS)
        key_onset = stream_key(seed, k, Stream.NLOS_ONSET)
        key_process = stream_key(seed, k, Stream.NLOS_PROCESS)
        key_uniform = stream_key(seed, k, Stream.NLOS_UNIFORM)
        key_vo = stream_key(seed, k, Stream.VELOCITY)

        # ---- truth, IMU, visual odometry
        for i in range(n):
            truth_at(w.traj_kind, traj_prm[i], t, seed, i, p, v, a)
            for d in range(3):
                v_prev = vel[b, i, d]
                pos[b, i, d], vel[b, i, d], acc[b, i, d] = p[d], v[d], a[d]
                u = (vel[b, i, d] - v_prev) / w.dt + imu_const_bias[b, i, d]
                for wi in range(imu_time.shape[1]):
                    if imu_nodes[b, wi, i] and _inside(t, imu_time[b, wi, 0], imu_time[b, wi, 1]):
                        u += imu_bias[b, wi, d]
                imu[b, i, d] = u + w.imu_sigma * normal_at(key_imu, i * 3 + d)
                if w.has_velocity:
                    # v_vo = v + b + σ n
                    velocity[b, i, d] = (vel[b, i, d] + velocity_bias[b, i, d]
                                         + w.velocity_sigma * normal_at(key_vo, i * 3 + d))

        # Gauss–Markov constants (τ > 0 whenever the process is on): onset probability per
        # step and the AR(1) coefficient φ = exp(−dt/τ) with its innovation scale σ√(1−φ²)
        g = gm_params[b]
        h = hybrid_params[b]
        p_on, phi, gm_step_sigma = 0.0, 0.0, 0.0
        if g[4] > 0.0:
            p_on = 1.0 - math.exp(-g[0] * w.dt)
            phi = math.exp(-w.dt / g[4])
            gm_step_sigma = g[3] * math.sqrt(1.0 - phi * phi)

        # ---- channels
        for i in range(n):
            # a UAV inside an IMU fault that drops it hears nothing
            blind = False
            for wi in range(imu_time.shape[1]):
                if imu_drop[b, wi] and imu_nodes[b, wi, i] and _inside(t, imu_time[b, wi, 0], imu_time[b, wi, 1]):
                    blind = True
            vision_out = False
            for wi in range(outage_time.shape[1]):
                if outage_nodes[b, wi, i] and _inside(t, outage_time[b, wi, 0], outage_time[b, wi, 1]):
                    vision_out = True
            for l in range(n_l):
                ch = kind[i, l]
                j = target[i, l]
                idx = i * n_l + l
                sg = sigma[i, l]
                ok = linked[i, l]
                err = 0.0
                lab = False
                if ch == ANCHOR or ch == PEER or ch == TDOA:
                    if ch == TDOA:
                        # range difference of the pair (j // A, j % A); a fault delays the second anchor
                        rng = _range_difference(pos, anchors, b, i, j)
                    else:
                        if ch == ANCHOR:
                            dx = pos[b, i, 0] - anchors[j, 0]
                            dy = pos[b, i, 1] - anchors[j, 1]
                            dz = pos[b, i, 2] - anchors[j, 2]
                        else:
                            dx = pos[b, i, 0] - pos[b, j, 0]
                            dy = pos[b, i, 1] - pos[b, j, 1]
                            dz = pos[b, i, 2] - pos[b, j, 2]
                        rng = math.sqrt(dx * dx + dy * dy + dz * dz)
                    if (ch == PEER and rng > w.peer_range) or (ch == ANCHOR and rng > w.anchor_range):
                        ok = False
                    # scheduled / uniform NLOS windows
                    for wi in range(bias_time.shape[1]):
                        if bias_mask[b, wi, i, l] and _inside(t, bias_time[b, wi, 0], bias_time[b, wi, 1]):
                            lo_b, hi_b = bias_param[b, wi, 1], bias_param[b, wi, 2]
                            if bias_param[b, wi, 0] == BIAS_UNIFORM:
                                err += lo_b + (hi_b - lo_b) * uniform_at(key_uniform, idx * 8 + wi)
                            elif bias_param[b, wi, 0] == BIAS_RAMP:
                                err += lo_b * min(1.0, (t - bias_time[b, wi, 0]) / hi_b)
                            else:
                                err += lo_b
                    # Gauss–Markov NLOS episodes; the draws are keyed by gm_key (i·L + l, or the peer
                    # pair's shared index under per_link, so both directions evolve as one state)
                    if gm_mask[b, i, l]:
                        gk = gm_key[i, l]
                        if gm_left[b, i, l] <= 0.0:
                            gm_bias[b, i, l] = 0.0
                            if uniform_at(key_onset, 2 * gk) < p_on:
                                u = uniform_at(key_onset, 2 * gk + 1)
                                gm_left[b, i, l] = max(1.0, -g[1] * math.log(u) / w.dt)
                                if g[6] > 0.0:  # ramp onset: from zero bias, relaxing towards the mean
                                    gm_bias[b, i, l] = 0.0
                                else:
                                    bb = g[2] + g[3] * normal_at(key_process, gk)
                                    gm_bias[b, i, l] = min(max(bb, 0.0), g[5])
                        else:
                            # b ← μ + φ(b − μ) + σ√(1−φ²)·n
                            bb = g[2] + phi * (gm_bias[b, i, l] - g[2]) + gm_step_sigma * normal_at(key_process, gk)
                            gm_bias[b, i, l] = min(max(bb, 0.0), g[5])
                            gm_left[b, i, l] -= 1.0
                        if gm_left[b, i, l] > 0.0:
                            err += gm_bias[b, i, l]
                    z[b, i, l, 0] = rng + err + sg * normal_at(key_peer if ch == PEER else key_anchor, idx)
                    z[b, i, l, 1] = 0.0
                    z[b, i, l, 2] = 0.0
                    systematic[b, i, l, 0] = err
                    systematic[b, i, l, 1] = 0.0
                    systematic[b, i, l, 2] = 0.0
                    lab = err > INJECTED_FAULT_SIGMAS * sg
                    if ch == PEER:
                        lab = lab or _imu_faulty(imu_time, imu_nodes, b, j, t)
                elif ch == LANDMARK:
                    dist2 = 0.0
                    for d in range(3):
                        # the landmark sits at its mapped (public) position plus the map's error
                        err_map = landmark_offset[b, j, d]
                        systematic[b, i, l, d] = err_map
                        rel = landmarks[j, d] + err_map - pos[b, i, d]
                        dist2 += rel * rel
                        z[b, i, l, d] = rel + sg * normal_at(key_landmark, idx * 3 + d)
                    if vision_out or dist2 > w.camera_range * w.camera_range:
                        ok = False
                    elif w.camera_fov_cos > -1.0 and not _in_view(landmarks, pos, vel, b, i, j, w.camera_fov_cos):
                        ok = False
                elif ch == PEER_REL:
                    for d in range(3):
                        systematic[b, i, l, d] = 0.0
                        z[b, i, l, d] = pos[b, j, d] - pos[b, i, d] + sg * normal_at(key_peer, idx * 3 + d)
                    lab = _imu_faulty(imu_time, imu_nodes, b, j, t)
                else:  # GPS: p + drift + noise
                    # hybrid noise as a contamination mixture: one draw per fix. With probability
                    # p the fix is a trivariate Student-t σ_t·n / sqrt(χ²_ν / ν), one χ² for the
                    # three axes (imm-arkf's multivariate t), ν uniform in [ν_lo, ν_hi]; else
                    # N(0, σ_g² I). The same n serves either branch.
                    mixture = hybrid_nodes[i] and h[5] == HYBRID_MIXTURE
                    heavy, t_factor = False, 0.0
                    if mixture and uniform_at(key_mix, 2 * idx) < h[0]:
                        heavy = True
                        lo_nu, hi_nu = int(h[3]), int(h[4])
                        nu = lo_nu + int(uniform_at(key_mix, 2 * idx + 1) * (hi_nu - lo_nu + 1))
                        chi2 = 0.0
                        for c in range(nu):
                            nc = normal_at(key_gps, 2_000_000 + idx * 64 + c)
                            chi2 += nc * nc
                        t_factor = h[1] / math.sqrt(chi2 / nu)
                    drift2 = 0.0
                    for d in range(3):
                        drift = 0.0
                        for wi in range(drift_time.shape[1]):
                            if drift_nodes[b, wi, i] and t >= drift_time[b, wi, 0]:
                                drift += drift_rate[b, wi, d] * (min(t, drift_time[b, wi, 1]) - drift_time[b, wi, 0])
                        drift2 += drift * drift
                        if mixture:
                            # a Student-t draw is heavy-tail excess as a whole (systematic), as the
                            # t component of the weighted sum is; a Gaussian draw is the nominal noise
                            nd = normal_at(key_gps, idx * 3 + d)
                            tail = t_factor * nd if heavy else 0.0
                            noise = tail if heavy else h[2] * nd
                        elif hybrid_nodes[i]:
                            # v = a·t_ν(σ_t) + (1 − a)·N(0, σ_g²), ν uniform in [ν_lo, ν_hi] (imm-arkf eq. 1)
                            lo_nu, hi_nu = int(h[3]), int(h[4])
                            nu = lo_nu + int(uniform_at(key_mix, idx * 3 + d) * (hi_nu - lo_nu + 1))
                            # the Student-t component is the heavy-tail excess (systematic), the
                            # Gaussian one the nominal white noise
                            tail = h[0] * h[1] * student_t_at(key_gps, idx * 3 + d, nu)
                            noise = tail + (1.0 - h[0]) * h[2] * normal_at(key_gps, 1_000_000 + idx * 3 + d)
                        elif gps_markov:
                            # e_k = φ e_{k−1} + σ√(1−φ²) n_k: nominal noise, correlated in time (not systematic)
                            tail = 0.0
                            gps_error[b, i, d] = gps_phi * gps_error[b, i, d] + gps_step * normal_at(key_gps,
                                                                                                      idx * 3 + d)
                            noise = sg * gps_error[b, i, d]
                        else:
                            tail = 0.0
                            noise = sg * normal_at(key_gps, idx * 3 + d)
                        z[b, i, l, d] = pos[b, i, d] + drift + noise
                        systematic[b, i, l, d] = drift + tail
                    err = math.sqrt(drift2)
                    lab = drift2 > 0.0  # a drifting fix is faulty from the first centimetre
                if blind:
                    ok = False
                for wi in range(uwb_time.shape[1]):
                    if uwb_mask[b, wi, i, l] and _inside(t, uwb_time[b, wi, 0], uwb_time[b, wi, 1]):
                        ok = False
                if ok and fs.packet_loss > 0.0 and uniform_at(key_loss, idx) < fs.packet_loss:
                    ok = False
                valid[b, i, l] = ok
                label[b, i, l] = lab and ok
                injected[b, i, l] = err
                error_label[b, i, l] = ok and own_sigmas(ch, systematic[b, i, l, 0], systematic[b, i, l, 1],
                                                      systematic[b, i, l, 2], sg) > label_threshold[i, l]


@njit(cache=True, error_model="numpy")
def sense_batch(w: WorldInputs, fs: FaultSchedule, go: np.ndarray) -> None:
    """Advance the episodes with ``go[b]`` by one step, on the calling thread."""
    sense_episodes(w, fs, go, 0, go.shape[0])


@njit(cache=True, parallel=True, error_model="numpy")
def sense_batch_threaded(w: WorldInputs, fs: FaultSchedule, go: np.ndarray) -> None:
    """``sense_batch`` with threads over blocks of ``BLOCK`` episodes."""
    n_b = go.shape[0]
    for block in prange((n_b + BLOCK - 1) // BLOCK):
        lo, hi = block_bounds(block, n_b)
        sense_episodes(w, fs, go, lo, hi)


def sense_kernel(batch_size: int) -> Callable[..., None]:
    """``sense_batch`` below ``SERIAL_BELOW`` episodes, else ``sense_batch_threaded``: chosen
    once per world, so that a process that only senses small batches never compiles the
    parallel lowering (as ``core_kernel.step_kernel``)."""
    return sense_batch if batch_size < SERIAL_BELOW else sense_batch_threaded


@njit(cache=True, error_model="numpy")
def reset_episodes(w: WorldInputs, idx: np.ndarray, imu_bias_sigma: float, velocity_bias_sigma: float,
                   init_pos_sigma: float, init_vel_sigma: float, x0: np.ndarray) -> None:
    """Start episodes ``idx`` at step 0 (their seeds and fault windows already set).

    Writes the truth at t = 0, the per-episode constant biases, the GNSS error's stationary
    start (ε_0 ~ N(0, 1) per axis in units of σ, when ``gps_tau`` > 0; drawn from the GPS
    stream at step 0, which sensing never uses: it starts at step 1) and the initial prior
    mean ``x0`` ``(B, N, 6)`` [p, v]: the truth perturbed by the stated initial uncertainty.
    Nothing of the previous episode leaks into the next: the step buffers are cleared (the
    first jerk feature is ‖u(1) − u(0)‖ with u(0) = 0).
    """
    n = w.pos.shape[1]
    for e in range(idx.shape[0]):
        b = idx[e]
        seed = w.seeds[b]
        w.steps[b] = 0
        key = stream_key(seed, 0, Stream.INIT)
        key_vo = stream_key(seed, 0, Stream.VELOCITY)
        key_gps = stream_key(seed, 0, Stream.GPS)
        for i in range(n):
            truth_at(w.traj_kind, w.traj_prm[i], 0.0, seed, i, w.pos[b, i], w.vel[b, i], w.acc[b, i])
            for d in range(3):
                w.imu_const_bias[b, i, d] = imu_bias_sigma * normal_at(key, 100 + i * 3 + d)
                x0[b, i, d] = w.pos[b, i, d] + init_pos_sigma * normal_at(key, 10_000 + i * 6 + d)
                x0[b, i, 3 + d] = w.vel[b, i, d] + init_vel_sigma * normal_at(key, 10_003 + i * 6 + d)
                w.imu[b, i, d] = 0.0
                w.velocity_bias[b, i, d] = 0.0
                w.velocity[b, i, d] = 0.0
                if w.has_velocity:
                    w.velocity_bias[b, i, d] = velocity_bias_sigma * normal_at(key_vo, 1_000_000 + i * 3 + d)
                    w.velocity[b, i, d] = w.vel[b, i, d] + w.velocity_bias[b, i, d]
                w.gps_error[b, i, d] = normal_at(key_gps, i * 3 + d) if w.gps_tau > 0.0 else 0.0
        w.z[b] = 0.0
        w.injected[b] = 0.0
        w.systematic[b] = 0.0
        w.error_label[b] = False
        w.valid[b] = False
        w.label[b] = False
        w.gm_bias[b] = 0.0
        w.gm_left[b] = 0.0
