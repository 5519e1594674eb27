"""Readable pure-numpy float64 reference of the CEKF backbone.

The same maths as ``cekf.py`` written the textbook way: dense F, G, Q; one joint update
with a stacked Jacobian H, S = H P Hᵀ + R, K = P Hᵀ S⁻¹ and the Joseph-form covariance
update. Slow (Python loops over episodes and UAVs) and meant as the oracle the fused
kernel is tested against.
"""

from __future__ import annotations

import numpy as np

from swarmloc.envs.tasks.channels import ANCHOR, GPS, LANDMARK, PEER, PEER_REL, TDOA, tdoa_pair


def transition(dt: float) -> tuple[np.ndarray, np.ndarray]:
    """F = [[I, dt·I], [0, I]] and G = [dt²/2·I; dt·I] of the constant-acceleration model."""
    eye = np.eye(3)
    F = np.block([[eye, dt * eye], [np.zeros((3, 3)), eye]])
    G = np.vstack([0.5 * dt * dt * eye, dt * eye])
    return F, G


def predict_reference(x: np.ndarray, P: np.ndarray, u: np.ndarray, dt: float, imu_sigma: float):
    """One UAV's prediction. Returns (x⁻, P⁻)."""
    F, G = transition(dt)
    # Q = σ_imu² G Gᵀ
    Q = imu_sigma**2 * G @ G.T
    # x⁻ = F x + G u
    x_prior = F @ x + G @ u
    # P⁻ = F P Fᵀ + Q
    P_prior = F @ P @ F.T + Q
    return x_prior, P_prior


def measurement_rows(x: np.ndarray, z: np.ndarray, kind: int, target: int, anchors: np.ndarray,
                     landmarks: np.ndarray, prior_pos: np.ndarray):
    """Innovation rows of one channel at the prior: (y, H) with y = z − h(x⁻), H = ∂h/∂x.

    Returns None for a degenerate range (zero distance to an anchor, a peer or a TDOA anchor).
    """
    p = x[:3]
    if kind in (ANCHOR, PEER):
        q = anchors[target] if kind == ANCHOR else prior_pos[target]
        # h = ‖p − q‖, H = (p − q)ᵀ/‖p − q‖ on the position block
        rng = np.linalg.norm(p - q)
        if rng < 1e-9:
            return None
        H = np.zeros((1, 6))
        H[0, :3] = (p - q) / rng
        return np.array([z[0] - rng]), H
    if kind == TDOA:
        i, j = tdoa_pair(target, len(anchors))
        # h = ‖p − a_j‖ − ‖p − a_i‖, H = (p − a_j)ᵀ/‖p − a_j‖ − (p − a_i)ᵀ/‖p − a_i‖
        r_j, r_i = np.linalg.norm(p - anchors[j]), np.linalg.norm(p - anchors[i])
        if r_j < 1e-9 or r_i < 1e-9:
            return None
        H = np.zeros((1, 6))
        H[0, :3] = (p - anchors[j]) / r_j - (p - anchors[i]) / r_i
        return np.array([z[0] - (r_j - r_i)]), H
    H = np.zeros((3, 6))
    if kind == GPS:
        # h = p, H = [I 0]
        H[:, :3] = np.eye(3)
        return z - p, H
    # landmark / relative position: h = q − p, H = [−I 0]
    q = landmarks[target] if kind == LANDMARK else prior_pos[target]
    H[:, :3] = -np.eye(3)
    return z - (q - p), H


def ci_peer_update(x: np.ndarray, P: np.ndarray, y: np.ndarray, H: np.ndarray, B: np.ndarray, r: float,
                   grid: int = 50) -> tuple[np.ndarray, np.ndarray, float]:
    """Covariance intersection of one peer channel (Julier and Uhlmann 1997; ``cekf`` docstring).

    The joint prior of (x_i, p_j) is bounded by blockdiag(P/ω, B/(1 − ω)) for the unknown
    correlation, so the channel updates x_i with S = H (P/ω) Hᵀ + J B Jᵀ/(1 − ω) + r I,
    J = ∂h/∂p_j = ±H_pos. ω minimises tr of the posterior's position block over
    {1/grid, …, (grid − 1)/grid} and ω = 1, which is no update.

    Args:
        x, P: the UAV's current mean and covariance.
        y: ``(m,)`` innovation at the current mean; H: ``(m, 6)`` its Jacobian in x_i.
        B: ``(3, 3)`` the neighbour's broadcast position covariance; r: the rows' variance.

    Returns:
        (x⁺, P⁺, ω).
    """
    Hp = H[:, :3]
    R = np.eye(len(y)) * r

    def posterior(w: float) -> tuple[np.ndarray, np.ndarray]:
        A = P / w
        R_eff = Hp @ B @ Hp.T / (1.0 - w) + R
        S = H @ A @ H.T + R_eff
        K = np.linalg.solve(S, H @ A).T
        I_KH = np.eye(6) - K @ H
        return x + K @ y, I_KH @ A @ I_KH.T + K @ R_eff @ K.T

    best_w, best = 1.0, np.trace(P[:3, :3])
    for k in range(1, grid):
        w = k / grid
        value = np.trace(posterior(w)[1][:3, :3])
        if value < best:
            best_w, best = w, value
    if best_w == 1.0:
        return x.copy(), P.copy(), 1.0
    x_post, P_post = posterior(best_w)
    return x_post, P_post, best_w


