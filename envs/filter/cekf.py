"""The CEKF backbone as fused numba kernels (``prange`` over the batch).

One 6-state EKF per UAV, state x = [p, v] (world ENU), covariance P.

Prediction (constant acceleration over dt, IMU reading u):
    x⁻ = F x + G u,  P⁻ = F P Fᵀ + Q,  F = [[I, dt·I], [0, I]],  G = [dt²/2·I; dt·I],
    Q = σ_imu² G Gᵀ.

Update (madrl §2.3): one joint update over the channels whose trust α > α_th, each with
R_j = R0_j / max(α_j, α_min); Jacobians at the prior; peer channels use the neighbour's
broadcast prior position as a known point (``peer_update = "point"``, every registered task).
A TDOA channel of anchor pair (i, j) is one scalar row h = ‖p − a_j‖ − ‖p − a_i‖ with
H = u_j − u_i on the position block (u_k the unit vector from anchor k to the prior position).

``peer_update = "ci"`` (a spec option, ``FilterSettings.peer_update``): the absolute channels
first, as one joint update; then each peer channel in channel order, by covariance
intersection (Julier and Uhlmann 1997) over the UAV's estimate and the neighbour's broadcast
one, whose error correlation the UAV cannot know. The joint prior of (x_i, p_j) is bounded
by blockdiag(P_i/ω, P_j/(1 − ω)); for a peer range (H = hᵀ on p_i, −hᵀ on p_j)
    S = hᵀP_i h/ω + hᵀP_j h/(1 − ω) + r,   K = (P_i/ω) Hᵀ / S,   P_i⁺ = P_i/ω − K H P_i/ω,
i.e. the point update with R = ω r + ω hᵀP_j h/(1 − ω) followed by P ← P/ω. A relative
position (z = p_j − p_i) is one 3-row block of the same form with S = A/ω + B/(1 − ω) + r I
(A, B the two position covariances). ω minimises the trace of P_i⁺'s position block on a grid
of ``constants.CI_GRID`` points, or is 1 (no update) when no grid point lowers it. P_j is the
neighbour's prior at this step (the broadcast one), read before any UAV updates.

``peer_update = "split_ci"``: split covariance intersection of all of a UAV's peers of a step
in one update, the prior rescaled once (``split_ci.py`` states the equations and sources).
Each UAV carries the independent part N of its covariance beside P (``P_ind`` in the batch
kernels); the absolute channels update as above and carry N through their gains.

The kernel processes the joint update as a sequence of scalar rows, all linearised at the
prior x⁻: for rows z_r = h_r(x⁻) + H_r (x − x⁻) + v_r with diagonal R, sequential linear
updates equal the joint update exactly (up to rounding), so no m×m inverse is needed. The
scalar covariance update P ← P − c cᵀ / s (c = P Hᵀ, s = H c + r) is the Joseph form
(I − kH) P (I − kH)ᵀ + k r kᵀ simplified for a scalar row; it is evaluated on the upper
triangle and mirrored, so P stays exactly symmetric, and stays positive definite since
s ≥ r ≥ R0 > 0. ``cekf_reference`` holds the readable dense float64 version of the same
maths; tests hold the two equal.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from swarmloc.envs.filter.constants import MIN_RANGE as _MIN_RANGE
from swarmloc.envs.filter.ekf_rows import joseph_part
from swarmloc.envs.filter.ekf_rows import scalar_update as _scalar_update
from swarmloc.envs.filter.peer_ci import ci_peers
from swarmloc.envs.filter.split_ci import row_gain, split_ci_peers
from swarmloc.envs.tasks.channels import ANCHOR, GPS, LANDMARK, PEER, PEER_REL, TDOA
from swarmloc.envs.world.cost import PREDICT_FLOPS, RANGE_ROW_FLOPS, TDOA_ROW_FLOPS, VECTOR_ROW_FLOPS
from swarmloc.envs.world.cost import SPLIT_PREDICT_FLOPS, SPLIT_TRACK_ROW_FLOPS

#: ``FilterSettings.peer_update`` as the kernels' integer code
PEER_UPDATE_CODES = {"point": 0, "ci": 1, "split_ci": 2}


@njit(cache=True, inline="always")
def predict_uav(x, P, u, dt, q):
    """In-place prediction of one UAV: x⁻ = F x + G u, P⁻ = F P Fᵀ + Q (Q = q·G Gᵀ)."""
    h2 = 0.5 * dt * dt
    for d in range(3):
        # p⁻ = p + dt·v + dt²/2·u ;  v⁻ = v + dt·u
        x[d] = x[d] + dt * x[3 + d] + h2 * u[d]
        x[3 + d] = x[3 + d] + dt * u[d]
    predict_covariance(P, dt, q)


@njit(cache=True, inline="always")
def predict_covariance(P, dt, q):
    """In-place P⁻ = F P Fᵀ + Q (Q = q·G Gᵀ): a UAV's covariance, or its independent part under ``"split_ci"``."""
    h2 = 0.5 * dt * dt
    # F P Fᵀ with F = [[I, dt I], [0, I]] on blocks A = P_pp, B = P_pv, C = P_vv:
    #   A⁻ = A + dt (B + Bᵀ) + dt² C,  B⁻ = B + dt C,  C⁻ = C
    for r in range(3):
        for c in range(3):
            P[r, c] = P[r, c] + dt * (P[r, 3 + c] + P[3 + r, c]) + dt * dt * P[3 + r, 3 + c]
    for r in range(3):
        for c in range(3):
            P[r, 3 + c] = P[r, 3 + c] + dt * P[3 + r, 3 + c]
            P[3 + c, r] = P[r, 3 + c]
    # Q = σ² G Gᵀ: q·dt⁴/4 on p-p, q·dt³/2 on p-v, q·dt² on v-v (diagonal blocks)
    for d in range(3):
        P[d, d] += q * h2 * h2
        P[d, 3 + d] += q * h2 * dt
        P[3 + d, d] += q * h2 * dt
        P[3 + d, 3 + d] += q * dt * dt


