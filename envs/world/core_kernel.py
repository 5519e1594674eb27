"""The link-trust core's step as one kernel: score the pending update, then sense, predict
and featurize the next step.

``FilterArrays`` names the CEKF state and the ``CoreStep`` outputs. ``step_episodes`` steps
a range of episodes; ``core_step`` steps the batch in one call on the calling thread and
``core_step_threaded`` with threads over blocks of episodes (``step_kernel`` picks one by
batch size); both take their named tuples through a ``StepHandle``. Per episode b, with trust α (scoring):

1. posterior at the pending step k: the trust-weighted joint update (``cekf.update_uav``);
   estimate, truth, labels, validity, trust and FLOPs of the update are written out; the
   episode counts one more update and is done after ``n_steps``;
2. if it goes on: the world senses step k+1 (``sim_kernel.sense_episodes``; skipped when
   the world inputs are None, for worlds that sense in Python), every UAV predicts to it
   (``cekf.predict_uav``) and the per-channel innovation features at the prior are
   computed (``cekf.features_uav``), with the IMU jerk ‖u(k+1) − u(k)‖, and the pending
   measurements' error labels from the truth, the world's systematic errors and the priors
   (``labels.channel_sigmas``: a peer link carries its neighbour's broadcast-estimate error).

Without scoring (after a reset) only step 2 runs, for the episodes in ``advance``. Every
episode goes through the same operations, in the same order, as with the separate batch
kernels (``cekf_update``, ``cekf_predict``, ``channel_features``): the results are
bit-identical, only fused.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np
from numba import njit, prange
from numba.core import types
from numba.experimental import structref

from swarmloc.envs.filter.cekf import features_uav, predict_covariance, predict_uav, update_uav
from swarmloc.envs.world.faults import FaultSchedule
from swarmloc.envs.world.labels import channel_sigmas
from swarmloc.envs.world.sim_kernel import BLOCK, SERIAL_BELOW, WorldInputs, block_bounds, sense_episodes


class FilterArrays(NamedTuple):
    """The CEKF backbone and the step outputs of B episodes (``step_episodes``' third argument).

    Shapes: B episodes, N UAVs, L channel slots per UAV, A anchors, M landmarks.

    Task (constant):
        dt: step length [s]; imu_sigma: accelerometer noise σ [m/s²] (Q = σ² G Gᵀ).
        alpha_th: trust at or below which a channel is left out of the update;
            alpha_min: floor of α in R = R0 / max(α, α_min).
        n_steps: updates per episode.
        peer_cov: a peer channel's NIS includes the neighbour's broadcast covariance
            (``TaskSpec.peer_nis_neighbour_cov``: v1 tasks; v0 keeps S = H P_i Hᵀ + R0).
        peer_update: ``cekf.PEER_UPDATE_CODES`` of ``FilterSettings.peer_update`` (0: the
            neighbour as a known point; 1: covariance intersection; 2: split covariance
            intersection of all peers together, ``split_ci.py``).
        kind, target, r0: ``(N, L)`` channel kind, target index and nominal variance R0 [m²];
            sigma ``(N, L)`` the nominal σ [m] (the error labels divide by it, as the world does).
        label_threshold: ``(N, L)`` error-label threshold on the systematic error in σ_eff.
        anchors: ``(A, 3)``; landmarks ``(M, 3)`` [m].

    The world's step buffers (views; the world writes them):
        world_pos: ``(B, N, 3)`` truth; world_imu ``(B, N, 3)`` IMU reading [m/s²].
        world_z: ``(B, N, L, 3)`` measurements; world_valid, world_label ``(B, N, L)`` bool.
        world_systematic: ``(B, N, L, 3)`` the measurements' own signed systematic error [m].

    Filter state:
        x: ``(B, N, 6)`` mean [p, v]; P ``(B, N, 6, 6)`` covariance (the prior at the pending step).
        split_w: ``(B, N, L + 1)`` under ``"split_ci"``: the weights of every UAV's previous peer update
            (``split_ci.split_ci_peers``; zeros after a reset); ``(0, 0, 1)`` (never read) otherwise.
        P_ind: ``(B, N, 6, 6)`` the independent part of P under ``"split_ci"``; ``(0, 0, 6, 6)``
            (never read) under the other updates.
        prior_pos: ``(B, N, 3)`` the broadcast prior positions (peer channels linearise at them).
        imu_prev: ``(B, N, 3)`` IMU reading of the step before the pending one (for the jerk).

    Privileged (error labels of the pending measurements; never an observation):
        pending_sigmas: ``(B, N, L)`` systematic error in units of σ_eff (0 where absent).
        pending_error_label: ``(B, N, L)`` bool, present and ``pending_sigmas > label_threshold``.

    Step outputs (the ``CoreStep`` arrays, same names and shapes):
        resid, pred, nis, valid: ``(B, N, L)`` features of the pending update.
        jerk: ``(B, N)``.
        estimate, truth: ``(B, N, 3)``; label, error_label, update_valid, applied, prev_trust,
        active ``(B, N, L)``; flops ``(B, N)`` of the last update.
        steps: ``(B,)`` int64 updates done; done ``(B,)`` bool.

    Work array:
        moving: ``(B,)`` bool, the episodes that advance in the current call.
    """

    dt: float
    imu_sigma: float
    alpha_th: float
    alpha_min: float
    n_steps: int
    peer_cov: bool
    peer_update: int
    kind: np.ndarray
    target: np.ndarray
    r0: np.ndarray
    sigma: np.ndarray
    label_threshold: np.ndarray
    anchors: np.ndarray
    landmarks: np.ndarray
    world_pos: np.ndarray
    world_imu: np.ndarray
    world_z: np.ndarray
    world_valid: np.ndarray
    world_label: np.ndarray
    world_systematic: np.ndarray
    x: np.ndarray
    P: np.ndarray
    P_ind: np.ndarray
    split_w: np.ndarray
    prior_pos: np.ndarray
    imu_prev: np.ndarray
    pending_sigmas: np.ndarray
    pending_error_label: np.ndarray
    resid: np.ndarray
    pred: np.ndarray
    nis: np.ndarray
    valid: np.ndarray
    jerk: np.ndarray
    estimate: np.ndarray
    truth: np.ndarray
    label: np.ndarray
    error_label: np.ndarray
    update_valid: np.ndarray
    applied: np.ndarray
    prev_trust: np.ndarray
    active: np.ndarray
    flops: np.ndarray
    steps: np.ndarray
    done: np.ndarray
    moving: np.ndarray


@njit(cache=True, error_model="numpy")
def step_episodes(w: WorldInputs | None, fs: FaultSchedule | None, f: FilterArrays, trust: np.ndarray, score: bool,
                  advance: np.ndarray, lo: int, hi: int) -> None:
    """One step of episodes lo..hi−1 on the calling thread.

    Args:
        w, fs: the world kernel's inputs and fault schedule (None: the world has already
            sensed, in Python).
        f: the filter state and step outputs.
        trust: ``(B, N, L)`` trust α of the pending update (read only when ``score``).
        score: apply ``trust`` and score the pending update first; then the episodes that
            are not done advance.
        advance: ``(B,)`` bool, the episodes allowed to advance.
        lo, hi: the episodes to step.

    The stages run over the whole range in turn (episodes do not interact, so the order is
    free): score, sense, predict and featurize.
    """
    n, n_l = f.kind.shape[0], f.kind.shape[1]
    x0, hvec, c, yv, S = np.empty(6), np.empty(3), np.empty(6), np.empty(3), np.empty((3, 3))
    prior_pp = np.empty((n, 3, 3))
    split = f.peer_update == 2
    # "split_ci": the broadcast priors' independent position parts and the update's scratch
    prior_ind_pp, work = np.empty((n, 3, 3)), np.empty((8, 6))
    # ---- score: posterior at the pending step; a finished episode is updated too (its
    # state is never scored again) but its outputs stay
    for b in range(lo, hi):
        f.moving[b] = advance[b]
        if not score:
            continue
        live = not f.done[b]
        if f.peer_update >= 1:  # the broadcast covariances, before any UAV updates ("ci", "split_ci" read them)
            for i in range(n):
                for d in range(3):
                    for e in range(3):
                        prior_pp[i, d, e] = f.P[b, i, d, e]
                        if split:
                            prior_ind_pp[i, d, e] = f.P_ind[b, i, d, e]
        for i in range(n):
            flops = update_uav(f.x[b, i], f.P[b, i], f.world_z[b, i], f.world_valid[b, i], trust[b, i], f.kind[i],
                               f.target[i], f.r0[i], f.anchors, f.landmarks, f.prior_pos[b], prior_pp,
                               f.peer_update, f.alpha_th,
                               f.alpha_min, f.active[b, i], x0, hvec, c, f.P_ind, b, i, prior_ind_pp, work,
                               f.split_w)
            if live:
                f.flops[b, i] = flops
                for d in range(3):
                    f.estimate[b, i, d] = f.x[b, i, d]
                    f.truth[b, i, d] = f.world_pos[b, i, d]
                for l in range(n_l):
                    f.label[b, i, l] = f.world_label[b, i, l]
                    f.error_label[b, i, l] = f.pending_error_label[b, i, l]
                    f.update_valid[b, i, l] = f.world_valid[b, i, l]
                    f.prev_trust[b, i, l] = f.applied[b, i, l]
                    f.applied[b, i, l] = trust[b, i, l]
        if live:
            f.steps[b] += 1
            f.done[b] = f.steps[b] >= f.n_steps
        f.moving[b] = advance[b] and not f.done[b]
    # ---- sense the next step
    if w is not None:
        for b in range(lo, hi):
            if f.moving[b]:
                for i in range(n):
                    for d in range(3):
                        f.imu_prev[b, i, d] = f.world_imu[b, i, d]
        sense_episodes(w, fs, f.moving, lo, hi)
    # ---- predict to it, then the features and error labels (peer channels read the neighbours' priors)
    q = f.imu_sigma * f.imu_sigma
    for b in range(lo, hi):
        if not f.moving[b]:
            continue
        for i in range(n):
            predict_uav(f.x[b, i], f.P[b, i], f.world_imu[b, i], f.dt, q)
            if split:
                predict_covariance(f.P_ind[b, i], f.dt, q)
            for d in range(3):
                f.prior_pos[b, i, d] = f.x[b, i, d]
        pos_b, prior_b, P_b = f.world_pos[b], f.prior_pos[b], f.P[b]
        for i in range(n):
            features_uav(f.x[b, i], f.P[b, i], f.world_z[b, i], f.world_valid[b, i], f.kind[i], f.target[i],
                         f.r0[i], f.anchors, f.landmarks, f.prior_pos[b], P_b, f.peer_cov, f.resid[b, i],
                         f.pred[b, i], f.nis[b, i], yv, S)
            # jerk = ‖u(k+1) − u(k)‖
            j0 = f.world_imu[b, i, 0] - f.imu_prev[b, i, 0]
            j1 = f.world_imu[b, i, 1] - f.imu_prev[b, i, 1]
            j2 = f.world_imu[b, i, 2] - f.imu_prev[b, i, 2]
            f.jerk[b, i] = math.sqrt(j0 * j0 + j1 * j1 + j2 * j2)
            for l in range(n_l):
                f.valid[b, i, l] = f.world_valid[b, i, l]
                sig = 0.0
                if f.world_valid[b, i, l]:
                    e = f.world_systematic
                    sig = channel_sigmas(f.kind[i, l], f.target[i, l], f.sigma[i, l], e[b, i, l, 0], e[b, i, l, 1],
                                         e[b, i, l, 2], pos_b, prior_b, P_b, i)
                f.pending_sigmas[b, i, l] = sig
                f.pending_error_label[b, i, l] = f.world_valid[b, i, l] and sig > f.label_threshold[i, l]


@structref.register
class StepHandleType(types.StructRef):
    """numba type of a ``StepHandle``."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class StepHandle(structref.StructRefProxy):
    """The step kernel's named tuples in one object: ``world``, ``faults``, ``filt``.

    numba unboxes every array of a call's arguments, about 70 here: some 10 µs, most of a
    one-episode step. A handle is one reference, built once per core (``make_handle``).
    """


