"""Readable float64 reference of the information bound (posterior Cramér–Rao bound).

The same maths as ``bound.py`` written as a direct transcription of the recursion of
Tichavský, Muravchik and Nehorai (1998) for a linear-Gaussian dynamic model with
nonlinear measurements, over the joint state of the swarm, UAV-major:
x = [p_1, v_1, …, p_N, v_N] (6N):

    J₀ = P₀⁻¹
    J_k = (Q + F J_{k−1}⁻¹ Fᵀ)⁻¹ + Σ_c H_cᵀ R_c⁻¹ H_c

F and Q are the CEKF's IMU-driven constant-acceleration model (``cekf_reference.transition``)
per UAV, block diagonal over the swarm; H_c is the Jacobian of channel c at the TRUE
positions over the joint state (a peer channel has a block for the receiver and one for
the neighbour); R_c the channel's nominal noise. Only the channels in ``use`` (present and
not labelled faulty) enter. The bound of UAV i at step k is tr[J_k⁻¹] over its position
block. Slow (dense 6N × 6N inverses, Python loops) and meant as the oracle the fast path is
tested against.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from swarmloc.envs.filter.bound import BoundInputs, Pcrlb
from swarmloc.envs.filter.cekf_reference import measurement_rows, transition
from swarmloc.envs.tasks.channels import PEER, PEER_REL


def joint_model(n_uav: int, dt: float, imu_sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """F and Q of the swarm ``(6N, 6N)``: the per-UAV CEKF model, block diagonal."""
    F1, G1 = transition(dt)
    # Q = σ_imu² G Gᵀ (cekf_reference.predict_reference)
    Q1 = imu_sigma**2 * G1 @ G1.T
    F = scipy.linalg.block_diag(*[F1] * n_uav)
    Q = scipy.linalg.block_diag(*[Q1] * n_uav)
    return F, Q


def channel_jacobian(i: int, kind: int, target: int, pos: np.ndarray, anchors: np.ndarray,
                     landmarks: np.ndarray) -> np.ndarray | None:
    """Jacobian ``(rows, 6N)`` of UAV i's channel at the true positions ``pos`` ``(N, 3)``.

    The receiver's block is the CEKF's own measurement Jacobian (``cekf_reference.measurement_rows``
    with the neighbour at its true position). A peer range ‖p_i − p_j‖ and a relative position
    p_j − p_i depend on the neighbour as −(receiver block): the neighbour's block is its negative.
    Returns None for a degenerate range (zero distance), which the CEKF skips too.
    """
    n = pos.shape[0]
    x_i = np.concatenate([pos[i], np.zeros(3)])
    rows = measurement_rows(x_i, np.zeros(3), kind, target, anchors, landmarks, pos)
    if rows is None:
        return None
    _, H_i = rows
    H = np.zeros((H_i.shape[0], 6 * n))
    H[:, 6 * i:6 * i + 6] = H_i
    if kind in (PEER, PEER_REL):
        H[:, 6 * target:6 * target + 3] = -H_i[:, :3]
    return H


def measurement_information(pos: np.ndarray, use: np.ndarray, kind: np.ndarray, target: np.ndarray,
                            r0: np.ndarray, anchors: np.ndarray, landmarks: np.ndarray) -> np.ndarray:
    """Σ_c H_cᵀ R_c⁻¹ H_c ``(6N, 6N)`` of one step.

    Args:
        pos: ``(N, 3)`` true positions; use: ``(N, L)`` channels that enter.
        kind, target, r0: ``(N, L)`` channel layout and nominal variances.
        anchors: ``(A, 3)``; landmarks: ``(M, 3)``.
    """
    n, n_l = kind.shape
    info = np.zeros((6 * n, 6 * n))
    for i in range(n):
        for l in range(n_l):
            if not use[i, l]:
                continue
            H = channel_jacobian(i, int(kind[i, l]), int(target[i, l]), pos, anchors, landmarks)
            if H is None:
                continue
            # Hᵀ R⁻¹ H with R = r0·I (independent rows of equal nominal variance)
            info += H.T @ H / r0[i, l]
    return info


def pcrlb_reference(inputs: BoundInputs) -> Pcrlb:
    """The bound of every UAV at every step (same contract as ``bound.pcrlb``).

    Returns:
        ``Pcrlb``: pos_var ``(T, B, N)`` = tr[J_k⁻¹] over each UAV's position block, and
        failed_at ``(B,)``: the first step whose J is not positive definite (−1: none; that
        episode's pos_var is NaN from there on).
    """
    w = inputs
    n_t, n_b, n = w.pos.shape[:3]
    F, Q = joint_model(n, w.dt, w.imu_sigma)
    J0 = np.diag(np.tile(1.0 / np.asarray(w.p0_diag), n))  # J₀ = P₀⁻¹ (P₀ diagonal)
    pos_var = np.full((n_t, n_b, n), np.nan)
    failed_at = np.full(n_b, -1, dtype=np.int64)
    for b in range(n_b):
        J = J0.copy()
        for k in range(n_t):
            # J_k = (Q + F J_{k−1}⁻¹ Fᵀ)⁻¹ + Σ_c H_cᵀ R_c⁻¹ H_c  (literal inverses: this is the reference)
            J = np.linalg.inv(Q + F @ np.linalg.inv(J) @ F.T) + measurement_information(
                w.pos[k, b], w.use[k, b], w.kind, w.target, w.r0, w.anchors, w.landmarks)
            J = 0.5 * (J + J.T)
            try:
                np.linalg.cholesky(J)
            except np.linalg.LinAlgError:
                failed_at[b] = k
                break
            C = np.linalg.inv(J)
            for i in range(n):
                pos_var[k, b, i] = np.trace(C[6 * i:6 * i + 3, 6 * i:6 * i + 3])
    return Pcrlb(pos_var=pos_var, failed_at=failed_at)