@njit(cache=True, inline="always")
def update_uav(x, P, z, valid, alpha, kind, target, r0, anchors, landmarks, prior_pos, prior_pp, peer_update,
               alpha_th, alpha_min, active, x0, hvec, c, P_ind, b, i, prior_ind_pp, work, W):
    """Trust-weighted joint update of one UAV over its L channels (in place).

    Args:
        x, P: the UAV's prior (updated in place to the posterior).
        z: ``(L, 3)`` measurements; valid, alpha: ``(L,)``.
        kind, target, r0: ``(L,)`` static channel description.
        anchors ``(A, 3)``, landmarks ``(M, 3)``, prior_pos ``(N, 3)`` broadcast priors.
        prior_pp: ``(N, 3, 3)`` the broadcast priors' position covariances (read by ``"ci"`` and ``"split_ci"``).
        peer_update: ``PEER_UPDATE_CODES`` of ``FilterSettings.peer_update``.
        active: ``(L,)`` output, whether the channel was used.
        x0, hvec, c: scratch 6-, 3-, 6-vectors.
        P_ind, b, i: ``"split_ci"``: ``P_ind[b, i]`` ``(6, 6)`` is the UAV's independent part of P (prior in,
            posterior out); unread otherwise (any 4-d float array: no view is made, which the point update's
            speed notices).
        prior_ind_pp: ``(N, 3, 3)`` ``"split_ci"``: the broadcast priors' independent position parts.
        work: ``(8, 6)`` scratch (``"split_ci"``: this step's own-noise part, a gain, a vector).
        W: ``"split_ci"``: ``W[b, i]`` ``(L + 1,)`` the weights of the UAV's previous peer update, where this
            one's search starts (all 0: cold; ``split_ci.split_ci_peers``), overwritten; unread otherwise.

    Returns:
        FLOPs of the step for this UAV (prediction + the rows applied, see ``cost.py``).
    """
    flops = PREDICT_FLOPS
    for a in range(6):
        x0[a] = x[a]
    split = peer_update == 2
    if split:
        flops += SPLIT_PREDICT_FLOPS
        # N_new, this step's own measurement noise, starts at 0 (split_ci.py)
        work[:6, :] = 0.0
    for l in range(kind.shape[0]):
        al = alpha[l]
        use = valid[l] and al > alpha_th
        active[l] = False
        if not use:
            continue
        # R = R0 / max(α, α_min)
        r = r0[l] / max(al, alpha_min)
        ch = kind[l]
        j = target[l]
        if peer_update >= 1 and (ch == PEER or ch == PEER_REL):
            continue  # "ci", "split_ci": the peer channels after the absolute ones (ci_peers, split_ci_peers)
        if ch == ANCHOR or ch == PEER:
            if ch == ANCHOR:
                q0, q1, q2 = anchors[j, 0], anchors[j, 1], anchors[j, 2]
            else:
                q0, q1, q2 = prior_pos[j, 0], prior_pos[j, 1], prior_pos[j, 2]
            d0, d1, d2 = x0[0] - q0, x0[1] - q1, x0[2] - q2
            rng = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            if rng < _MIN_RANGE:
                continue
            # H = (p⁻ − q)ᵀ / ‖p⁻ − q‖ at the prior
            hvec[0], hvec[1], hvec[2] = d0 / rng, d1 / rng, d2 / rng
            # y = z − h(x⁻) − H (x − x⁻)
            y = z[l, 0] - rng - (hvec[0] * (x[0] - x0[0]) + hvec[1] * (x[1] - x0[1]) + hvec[2] * (x[2] - x0[2]))
            # H enters as +hvec; _scalar_update uses hvec when col < 0
            _scalar_update(x, P, hvec, -1, y, r, c)
            flops += RANGE_ROW_FLOPS
            if split:
                flops += _track_split(P_ind[b, i], work, c, hvec, -1, r)
        elif ch == TDOA:
            # the pair (i, j) of target code j = i·A + j': h = ‖p − a_j'‖ − ‖p − a_i‖
            n_a = anchors.shape[0]
            ia, ib = j // n_a, j % n_a
            e0, e1, e2 = x0[0] - anchors[ib, 0], x0[1] - anchors[ib, 1], x0[2] - anchors[ib, 2]
            f0, f1, f2 = x0[0] - anchors[ia, 0], x0[1] - anchors[ia, 1], x0[2] - anchors[ia, 2]
            rb = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
            ra = math.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
            if rb < _MIN_RANGE or ra < _MIN_RANGE:
                continue
            # H = (p⁻ − a_j)ᵀ/‖p⁻ − a_j‖ − (p⁻ − a_i)ᵀ/‖p⁻ − a_i‖ at the prior
            hvec[0], hvec[1], hvec[2] = e0 / rb - f0 / ra, e1 / rb - f1 / ra, e2 / rb - f2 / ra
            # y = z − h(x⁻) − H (x − x⁻)
            y = z[l, 0] - (rb - ra) - (hvec[0] * (x[0] - x0[0]) + hvec[1] * (x[1] - x0[1])
                                       + hvec[2] * (x[2] - x0[2]))
            _scalar_update(x, P, hvec, -1, y, r, c)
            flops += TDOA_ROW_FLOPS
            if split:
                flops += _track_split(P_ind[b, i], work, c, hvec, -1, r)
        else:
            for d in range(3):
                if ch == GPS:
                    # z = p + v, H = e_d: y = z_d − p_d
                    y = z[l, d] - x[d]
                    _scalar_update(x, P, hvec, d, y, r, c)
                else:
                    # landmark: z = m − p; peer_rel: z = p̂_j − p; H = −e_d: y = z_d − q_d + p_d
                    qd = landmarks[j, d] if ch == LANDMARK else prior_pos[j, d]
                    y = -(z[l, d] - qd + x[d])  # sign folded: update along +e_d with −y
                    _scalar_update(x, P, hvec, d, y, r, c)
                flops += VECTOR_ROW_FLOPS
                if split:
                    flops += _track_split(P_ind[b, i], work, c, hvec, d, r)
        active[l] = True
    if peer_update == 1:
        flops += ci_peers(x, P, z, valid, alpha, kind, target, r0, prior_pos, prior_pp, alpha_th, alpha_min, active,
                          x0, hvec, c)
    elif split:
        flops += split_ci_peers(x, P, P_ind[b, i], work, z, valid, alpha, kind, target, r0, prior_pos, prior_pp,
                                prior_ind_pp, alpha_th, alpha_min, active, x0, c, W[b, i])
    return flops