def update_reference(x: np.ndarray, P: np.ndarray, z: np.ndarray, valid: np.ndarray, alpha: np.ndarray,
                     kind: np.ndarray, target: np.ndarray, r0: np.ndarray, anchors: np.ndarray,
                     landmarks: np.ndarray, prior_pos: np.ndarray, alpha_th: float, alpha_min: float,
                     prior_cov: np.ndarray | None = None, peer_update: str = "point"):
    """One UAV's trust-weighted joint update. Returns (x⁺, P⁺, active (L,) bool).

    ``peer_update = "ci"`` (``prior_cov`` ``(N, 6, 6)`` the broadcast covariances): the joint
    update of the absolute channels, then each peer channel by :func:`ci_peer_update`, in
    channel order, linearised at the prior like the others.
    """
    if peer_update not in ("point", "ci"):
        raise ValueError(f"peer_update must be 'point' or 'ci', got {peer_update!r}")
    if peer_update == "ci" and prior_cov is None:
        raise ValueError("peer_update='ci' needs prior_cov, the (N, 6, 6) broadcast covariances")
    peers = np.isin(kind, (PEER, PEER_REL)) if peer_update == "ci" else np.zeros(len(kind), dtype=bool)
    x_post, P_post, active = _joint_update(x, P, z, valid & ~peers, alpha, kind, target, r0, anchors, landmarks,
                                           prior_pos, alpha_th, alpha_min)
    for l in np.flatnonzero(peers & valid & (alpha > alpha_th)):
        rows = measurement_rows(x, z[l], int(kind[l]), int(target[l]), anchors, landmarks, prior_pos)
        if rows is None:
            continue
        y, H = rows
        # linearised at the prior x: y − H (x_post − x) is the innovation at the current mean
        y = y - H @ (x_post - x)
        B = prior_cov[int(target[l]), :3, :3]
        x_post, P_post, _ = ci_peer_update(x_post, P_post, y, H, B, r0[l] / max(alpha[l], alpha_min))
        active[l] = True
    return x_post, P_post, active


def _joint_update(x: np.ndarray, P: np.ndarray, z: np.ndarray, valid: np.ndarray, alpha: np.ndarray,
                  kind: np.ndarray, target: np.ndarray, r0: np.ndarray, anchors: np.ndarray,
                  landmarks: np.ndarray, prior_pos: np.ndarray, alpha_th: float, alpha_min: float):
    """The joint update of the channels in ``valid`` with α > α_th. Returns (x⁺, P⁺, active)."""
    ys, Hs, Rs = [], [], []
    active = np.zeros(len(kind), dtype=bool)
    for l in range(len(kind)):
        # channels with α ≤ α_th (or no measurement) are skipped
        if not valid[l] or alpha[l] <= alpha_th:
            continue
        rows = measurement_rows(x, z[l], int(kind[l]), int(target[l]), anchors, landmarks, prior_pos)
        if rows is None:
            continue
        y, H = rows
        # R_j = R0_j / max(α_j, α_min)
        r = r0[l] / max(alpha[l], alpha_min)
        ys.append(y)
        Hs.append(H)
        Rs.extend([r] * len(y))
        active[l] = True
    if not ys:
        return x.copy(), P.copy(), active
    y = np.concatenate(ys)
    H = np.vstack(Hs)
    R = np.diag(Rs)
    # S = H P Hᵀ + R
    S = H @ P @ H.T + R
    # K = P Hᵀ S⁻¹ (solve, not invert)
    K = np.linalg.solve(S, H @ P).T
    # x⁺ = x⁻ + K y
    x_post = x + K @ y
    # P⁺ = (I − K H) P (I − K H)ᵀ + K R Kᵀ  (Joseph form: symmetric, positive by construction)
    I_KH = np.eye(6) - K @ H
    P_post = I_KH @ P @ I_KH.T + K @ R @ K.T
    return x_post, P_post, active


def run_reference(x: np.ndarray, P: np.ndarray, imu: np.ndarray, z: np.ndarray, valid: np.ndarray,
                  alpha: np.ndarray, kind: np.ndarray, target: np.ndarray, r0: np.ndarray, anchors: np.ndarray,
                  landmarks: np.ndarray, dt: float, imu_sigma: float, alpha_th: float, alpha_min: float,
                  peer_update: str = "point"):
    """Filter whole sequences (same contract as ``cekf.cekf_run``). Returns (est (T,B,N,3), x, P)."""
    x, P = x.copy(), P.copy()
    n_t, n_b, n = z.shape[:3]
    est = np.zeros((n_t, n_b, n, 3))
    for t in range(n_t):
        for b in range(n_b):
            for i in range(n):
                x[b, i], P[b, i] = predict_reference(x[b, i], P[b, i], imu[t, b, i], dt, imu_sigma)
            prior_pos, prior_cov = x[b, :, :3].copy(), P[b].copy()
            for i in range(n):
                x[b, i], P[b, i], _ = update_reference(
                    x[b, i], P[b, i], z[t, b, i], valid[t, b, i], alpha[t, b, i], kind[i], target[i], r0[i],
                    anchors, landmarks, prior_pos, alpha_th, alpha_min, prior_cov, peer_update)
            est[t, b] = x[b, :, :3]
    return est, x, P
