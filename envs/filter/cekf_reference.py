"""Readable pure-numpy float64 reference of the CEKF backbone.

The same maths as ``cekf.py`` written the textbook way: dense F, G, Q; one joint update
with a stacked Jacobian H, S = H P Hᵀ + R, K = P Hᵀ S⁻¹ and the Joseph-form covariance
update. Slow (Python loops over episodes and UAVs) and meant as the oracle the fused
kernel is tested against. The peer updates ``"ci"`` (``ci_peer_update``) and ``"split_ci"``
(``split_ci_update_reference``, ``split_ci_peer_update``: the equations in ``split_ci.py``)
are written out the same way: stacked rows, dense matrices, the ω search over whole posteriors.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from swarmloc.envs.filter.constants import (OMEGA_FLOOR, SPLIT_CI_DEPENDENT_FLOOR, SPLIT_CI_GRID, SPLIT_CI_STEPS,
                                            SPLIT_CI_WARM_MIX, SPLIT_CI_WARM_STEPS)
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


class PeerRows(NamedTuple):
    """One peer channel as the split covariance intersection sees it (``split_ci_peer_update``)."""

    #: ``(m,)`` innovation at the UAV's current mean, linearised at its prior
    y: np.ndarray
    #: ``(m, 6)`` Jacobian in the UAV's state
    H: np.ndarray
    #: ``(m, 3)`` Jacobian in the neighbour's position (a range: −uᵀ; a relative position: I)
    J: np.ndarray
    #: ``(3, 3)`` the neighbour's broadcast position covariance: its dependent part D_j …
    D: np.ndarray
    #: … and its independent part N_j
    N: np.ndarray
    #: the rows' variance R0 / max(α, α_min)
    r: float
    #: the channel's index among the UAV's L (where its weight of the previous update is kept)
    slot: int = 0


def split_ci_peer_update(x: np.ndarray, P: np.ndarray, N_old: np.ndarray, N_new: np.ndarray,
                         peers: Sequence[PeerRows], grid: int = SPLIT_CI_GRID, steps: int = SPLIT_CI_STEPS,
                         previous: np.ndarray | None = None):
    """Split covariance intersection of all of a UAV's peer channels of a step (``split_ci`` docstring, steps 2–3).

    The dependent errors of the UAV (D = P − N_old − N_new) and of its neighbours (D_j) are bounded
    by blockdiag(D/ω_0, D_1/ω_1, …) with Σ ω = 1, the independent parts add on the diagonal. The
    weights minimise tr P⁺ (the whole state): the best ω_0 on {1/grid, …, (grid − 1)/grid} with the
    neighbours sharing 1 − ω_0 in proportion to Δ_j (the trace reduction of each alone at full weight),
    then ``steps`` multiplicative steps; no update when the weights they reach do not lower tr P. Warm
    (``previous``, the UAV's weights of its previous update by channel slot, ω_0 first, with ω_0 > 0): the
    start is ω_0 = previous ω_0 and each peer (1 − λ) previous + λ (1 − ω_0) Δ share, normalised
    (λ = ``SPLIT_CI_WARM_MIX``), then ``SPLIT_CI_WARM_STEPS`` steps.

    Args:
        x, P: the UAV's mean and covariance after its absolute channels.
        N_old: ``(6, 6)`` the independent part its prior held, through the absolute update.
        N_new: ``(6, 6)`` the absolute update's own noise, K_a R_a K_aᵀ.
        peers: the peer channels, one per neighbour.
        grid, steps: the ω_0 grid and the multiplicative steps after it (a cold start).
        previous: ``(L + 1,)`` the previous update's weights (all 0 or None: a cold start).

    Returns:
        (x⁺, P⁺, N⁺, ω), N⁺ = (I − K H) N_new (I − K H)ᵀ + K R_own Kᵀ the posterior's independent part and
        ω ``(m + 1,)`` the weights the search reached (also when no update was better; without peers [1]).
    """
    no_update = (x.copy(), P.copy(), N_new.copy(), np.eye(len(peers) + 1)[0])
    if not peers:
        return no_update
    N_ind = N_old + N_new
    D = P - N_ind
    H = np.vstack([p.H for p in peers])
    y = np.concatenate([p.y for p in peers])
    # Δ_j = tr(P_pp H_jᵀ (H_j P H_jᵀ + J_j P_j J_jᵀ + r I)⁻¹ H_j P_pp), the neighbours' shares of 1 − ω_0
    delta = np.array([np.trace(P[:3, :] @ p.H.T @ np.linalg.solve(
        p.H @ P @ p.H.T + p.J @ (p.D + p.N) @ p.J.T + p.r * np.eye(len(p.y)), p.H @ P[:, :3])) for p in peers])
    share = delta / delta.sum()

    def weights(w: float) -> np.ndarray:
        return np.concatenate([[w], (1.0 - w) * share])

    if previous is not None and previous[0] > 0.0:
        # (1 − λ) × the previous weights + λ × (ω_0 = 1/2, the neighbours sharing the other half by Δ)
        start = np.concatenate([[(1.0 - SPLIT_CI_WARM_MIX) * previous[0] + 0.5 * SPLIT_CI_WARM_MIX],
                                [(1.0 - SPLIT_CI_WARM_MIX) * previous[p.slot + 1] + 0.5 * SPLIT_CI_WARM_MIX * s
                                 for p, s in zip(peers, share)]])
        omega = start / start.sum()
        steps = SPLIT_CI_WARM_STEPS
    else:
        best_w, best = 0.5, np.inf
        for k in range(1, grid):
            value = _fused_trace(P, N_ind, peers, weights(k / grid))[0]
            if value < best:
                best_w, best = k / grid, value
        omega = weights(best_w)
    for _ in range(steps):
        g = _fused_trace(P, N_ind, peers, omega)[1]
        if (omega * np.sqrt(g)).sum() > 0.0:
            # ω_k ← ω_k √g_k / Σ_l ω_l √g_l (at least OMEGA_FLOOR, renormalised)
            omega = np.maximum(omega * np.sqrt(g) / (omega * np.sqrt(g)).sum(), OMEGA_FLOOR)
            omega = omega / omega.sum()
    # any weights on the simplex give a consistent update: the last ones, unless no update is better
    if not _fused_trace(P, N_ind, peers, omega)[0] < np.trace(P):
        return (*no_update[:3], omega)
    # P1 = D/ω_0 + N; R = blockdiag(J_j (D_j/ω_j + N_j) J_jᵀ + r_j I)
    prior = D / omega[0] + N_ind
    R = _block_diag([_dependent(p) / om + p.J @ p.N @ p.J.T + p.r * np.eye(len(p.y))
                     for p, om in zip(peers, omega[1:])])
    R_own = _block_diag([p.r * np.eye(len(p.y)) for p in peers])
    # S = H P1 Hᵀ + R, K = P1 Hᵀ S⁻¹
    S = H @ prior @ H.T + R
    K = np.linalg.solve(S, H @ prior).T
    I_KH = np.eye(6) - K @ H
    # Joseph form for P⁺; the own noise alone for N⁺
    return x + K @ y, I_KH @ prior @ I_KH.T + K @ R @ K.T, I_KH @ N_new @ I_KH.T + K @ R_own @ K.T, omega


def _dependent(p: PeerRows) -> np.ndarray:
    """J_j D_j J_jᵀ; a range's (a scalar) that rounding left below 0 counts as 0."""
    dep = p.J @ p.D @ p.J.T
    return np.maximum(dep, 0.0) if len(p.y) == 1 else dep


def _fused_trace(P: np.ndarray, N_ind: np.ndarray, peers: Sequence[PeerRows], omega: np.ndarray):
    """tr P⁺ (the whole state) at the weights ω and g = −∂ tr P⁺ / ∂ω (negative rounding clipped), in
    information form.

    (P⁺)⁻¹ = P1⁻¹ + E (Σ_j H_jᵀ R_j⁻¹ H_j) Eᵀ with P1 = D/ω_0 + N and E the position rows (the rows touch only
    the position), so with Q = P⁺²: g_0 = tr(Q P1⁻¹ D P1⁻¹)/ω_0², g_j = tr(Q_pp H_jᵀ R_j⁻¹ J_j D_j J_jᵀ R_j⁻¹ H_j)/ω_j².
    +inf where P1 or P⁺⁻¹ is not positive definite.
    """
    D = P - N_ind
    P1 = D / omega[0] + N_ind
    if np.linalg.eigvalsh(P1).min() <= 0.0:
        return np.inf, np.zeros(len(omega))
    P1_inv = np.linalg.inv(P1)
    info = P1_inv.copy()
    parts = []
    for p, om in zip(peers, omega[1:]):
        Hp = p.H[:, :3]
        R_inv = np.linalg.inv(_dependent(p) / om + p.J @ p.N @ p.J.T + p.r * np.eye(len(p.y)))
        info[:3, :3] += Hp.T @ R_inv @ Hp
        parts.append(Hp.T @ R_inv @ _dependent(p) @ R_inv @ Hp / om**2)
    if np.linalg.eigvalsh(info).min() <= 0.0:
        return np.inf, np.zeros(len(omega))
    P_post = np.linalg.inv(info)
    Q = P_post @ P_post
    g = [np.trace(Q @ P1_inv @ D @ P1_inv) / omega[0] ** 2] + [np.trace(Q[:3, :3] @ part) for part in parts]
    return np.trace(P_post), np.maximum(np.array(g), 0.0)


def _block_diag(blocks: list[np.ndarray]) -> np.ndarray:
    """The block-diagonal matrix of square ``blocks``."""
    size = sum(len(b) for b in blocks)
    out = np.zeros((size, size))
    at = 0
    for b in blocks:
        out[at:at + len(b), at:at + len(b)] = b
        at += len(b)
    return out


def split_ci_update_reference(x: np.ndarray, P: np.ndarray, N: np.ndarray, z: np.ndarray, valid: np.ndarray,
                              alpha: np.ndarray, kind: np.ndarray, target: np.ndarray, r0: np.ndarray,
                              anchors: np.ndarray, landmarks: np.ndarray, prior_pos: np.ndarray, prior_cov: np.ndarray,
                              prior_ind: np.ndarray, alpha_th: float, alpha_min: float,
                              weights: np.ndarray | None = None):
    """One UAV's update under ``peer_update = "split_ci"`` (``split_ci`` docstring). Returns (x⁺, P⁺, N⁺, active).

    Args:
        x, P, N: the UAV's prior mean, covariance and the independent part of it.
        z, valid, alpha, kind, target, r0, anchors, landmarks, prior_pos: as ``update_reference``.
        prior_cov, prior_ind: ``(N, 6, 6)`` every UAV's broadcast prior covariance and its independent part.
        alpha_th, alpha_min: the trust threshold and floor.
        weights: ``(L + 1,)`` the UAV's weights of its previous peer update (ω_0 first, by channel; zeros: a
            cold start), overwritten with this update's (zeros without peers); None: a cold start, not kept.
    """
    peers = np.isin(kind, (PEER, PEER_REL))
    # 1. the absolute channels, one joint update: N_old = T N Tᵀ, N_new = K R Kᵀ
    y, H, R, active = _stack_rows(x, z, valid & ~peers, alpha, kind, target, r0, anchors, landmarks, prior_pos,
                                  alpha_th, alpha_min)
    if y is None:
        x_abs, P_abs, N_old, N_new = x.copy(), P.copy(), N.copy(), np.zeros((6, 6))
    else:
        S = H @ P @ H.T + R
        K = np.linalg.solve(S, H @ P).T
        I_KH = np.eye(6) - K @ H
        x_abs, N_old, N_new = x + K @ y, I_KH @ N @ I_KH.T, K @ R @ K.T
        P_abs = I_KH @ P @ I_KH.T + N_new
    # 2. the peer channels together, linearised at the prior like every row
    rows = []
    for l in np.flatnonzero(peers & valid & (alpha > alpha_th)):
        found = measurement_rows(x, z[l], int(kind[l]), int(target[l]), anchors, landmarks, prior_pos)
        if found is None:
            continue
        y_l, H_l = found
        j = int(target[l])
        # ∂h/∂p_j = −∂h/∂p_i for a range and a relative position alike
        rows.append(PeerRows(y=y_l - H_l @ (x_abs - x), H=H_l, J=-H_l[:, :3],
                             D=prior_cov[j, :3, :3] - prior_ind[j, :3, :3], N=prior_ind[j, :3, :3],
                             r=r0[l] / max(alpha[l], alpha_min), slot=int(l)))
        active[l] = True
    x_post, P_post, N_post, omega = split_ci_peer_update(x_abs, P_abs, N_old, N_new, rows, previous=weights)
    if weights is not None:
        weights[:] = 0.0
        # kept only where there are dependent parts for them to act on (SPLIT_CI_DEPENDENT_FLOOR)
        dependent = np.trace(P_abs - N_old - N_new) + sum(np.trace(_dependent(p)) for p in rows)
        if rows and dependent > SPLIT_CI_DEPENDENT_FLOOR * np.trace(P_abs):
            weights[0] = omega[0]
            weights[[p.slot + 1 for p in rows]] = omega[1:]
    return x_post, P_post, N_post, active


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
        raise ValueError(f"peer_update must be 'point' or 'ci' ('split_ci': split_ci_update_reference), "
                         f"got {peer_update!r}")
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
    y, H, R, active = _stack_rows(x, z, valid, alpha, kind, target, r0, anchors, landmarks, prior_pos, alpha_th,
                                  alpha_min)
    if y is None:
        return x.copy(), P.copy(), active
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


def _stack_rows(x: np.ndarray, z: np.ndarray, valid: np.ndarray, alpha: np.ndarray, kind: np.ndarray,
                target: np.ndarray, r0: np.ndarray, anchors: np.ndarray, landmarks: np.ndarray, prior_pos: np.ndarray,
                alpha_th: float, alpha_min: float):
    """The stacked rows of the channels in ``valid`` with α > α_th at the prior x.

    Returns (y, H, R, active): ``(m,)``, ``(m, 6)``, ``(m, m)`` diagonal and ``(L,)`` bool; y, H and R
    are None when no channel takes part.
    """
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
        return None, None, None, active
    return np.concatenate(ys), np.vstack(Hs), np.diag(Rs), active


def run_reference(x: np.ndarray, P: np.ndarray, imu: np.ndarray, z: np.ndarray, valid: np.ndarray,
                  alpha: np.ndarray, kind: np.ndarray, target: np.ndarray, r0: np.ndarray, anchors: np.ndarray,
                  landmarks: np.ndarray, dt: float, imu_sigma: float, alpha_th: float, alpha_min: float,
                  peer_update: str = "point", P_ind: np.ndarray | None = None):
    """Filter whole sequences (same contract as ``cekf.cekf_run``). Returns (est (T,B,N,3), x, P).

    ``"split_ci"`` carries the independent parts: ``P_ind`` ``(B, N, 6, 6)`` (updated in place), or
    P all independent at the start without it.
    """
    x, P = x.copy(), P.copy()
    N = P.copy() if P_ind is None else P_ind
    n_t, n_b, n = z.shape[:3]
    # "split_ci": every UAV's weights of its previous peer update (zeros: the first search starts cold)
    W = np.zeros((n_b, n, z.shape[3] + 1))
    est = np.zeros((n_t, n_b, n, 3))
    for t in range(n_t):
        for b in range(n_b):
            for i in range(n):
                x_prior, P[b, i] = predict_reference(x[b, i], P[b, i], imu[t, b, i], dt, imu_sigma)
                if peer_update == "split_ci":
                    # N⁻ = F N Fᵀ + Q: the process noise is the UAV's own
                    _, N[b, i] = predict_reference(x[b, i], N[b, i], imu[t, b, i], dt, imu_sigma)
                x[b, i] = x_prior
            prior_pos, prior_cov, prior_ind = x[b, :, :3].copy(), P[b].copy(), N[b].copy()
            for i in range(n):
                if peer_update == "split_ci":
                    x[b, i], P[b, i], N[b, i], _ = split_ci_update_reference(
                        x[b, i], P[b, i], N[b, i], z[t, b, i], valid[t, b, i], alpha[t, b, i], kind[i], target[i],
                        r0[i], anchors, landmarks, prior_pos, prior_cov, prior_ind, alpha_th, alpha_min, W[b, i])
                else:
                    x[b, i], P[b, i], _ = update_reference(
                        x[b, i], P[b, i], z[t, b, i], valid[t, b, i], alpha[t, b, i], kind[i], target[i], r0[i],
                        anchors, landmarks, prior_pos, alpha_th, alpha_min, prior_cov, peer_update)
            est[t, b] = x[b, :, :3]
    return est, x, P