@njit(cache=True, inline="always")
def _track_split(N, work, c, hvec, col, r):
    """``"split_ci"``: both independent parts through the absolute row just applied (split_ci.py, step 1):
    N_old ← (I − k H) N_old (I − k H)ᵀ, N_new ← (I − k H) N_new (I − k H)ᵀ + r k kᵀ (N_new in ``work[:6]``,
    k and a scratch vector in its last rows). Returns their FLOPs."""
    k, vec = work[6], work[7]
    row_gain(c, hvec, col, r, k)
    joseph_part(N, k, hvec, col, 0.0, vec)
    joseph_part(work[:6], k, hvec, col, r, vec)
    return SPLIT_TRACK_ROW_FLOPS


@njit(cache=True, parallel=True, error_model="numpy")
def cekf_predict(x, P, imu, dt, imu_sigma, prior_pos, P_ind=None):
    """Predict every UAV of every episode; copy the prior positions to ``prior_pos``.

    ``P_ind`` ``(B, N, 6, 6)``, the independent parts of ``"split_ci"``, is predicted too when given
    (F N Fᵀ + Q: the process noise is every UAV's own).
    """
    n_b, n = x.shape[0], x.shape[1]
    q = imu_sigma * imu_sigma
    for b in prange(n_b):
        for i in range(n):
            predict_uav(x[b, i], P[b, i], imu[b, i], dt, q)
            if P_ind is not None:
                predict_covariance(P_ind[b, i], dt, q)
            for d in range(3):
                prior_pos[b, i, d] = x[b, i, d]


