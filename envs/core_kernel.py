"""The link-trust core's step as one kernel: score the pending update, then sense, predict
and featurize the next step, episode by episode.

``FilterArrays`` names the CEKF state and the ``CoreStep`` outputs; ``core_step`` runs one
step of every episode in one call, threads over blocks of episodes (``step_episodes`` runs
a range of episodes on the calling thread, for small batches). Per episode b, with trust α
(scoring):

1. posterior at the pending step k: the trust-weighted joint update (``cekf.update_uav``);
   estimate, truth, labels, trust and FLOPs of the update are written out, the episode
   counts one more update and is done after ``n_steps``;
2. if it goes on: the world senses step k+1 (``world_kernel.sense_episode``; skipped when
   the world inputs are None, for worlds that sense in Python), every UAV predicts to it
   (``cekf.predict_uav``) and the per-channel innovation features at the prior are
   computed (``cekf.features_uav``), with the IMU jerk ‖u(k+1) − u(k)‖.

Without scoring (after a reset) only step 2 runs, for the episodes in ``advance``. The
numbers are those of the separate kernels (``cekf_update``, ``cekf_predict``,
``channel_features``) applied to the whole batch: every episode's arithmetic is the same
sequence of operations, only fused, so the results are bit-identical.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from .cekf import features_uav, predict_uav, update_uav
from .faults import FaultSchedule
from .world_kernel import BLOCK, WorldInputs, block_bounds, sense_episode


class FilterArrays(NamedTuple):
    """The CEKF backbone and the step outputs of B episodes (``core_step``'s second argument).

    Shapes: B episodes, N UAVs, L channel slots per UAV, A anchors, M landmarks.

    Task (constant):
        dt: step length [s]; imu_sigma: accelerometer noise σ [m/s²] (Q = σ² G Gᵀ).
        alpha_th: trust at or below which a channel is left out of the update;
            alpha_min: floor of α in R = R0 / max(α, α_min).
        n_steps: updates per episode.
        kind, target, r0: ``(N, L)`` channel kind, target index and nominal variance R0 [m²].
        anchors: ``(A, 3)``; landmarks ``(M, 3)`` [m].

    The world's step buffers (views; the world writes them):
        world_pos: ``(B, N, 3)`` truth; world_imu ``(B, N, 3)`` IMU reading [m/s²].
        world_z: ``(B, N, L, 3)`` measurements; world_valid, world_label ``(B, N, L)`` bool.

    Filter state:
        x: ``(B, N, 6)`` mean [p, v]; P ``(B, N, 6, 6)`` covariance (the prior at the pending step).
        prior_pos: ``(B, N, 3)`` the broadcast prior positions (peer channels linearise at them).
        imu_prev: ``(B, N, 3)`` IMU reading of the step before the pending one (for the jerk).

    Step outputs (the ``CoreStep`` arrays, same names and shapes):
        resid, pred, nis, valid: ``(B, N, L)`` features of the pending update.
        jerk: ``(B, N)``.
        estimate, truth: ``(B, N, 3)``; label, update_valid, applied, prev_trust, active
        ``(B, N, L)``; flops ``(B, N)`` of the last update.
        steps: ``(B,)`` int64 updates done; done ``(B,)`` bool.
    """

    dt: float
    imu_sigma: float
    alpha_th: float
    alpha_min: float
    n_steps: int
    kind: np.ndarray
    target: np.ndarray
    r0: np.ndarray
    anchors: np.ndarray
    landmarks: np.ndarray
    world_pos: np.ndarray
    world_imu: np.ndarray
    world_z: np.ndarray
    world_valid: np.ndarray
    world_label: np.ndarray
    x: np.ndarray
    P: np.ndarray
    prior_pos: np.ndarray
    imu_prev: np.ndarray
    resid: np.ndarray
    pred: np.ndarray
    nis: np.ndarray
    valid: np.ndarray
    jerk: np.ndarray
    estimate: np.ndarray
    truth: np.ndarray
    label: np.ndarray
    update_valid: np.ndarray
    applied: np.ndarray
    prev_trust: np.ndarray
    active: np.ndarray
    flops: np.ndarray
    steps: np.ndarray
    done: np.ndarray


@njit(cache=True, inline="always")
def _score(f: FilterArrays, trust: np.ndarray, b: int, x0: np.ndarray, hvec: np.ndarray, c: np.ndarray) -> bool:
    """Apply ``trust[b]`` to episode b's pending update and write the step outputs; returns whether it goes on.

    A finished episode is updated too (its state is never scored again) but its outputs stay.
    """
    live = not f.done[b]
    for i in range(f.x.shape[1]):
        flops = update_uav(f.x[b, i], f.P[b, i], f.world_z[b, i], f.world_valid[b, i], trust[b, i], f.kind[i],
                           f.target[i], f.r0[i], f.anchors, f.landmarks, f.prior_pos[b], f.alpha_th, f.alpha_min,
                           f.active[b, i], x0, hvec, c)
        if live:
            f.flops[b, i] = flops
            for d in range(3):
                f.estimate[b, i, d] = f.x[b, i, d]
                f.truth[b, i, d] = f.world_pos[b, i, d]
            for l in range(f.kind.shape[1]):
                f.label[b, i, l] = f.world_label[b, i, l]
                f.update_valid[b, i, l] = f.world_valid[b, i, l]
                f.prev_trust[b, i, l] = f.applied[b, i, l]
                f.applied[b, i, l] = trust[b, i, l]
    if live:
        f.steps[b] += 1
        f.done[b] = f.steps[b] >= f.n_steps
    return not f.done[b]


@njit(cache=True, inline="always")
def _advance(w: WorldInputs | None, fs: FaultSchedule | None, f: FilterArrays, b: int, yv: np.ndarray,
             S: np.ndarray) -> None:
    """Sense episode b's next step (unless ``w`` is None), predict every UAV to it, write its features."""
    n = f.x.shape[1]
    if w is not None:
        for i in range(n):
            for d in range(3):
                f.imu_prev[b, i, d] = f.world_imu[b, i, d]
        sense_episode(w, fs, b)
    q = f.imu_sigma * f.imu_sigma
    for i in range(n):
        predict_uav(f.x[b, i], f.P[b, i], f.world_imu[b, i], f.dt, q)
        for d in range(3):
            f.prior_pos[b, i, d] = f.x[b, i, d]
    # features after every UAV has predicted: peer channels read the neighbours' priors
    for i in range(n):
        features_uav(f.x[b, i], f.P[b, i], f.world_z[b, i], f.world_valid[b, i], f.kind[i], f.target[i], f.r0[i],
                     f.anchors, f.landmarks, f.prior_pos[b], f.resid[b, i], f.pred[b, i], f.nis[b, i], yv, S)
        # jerk = ‖u(k+1) − u(k)‖
        j0 = f.world_imu[b, i, 0] - f.imu_prev[b, i, 0]
        j1 = f.world_imu[b, i, 1] - f.imu_prev[b, i, 1]
        j2 = f.world_imu[b, i, 2] - f.imu_prev[b, i, 2]
        f.jerk[b, i] = math.sqrt(j0 * j0 + j1 * j1 + j2 * j2)
        for l in range(f.kind.shape[1]):
            f.valid[b, i, l] = f.world_valid[b, i, l]


@njit(cache=True)
def step_episodes(w: WorldInputs | None, fs: FaultSchedule | None, f: FilterArrays, trust: np.ndarray, score: bool,
                  advance: np.ndarray, lo: int, hi: int) -> None:
    """One step of episodes lo..hi−1 on the calling thread (arguments as ``core_step``)."""
    x0, hvec, c, yv, S = np.empty(6), np.empty(3), np.empty(6), np.empty(3), np.empty((3, 3))
    for b in range(lo, hi):
        go = advance[b]
        if score:
            go = _score(f, trust, b, x0, hvec, c) and go
        if go:
            _advance(w, fs, f, b, yv, S)


@njit(cache=True, parallel=True)
def core_step(w: WorldInputs | None, fs: FaultSchedule | None, f: FilterArrays, trust: np.ndarray, score: bool,
              advance: np.ndarray) -> None:
    """One step of every episode, threads over blocks of episodes.

    Args:
        w, fs: the world kernel's inputs and fault schedule (None: the world has already
            sensed, in Python).
        f: the filter state and step outputs.
        trust: ``(B, N, L)`` trust α of the pending update (read only when ``score``).
        score: apply ``trust`` and score the pending update first; then the episodes that
            are not done advance.
        advance: ``(B,)`` bool, the episodes allowed to advance.
    """
    n_b = advance.shape[0]
    for block in prange((n_b + BLOCK - 1) // BLOCK):
        lo, hi = block_bounds(block, n_b)
        step_episodes(w, fs, f, trust, score, advance, lo, hi)