structref.define_proxy(StepHandle, StepHandleType, ["world", "faults", "filt"])


@njit(cache=True)
def make_handle(w: WorldInputs | None, fs: FaultSchedule | None, f: FilterArrays) -> StepHandle:
    """Hold the kernel's named tuples in a ``StepHandle`` (compiled, so the constructor is cached)."""
    return StepHandle(w, fs, f)


@njit(cache=True, parallel=True, error_model="numpy")
def _step_blocks(w: WorldInputs | None, fs: FaultSchedule | None, f: FilterArrays, trust: np.ndarray, score: bool,
                 advance: np.ndarray) -> None:
    """``step_episodes`` over the batch, threads over blocks of ``BLOCK`` episodes."""
    n_b = advance.shape[0]
    for block in prange((n_b + BLOCK - 1) // BLOCK):
        lo, hi = block_bounds(block, n_b)
        step_episodes(w, fs, f, trust, score, advance, lo, hi)


@njit(cache=True, error_model="numpy")
def core_step(h: StepHandle, trust: np.ndarray, score: bool, advance: np.ndarray) -> None:
    """One step of every episode, on the calling thread (``step_episodes`` over the batch).

    Args:
        h: the world inputs, fault schedule and filter arrays.
        trust, score, advance: as in ``step_episodes``.
    """
    step_episodes(h.world, h.faults, h.filt, trust, score, advance, 0, advance.shape[0])


@njit(cache=True, error_model="numpy")
def core_step_threaded(h: StepHandle, trust: np.ndarray, score: bool, advance: np.ndarray) -> None:
    """``core_step`` with threads over blocks of ``BLOCK`` episodes (``_step_blocks``)."""
    _step_blocks(h.world, h.faults, h.filt, trust, score, advance)


def step_kernel(batch_size: int) -> Callable[..., None]:
    """The step kernel for a batch: ``core_step`` below ``SERIAL_BELOW`` episodes, else
    ``core_step_threaded``.

    Two kernels chosen once per core, rather than one that branches on the batch size, so
    that a process that only steps small batches never compiles the threaded one: its
    parallel lowering is most of the cold compilation of the step (about 130 s of 185 s).
    """
    return core_step if batch_size < SERIAL_BELOW else core_step_threaded