@njit(cache=True, parallel=True, error_model="numpy")
def cekf_update(x, P, z, valid, alpha, kind, target, r0, anchors, landmarks, prior_pos,
                alpha_th, alpha_min, active, flops, peer_update=0, P_ind=None, W=None):
    """Trust-weighted joint update of every UAV of every episode (in place).

    Shapes: x ``(B, N, 6)``, P ``(B, N, 6, 6)``, z ``(B, N, L, 3)``, valid/alpha/active
    ``(B, N, L)``, kind/target/r0 ``(N, L)``, prior_pos ``(B, N, 3)``, flops ``(B, N)`` output;
    P holds the priors on entry (``"ci"`` reads the neighbours' before any UAV updates).
    ``"split_ci"`` needs ``P_ind`` ``(B, N, 6, 6)``, the independent parts of P (prior in,
    posterior out; ``split_ci.py``), and takes ``W`` ``(B, N, L + 1)``, the weights of every UAV's previous
    peer update (in and out; zeros: a cold start); without ``W`` every call starts cold.
    """
    n_b, n, n_l = x.shape[0], x.shape[1], z.shape[2]
    if peer_update == 2 and P_ind is None:
        raise ValueError("peer_update 'split_ci' needs P_ind, the (B, N, 6, 6) independent parts of P")
    # the independent parts ("split_ci"; otherwise unread, a stand-in)
    if P_ind is None:
        N_all = np.zeros((1, 1, 6, 6))
    else:
        N_all = P_ind
    if W is None:
        W_all = np.zeros((n_b, n, n_l + 1) if peer_update == 2 else (1, 1, 1))
    else:
        W_all = W
    for b in prange(n_b):
        x0 = np.empty(6)
        hvec = np.empty(3)
        c = np.empty(6)
        work = np.empty((8, 6))
        prior_pp = np.empty((n, 3, 3))
        prior_ind_pp = np.empty((n, 3, 3))
        if peer_update >= 1:
            for i in range(n):
                prior_pp[i] = P[b, i, :3, :3]
        if peer_update == 2:
            for i in range(n):
                prior_ind_pp[i] = N_all[b, i, :3, :3]
        for i in range(n):
            flops[b, i] = update_uav(x[b, i], P[b, i], z[b, i], valid[b, i], alpha[b, i], kind[i], target[i],
                                    r0[i], anchors, landmarks, prior_pos[b], prior_pp, peer_update, alpha_th,
                                    alpha_min,
                                    active[b, i], x0, hvec, c, N_all, b, i, prior_ind_pp, work, W_all)


