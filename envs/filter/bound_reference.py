"""Readable float64 reference of the information bound (posterior Cramér–Rao bound).

The same maths as ``bound.py`` written as a direct transcription of the recursion of
Tichavský, Muravchik and Nehorai (1998) for a linear-Gaussian dynamic model with nonlinear
measurements, over the joint state of the swarm, UAV-major: x = [x_1, …, x_N] with
x_i = [p_i, v_i, (b_i), (f_i)] (6, 9 or 12 states: the accelerometer bias b where the task
draws one, the IMU-fault bias f where an episode has an IMU fault):

    J₀ = P₀⁻¹
    C_k⁻ = Q_k + F_k J_{k−1}⁻¹ F_kᵀ
    J_k = (C_k⁻)⁻¹ + Σ_c E_{x ~ N(x_k, C_k⁻)}[H_c(x)ᵀ R_c⁻¹ H_c(x)]

F_k, Q_k per UAV (``uav_model``): the CEKF's IMU-driven constant-acceleration model
(``cekf_reference.transition``) with the biases integrated like the acceleration they corrupt,
f redrawn at a fault's onset. H_c is the Jacobian of channel c over the joint state (a peer
channel has a block for the receiver and one for the neighbour); the expectation is over the
positions, centred at the TRUE ones with the predicted covariance, by the third-degree
cubature rule (``expected_information``); R_c the channel's nominal noise. Only the channels
in ``use`` (present and not labelled faulty) enter. The bound of UAV i at step k is
tr[J_k⁻¹] over its position block. Slow (dense inverses, Python loops) and meant as the
oracle the fast path is tested against.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from swarmloc.envs.filter.bound import BoundInputs, Pcrlb
from swarmloc.envs.filter.cekf_reference import measurement_rows, transition
from swarmloc.envs.tasks.channels import PEER, PEER_REL

#: the third-degree spherical-radial cubature rule of a 3-vector (Arasaratnam & Haykin 2009):
#: points x̄ ± √3 L e_c (L Lᵀ = Σ), weight 1/6 each
CUBATURE_UNIT = np.sqrt(3.0) * np.vstack([np.eye(3), -np.eye(3)])


def uav_model(dt: float, imu_sigma: float, has_bias: bool, has_fault: bool, fault_active: bool,
              fault_onset_var: float) -> tuple[np.ndarray, np.ndarray]:
    """One UAV's F and Q ``(s, s)`` at one step, s = 6 + 3·has_bias + 3·has_fault.

    The accelerometer reads u = a + b + f·[fault active] + n, n ~ N(0, σ_imu² I), so the motion
    integrates a = u − b − f − n: with G = [dt²/2·I; dt·I] (``cekf_reference.transition``),
    [p; v]⁺ = F₆ [p; v] − G (b + f + n), b⁺ = b, f⁺ = f. At a fault's onset f is first drawn
    afresh, f ~ N(0, σ_f² I) (the reset R: f's row of R zero, its noise σ_f² I), then the step
    moves with it: F = F_m R, Q = F_m Q_R F_mᵀ + Q_imu.
    """
    F6, G = transition(dt)
    s = 6 + 3 * has_bias + 3 * has_fault
    F = np.eye(s)
    Q = np.zeros((s, s))
    F[:6, :6] = F6
    Q[:6, :6] = imu_sigma**2 * G @ G.T  # Q = σ_imu² G Gᵀ (cekf_reference.predict_reference)
    col = 6
    if has_bias:
        F[:6, col:col + 3] = -G
        col += 3
    if has_fault:
        if fault_active:
            F[:6, col:col + 3] = -G
        if fault_onset_var > 0:
            R, Q_R = np.eye(s), np.zeros((s, s))
            R[col:col + 3, col:col + 3] = 0.0
            Q_R[col:col + 3, col:col + 3] = fault_onset_var * np.eye(3)
            F, Q = F @ R, F @ Q_R @ F.T + Q
    return F, Q


def joint_model(n_uav: int, dt: float, imu_sigma: float, has_bias: bool = False, has_fault: bool = False,
                fault_active: np.ndarray | None = None,
                fault_onset_var: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """F and Q of the swarm ``(sN, sN)``: ``uav_model`` per UAV, block diagonal."""
    active = np.zeros(n_uav, bool) if fault_active is None else fault_active
    onset = np.zeros(n_uav) if fault_onset_var is None else fault_onset_var
    blocks = [uav_model(dt, imu_sigma, has_bias, has_fault, bool(active[i]), float(onset[i])) for i in range(n_uav)]
    return scipy.linalg.block_diag(*[F for F, _ in blocks]), scipy.linalg.block_diag(*[Q for _, Q in blocks])


def channel_jacobian(i: int, kind: int, target: int, pos: np.ndarray, anchors: np.ndarray,
                     landmarks: np.ndarray, s: int = 6) -> np.ndarray | None:
    """Jacobian ``(rows, sN)`` of UAV i's channel at the positions ``pos`` ``(N, 3)`` (s states per UAV).

    The receiver's block is the CEKF's own measurement Jacobian (``cekf_reference.measurement_rows``
    with the neighbour at ``pos``). A peer range ‖p_i − p_j‖ and a relative position
    p_j − p_i depend on the neighbour as −(receiver block): the neighbour's block is its negative.
    Returns None for a degenerate range (zero distance), which the CEKF skips too.
    """
    n = pos.shape[0]
    x_i = np.concatenate([pos[i], np.zeros(3)])
    rows = measurement_rows(x_i, np.zeros(3), kind, target, anchors, landmarks, pos)
    if rows is None:
        return None
    _, H_i = rows
    H = np.zeros((H_i.shape[0], s * n))
    H[:, s * i:s * i + 6] = H_i
    if kind in (PEER, PEER_REL):
        H[:, s * target:s * target + 3] = -H_i[:, :3]
    return H


def expected_information(i: int, kind: int, target: int, pos: np.ndarray, C_pos: np.ndarray, anchors: np.ndarray,
                         landmarks: np.ndarray, s: int = 6) -> np.ndarray:
    """E[Hᵀ H] ``(sN, sN)`` of UAV i's channel over the positions p ~ N(pos, C_pos), by cubature.

    H depends on the positions through one 3-vector: p_i − p_j for a peer channel (the
    neighbour's position moves it the other way), p_i otherwise. Its covariance is
    Σ = T C_pos Tᵀ with T the selection (I at i, −I at j for a peer); the six cubature points
    move p_i by ±√3 L e_c (L = cholesky(Σ)), which moves that 3-vector by the same amount.
    """
    n = pos.shape[0]
    T = np.zeros((3, 3 * n))
    T[:, 3 * i:3 * i + 3] = np.eye(3)
    if kind in (PEER, PEER_REL):
        T[:, 3 * target:3 * target + 3] -= np.eye(3)
    L = np.linalg.cholesky(T @ C_pos @ T.T)
    info = np.zeros((s * n, s * n))
    for xi in CUBATURE_UNIT @ L.T:
        moved = pos.copy()
        moved[i] = pos[i] + xi
        H = channel_jacobian(i, kind, target, moved, anchors, landmarks, s)
        if H is not None:
            info += H.T @ H / len(CUBATURE_UNIT)
    return info


def measurement_information(pos: np.ndarray, use: np.ndarray, kind: np.ndarray, target: np.ndarray,
                            r0: np.ndarray, anchors: np.ndarray, landmarks: np.ndarray, C_pos: np.ndarray,
                            s: int = 6) -> np.ndarray:
    """Σ_c E[H_cᵀ R_c⁻¹ H_c] ``(sN, sN)`` of one step.

    Args:
        pos: ``(N, 3)`` true positions; use: ``(N, L)`` channels that enter.
        kind, target, r0: ``(N, L)`` channel layout and nominal variances.
        anchors: ``(A, 3)``; landmarks: ``(M, 3)``.
        C_pos: ``(3N, 3N)`` the predicted covariance of the positions (UAV-major).
        s: states per UAV.
    """
    n, n_l = kind.shape
    info = np.zeros((s * n, s * n))
    for i in range(n):
        for l in range(n_l):
            if use[i, l]:
                # Hᵀ R⁻¹ H with R = r0·I (independent rows of equal nominal variance)
                info += expected_information(i, int(kind[i, l]), int(target[i, l]), pos, C_pos, anchors,
                                             landmarks, s) / r0[i, l]
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
    has_bias, has_fault = w.bias_sigma > 0, bool((np.asarray(w.fault_var) > 0).any())
    s = 6 + 3 * has_bias + 3 * has_fault
    # P₀ per UAV: the filter's diagonal, the bias prior σ_b² I; f is redrawn at each onset (any variance before)
    p0 = np.concatenate([w.p0_diag, [w.bias_sigma**2] * 3 * has_bias, [1.0] * 3 * has_fault])
    J0 = np.diag(np.tile(1.0 / p0, n))  # J₀ = P₀⁻¹
    pos_idx = np.concatenate([np.arange(s * i, s * i + 3) for i in range(n)])
    pos_var = np.full((n_t, n_b, n), np.nan)
    failed_at = np.full(n_b, -1, dtype=np.int64)
    for b in range(n_b):
        J = J0.copy()
        fv = np.asarray(w.fault_var[:, b], dtype=float)
        for k in range(n_t):
            onset = np.where((fv[k] > 0) & ((fv[k - 1] != fv[k]) if k > 0 else True), fv[k], 0.0)
            F, Q = joint_model(n, w.dt, w.imu_sigma, has_bias, has_fault, fv[k] > 0, onset)
            # C⁻ = Q + F J_{k−1}⁻¹ Fᵀ;  J_k = (C⁻)⁻¹ + Σ_c E[H_cᵀ R_c⁻¹ H_c]  (literal inverses: this is the reference)
            C_prior = predicted_covariance(J, F, Q)
            J = np.linalg.inv(C_prior) + measurement_information(
                w.pos[k, b], w.use[k, b], w.kind, w.target, w.r0, w.anchors, w.landmarks,
                C_prior[np.ix_(pos_idx, pos_idx)], s)
            J = 0.5 * (J + J.T)
            var = position_variances(J, n, s)
            if var is None:
                failed_at[b] = k
                break
            pos_var[k, b] = var
    return Pcrlb(pos_var=pos_var, failed_at=failed_at)


def predicted_covariance(J: np.ndarray, F: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """C⁻ = Q + F J⁻¹ Fᵀ, symmetrized (one prediction of the recursion)."""
    C = Q + F @ np.linalg.inv(J) @ F.T
    return 0.5 * (C + C.T)


def position_variances(J: np.ndarray, n: int, s: int) -> np.ndarray | None:
    """tr[J⁻¹] over each of the N UAVs' position blocks (s states per UAV, UAV-major, first in the state) of a
    symmetric J; None where J is not positive definite."""
    try:
        np.linalg.cholesky(J)
    except np.linalg.LinAlgError:
        return None
    C = np.linalg.inv(J)
    return np.array([np.trace(C[s * i:s * i + 3, s * i:s * i + 3]) for i in range(n)])