@njit(cache=True, parallel=True, error_model="numpy")
def cekf_run(x, P, imu, z, valid, alpha, kind, target, r0, anchors, landmarks, dt, imu_sigma,
             alpha_th, alpha_min, est, peer_update=0, P_ind=None, W=None):
    """Filter whole sequences: T predict+update steps per episode in one call.

    Shapes: imu ``(T, B, N, 3)``, z ``(T, B, N, L, 3)``, valid/alpha ``(T, B, N, L)``,
    est ``(T, B, N, 3)`` output posterior positions. Used for offline evaluation and the
    speed benchmark (no per-step Python dispatch). ``"split_ci"`` carries the independent
    parts in ``P_ind`` ``(B, N, 6, 6)`` (updated in place), or, without it, starts from P
    all independent (an initial prior), and the weights of the peer updates in ``W`` ``(B, N, L + 1)``
    (updated in place), or, without it, starts them cold.
    """
    n_t, n_b, n, n_l = z.shape[0], z.shape[1], z.shape[2], z.shape[3]
    q = imu_sigma * imu_sigma
    # the independent parts ("split_ci": P all independent without P_ind; otherwise unread, a stand-in)
    if P_ind is None:
        N_all = P.copy() if peer_update == 2 else np.zeros((1, 1, 6, 6))
    else:
        N_all = P_ind
    if W is None:
        W_all = np.zeros((n_b, n, n_l + 1) if peer_update == 2 else (1, 1, 1))
    else:
        W_all = W
    for b in prange(n_b):
        x0 = np.empty(6)
        hvec = np.empty(3)
        c = np.empty(6)
        work = np.empty((8, 6))
        prior = np.empty((n, 3))
        prior_pp = np.empty((n, 3, 3))
        prior_ind_pp = np.empty((n, 3, 3))
        active = np.empty(n_l, dtype=np.bool_)
        for t in range(n_t):
            for i in range(n):
                predict_uav(x[b, i], P[b, i], imu[t, b, i], dt, q)
                for d in range(3):
                    prior[i, d] = x[b, i, d]
                if peer_update >= 1:
                    prior_pp[i] = P[b, i, :3, :3]
                if peer_update == 2:
                    predict_covariance(N_all[b, i], dt, q)
                    prior_ind_pp[i] = N_all[b, i, :3, :3]
            for i in range(n):
                update_uav(x[b, i], P[b, i], z[t, b, i], valid[t, b, i], alpha[t, b, i], kind[i], target[i],
                           r0[i], anchors, landmarks, prior, prior_pp, peer_update, alpha_th, alpha_min, active, x0,
                           hvec, c, N_all, b, i, prior_ind_pp, work, W_all)
                for d in range(3):
                    est[t, b, i, d] = x[b, i, d]


@njit(cache=True, inline="always")
def features_uav(x, P, z, valid, kind, target, r0, anchors, landmarks, prior_pos, prior_cov, peer_cov,
                 resid, pred, nis, yv, S):
    """Innovation features of one UAV's L channels at its prior (see ``channel_features``).

    Args:
        x, P: the UAV's prior mean ``(6,)`` and covariance ``(6, 6)``.
        z: ``(L, 3)`` measurements; valid ``(L,)``; kind, target, r0 ``(L,)``.
        anchors ``(A, 3)``, landmarks ``(M, 3)``, prior_pos ``(N, 3)`` broadcast priors.
        prior_cov: ``(N, 6, 6)`` the UAVs' prior covariances (the broadcast P_j; read only
            when ``peer_cov``).
        peer_cov: add the neighbour's broadcast covariance to a peer channel's S (v1 tasks,
            ``TaskSpec.peer_nis_neighbour_cov``); False keeps the v0 NIS bit for bit.
        resid, pred, nis: ``(L,)`` outputs.
        yv, S: scratch 3-vector and 3×3 matrix.
    """
    for l in range(kind.shape[0]):
        if not valid[l]:
            resid[l] = 0.0
            pred[l] = 0.0
            nis[l] = 0.0
            continue
        ch = kind[l]
        j = target[l]
        if ch == ANCHOR or ch == PEER:
            if ch == ANCHOR:
                q0, q1, q2 = anchors[j, 0], anchors[j, 1], anchors[j, 2]
            else:
                q0, q1, q2 = prior_pos[j, 0], prior_pos[j, 1], prior_pos[j, 2]
            d0, d1, d2 = x[0] - q0, x[1] - q1, x[2] - q2
            rng = max(math.sqrt(d0 * d0 + d1 * d1 + d2 * d2), _MIN_RANGE)
            h0, h1, h2 = d0 / rng, d1 / rng, d2 / rng
            y = z[l, 0] - rng
            # S = h P_pp hᵀ + R0
            s = (h0 * (P[0, 0] * h0 + P[0, 1] * h1 + P[0, 2] * h2)
                 + h1 * (P[1, 0] * h0 + P[1, 1] * h1 + P[1, 2] * h2)
                 + h2 * (P[2, 0] * h0 + P[2, 1] * h1 + P[2, 2] * h2) + r0[l])
            if peer_cov and ch == PEER:
                # v1: S += u P_j uᵀ, the neighbour's broadcast prior p̂_j is uncertain too (∂h/∂p_j = −u;
                # the CEKF keeps no cross-covariance of i and j, so none is added)
                Pj = prior_cov[j]
                s += (h0 * (Pj[0, 0] * h0 + Pj[0, 1] * h1 + Pj[0, 2] * h2)
                      + h1 * (Pj[1, 0] * h0 + Pj[1, 1] * h1 + Pj[1, 2] * h2)
                      + h2 * (Pj[2, 0] * h0 + Pj[2, 1] * h1 + Pj[2, 2] * h2))
            resid[l] = abs(y)
            pred[l] = rng
            nis[l] = y * y / s
        elif ch == TDOA:
            n_a = anchors.shape[0]
            ia, ib = j // n_a, j % n_a
            e0, e1, e2 = x[0] - anchors[ib, 0], x[1] - anchors[ib, 1], x[2] - anchors[ib, 2]
            f0, f1, f2 = x[0] - anchors[ia, 0], x[1] - anchors[ia, 1], x[2] - anchors[ia, 2]
            rb = max(math.sqrt(e0 * e0 + e1 * e1 + e2 * e2), _MIN_RANGE)
            ra = max(math.sqrt(f0 * f0 + f1 * f1 + f2 * f2), _MIN_RANGE)
            # h = ‖p⁻ − a_j‖ − ‖p⁻ − a_i‖, H = u_j − u_i on the position block
            h0, h1, h2 = e0 / rb - f0 / ra, e1 / rb - f1 / ra, e2 / rb - f2 / ra
            y = z[l, 0] - (rb - ra)
            # S = H P_pp Hᵀ + R0
            s = (h0 * (P[0, 0] * h0 + P[0, 1] * h1 + P[0, 2] * h2)
                 + h1 * (P[1, 0] * h0 + P[1, 1] * h1 + P[1, 2] * h2)
                 + h2 * (P[2, 0] * h0 + P[2, 1] * h1 + P[2, 2] * h2) + r0[l])
            resid[l] = abs(y)
            pred[l] = abs(rb - ra)
            nis[l] = y * y / s
        else:
            # 3-vector channel: S = P_pp + R0·I (H = ±I on position)
            dist2 = 0.0
            for d in range(3):
                if ch == GPS:
                    yv[d] = z[l, d] - x[d]
                else:
                    qd = landmarks[j, d] if ch == LANDMARK else prior_pos[j, d]
                    hd = qd - x[d]
                    dist2 += hd * hd
                    yv[d] = z[l, d] - hd
            for r_ in range(3):
                for c_ in range(3):
                    S[r_, c_] = P[r_, c_] + (r0[l] if r_ == c_ else 0.0)
            if peer_cov and ch == PEER_REL:
                # v1: S += P_j,pp for a relative position to the neighbour's broadcast prior
                for r_ in range(3):
                    for c_ in range(3):
                        S[r_, c_] += prior_cov[j, r_, c_]
            nis[l] = _quad_inv3(S, yv)
            resid[l] = math.sqrt(yv[0] * yv[0] + yv[1] * yv[1] + yv[2] * yv[2])
            pred[l] = math.sqrt(dist2) if ch != GPS else 0.0


@njit(cache=True, parallel=True, error_model="numpy")
def channel_features(x, P, z, valid, kind, target, r0, anchors, landmarks, prior_pos, peer_cov,
                     resid, pred, nis):
    """Per-channel innovation features at the prior (before the policy picks trust).

    Outputs ``(B, N, L)``: resid = ‖y‖ (innovation magnitude), pred = predicted distance
    ‖h(x⁻)‖ to the channel's target (0 for GPS; the predicted range difference's magnitude
    for TDOA), nis = yᵀ S⁻¹ y with S = H P⁻ Hᵀ + R0; with ``peer_cov`` (v1 tasks) a peer
    channel's S also holds the neighbour's broadcast covariance: + u P_j⁻ uᵀ for a range,
    + P_j,pp⁻ for a relative position (P holds every UAV's prior, so P[b, j] is P_j⁻).
    Invalid channels get zeros.
    """
    n_b, n = z.shape[0], z.shape[1]
    for b in prange(n_b):
        yv = np.empty(3)
        S = np.empty((3, 3))
        for i in range(n):
            features_uav(x[b, i], P[b, i], z[b, i], valid[b, i], kind[i], target[i], r0[i], anchors, landmarks,
                         prior_pos[b], P[b], peer_cov, resid[b, i], pred[b, i], nis[b, i], yv, S)


@njit(cache=True, inline="always")
def _quad_inv3(S, y):
    """yᵀ S⁻¹ y for a symmetric positive-definite 3×3 S (Cholesky)."""
    l00 = math.sqrt(S[0, 0])
    l10 = S[1, 0] / l00
    l20 = S[2, 0] / l00
    l11 = math.sqrt(S[1, 1] - l10 * l10)
    l21 = (S[2, 1] - l20 * l10) / l11
    l22 = math.sqrt(S[2, 2] - l20 * l20 - l21 * l21)
    # forward substitution L w = y; yᵀ S⁻¹ y = ‖w‖²
    w0 = y[0] / l00
    w1 = (y[1] - l10 * w0) / l11
    w2 = (y[2] - l20 * w0 - l21 * w1) / l22
    return w0 * w0 + w1 * w1 + w2 * w2


def initial_covariance(batch: int, n_uav: int, pos_sigma: float, vel_sigma: float) -> np.ndarray:
    """Diagonal initial covariance ``(B, N, 6, 6)`` from the stated initial uncertainty."""
    diag = np.array([pos_sigma**2] * 3 + [vel_sigma**2] * 3)
    return np.broadcast_to(np.diag(diag), (batch, n_uav, 6, 6)).copy()

