"""Split covariance intersection of a UAV's peer channels, all of a step in one update
(``FilterSettings.peer_update = "split_ci"``; the numba kernel, ``cekf_reference`` holds the
readable version and tests hold the two equal).

Each UAV keeps its covariance split as P = D + N (Julier and Uhlmann 2001, split covariance
intersection; Li and Nashashibi 2013 and Wanasinghe et al. 2014 for cooperative localization):
N bounds the part of its error that no other UAV's estimate holds, D the rest, whose
correlation with the neighbours' errors is unknown. The prediction adds the process noise to
the independent part: D⁻ = F D Fᵀ, N⁻ = F N Fᵀ + Q. At reset N = P0 (the initial errors are
drawn independently).

Update of UAV i at step k, every row linearised at its prior x⁻ (as every CEKF update):

1. The absolute channels (anchors, TDOA, landmarks, GPS): one joint EKF update, gain K_a,
   T_a = I − K_a H_a. The parts go through it: N_old = T_a N⁻ T_aᵀ (what the prior held) and
   N_new = K_a R_a K_aᵀ (this step's own measurement noise); P' = T_a P⁻ T_aᵀ + N_new,
   N' = N_old + N_new, D' = P' − N'.
2. The peer channels of the step together, one channel per neighbour j, each fused against
   the neighbour's broadcast prior (p̂_j⁻, P_j = D_j + N_j position blocks). The dependent
   errors of the UAV and of its m neighbours may be correlated in any way, so their joint
   covariance is bounded, for weights ω_0 + ω_1 + … + ω_m = 1, by
       blockdiag(D'/ω_0, D_1/ω_1, …, D_m/ω_m)
   (covariance intersection of m + 1 sources, Julier and Uhlmann 1997; by Cauchy–Schwarz,
   (Σ a_kᵀ d_k)² ≤ Σ (a_kᵀ d_k)²/ω_k for Σ ω_k = 1), and the independent parts add on the
   block diagonal. The update is then an ordinary joint EKF update with
       prior   P1 = D'/ω_0 + N'
       noise   R_j = J_j (D_j/ω_j + N_j) J_jᵀ + r_j I     (block diagonal over neighbours)
       S = H P1 Hᵀ + R,  K = P1 Hᵀ S⁻¹,  x⁺ = x' + K y,  P⁺ = (I − K H) P1 (I − K H)ᵀ + K R Kᵀ
   with J_j = ∂h/∂p_j: a range has H = [uᵀ 0], J = −uᵀ (u the unit vector from p̂_j⁻ to
   p̂_i⁻), so R_j = r_j + uᵀD_j u/ω_j + uᵀN_j u; a relative position z = p_j − p_i + v is
   used as the measurement m = p̂_j⁻ − z of p_i (H = [I 0]) with R_j = D_j/ω_j + N_j + r_j I.
   The UAV's prior is rescaled once per step, whatever the number of peers (the ``"ci"``
   option rescales it once per peer).
3. Bookkeeping: the posterior's independent part is the own measurement noise of this step,
   N⁺ = (I − K H) N_new (I − K H)ᵀ + K R_own Kᵀ, R_own = blockdiag(r_j I); D⁺ = P⁺ − N⁺.
   The prior's independent part N_old moves to D: the UAV broadcast its prior at this step,
   and the neighbours that fused it now hold it. (The split-CI fusion of two estimates keeps
   both inputs' independent parts independent in the result; with every UAV fusing every
   neighbour at every step that would count them twice, so here only what no neighbour has
   seen stays independent.) Where no neighbour fused the broadcast this is conservative.

Trust α scales each channel's noise as everywhere: r_j = R0_j / max(α_j, α_min); booking
K R_own Kᵀ with the inflated r_j overstates N⁺, which keeps both bounds valid.

The weights minimise tr P⁺, the trace of the whole posterior covariance (position and velocity:
with the position block alone, the search inflates the unobserved velocity by 1/ω_0 at every
step, and on VisionLoss-v1's swarm-wide vision outages the filter diverged). Any weights give a
consistent update, so the search only needs to be good:
- a start: the neighbours share 1 − ω_0 in proportion to what each would give alone at full
  weight, Δ_j = tr(P'_pp H_jᵀ (H_j P' H_jᵀ + J_j P_j J_jᵀ + r_j I)⁻¹ H_j P'_pp) (fast covariance
  intersection weighs its sources by their information in the same way, Niehsen 2002), and ω_0
  is the best of {1/SPLIT_CI_GRID, …, (SPLIT_CI_GRID − 1)/SPLIT_CI_GRID};
- then ``SPLIT_CI_STEPS`` multiplicative steps ω_k ← ω_k √g_k / Σ_l ω_l √g_l with
  g_k = −∂ tr P⁺/∂ω_k, the algorithm of optimal experimental design for the trace criterion
  (Silvey, Titterington and Torsney 1978; Yu 2010): with many peers the best weights sit on a
  few of them, which a share by Δ alone misses (without the steps, uniform's RMSE is 5–9 % higher
  on Scale8 and Scale32 with the anchors ranged within 11 m, 4 dev seeds);
- no peer update (ω_0 = 1) when the weights reached do not lower tr P';
- warm starts: after a UAV's first update with peers its weights are kept by channel (``weights``), and
  the next search starts from them mixed ``SPLIT_CI_WARM_MIX`` towards the cold start (ω_0 = 1/2, the
  Δ shares of the other half), then takes ``SPLIT_CI_WARM_STEPS`` steps: the weights follow the
  geometry from step to step instead of being searched again (``constants.py`` has the measurements).
  They are not kept while there is no dependent part for them to act on (tr D' and the neighbours'
  below ``SPLIT_CI_DEPENDENT_FLOOR`` tr P', as right after a reset).
tr P⁺ is the information form (P⁺)⁻¹ = P1⁻¹ + E (Σ_j H_jᵀ R_j⁻¹ H_j) Eᵀ (E the position rows) turned
by the push-through identity into 3×3 algebra (``_fused_trace``), and g its derivative. The update itself applies the
neighbours' blocks one after the other (exact, R being block diagonal): a range as one scalar row
(``ekf_rows.scalar_update``), a relative position as one 3-row block.

References: S. J. Julier and J. K. Uhlmann, "A non-divergent estimation algorithm in the
presence of unknown correlations", ACC 1997; S. J. Julier and J. K. Uhlmann, "General
decentralized data fusion with covariance intersection", Handbook of Multisensor Data Fusion,
2001; H. Li and F. Nashashibi, "Cooperative multi-vehicle localization using split covariance
intersection filter", IEEE ITS Magazine 5(2), 2013; T. R. Wanasinghe, G. K. I. Mann and R. G.
Gosine, "Decentralized cooperative localization for heterogeneous multi-robot system using
split covariance intersection filter", CRV 2014; W. Niehsen, "Information fusion based on
fast covariance intersection filtering", FUSION 2002; S. D. Silvey, D. M. Titterington and B.
Torsney, "An algorithm for optimal designs on a finite design space", Communications in
Statistics A 7, 1978; Y. Yu, "Monotonic convergence of a general algorithm for computing optimal
designs", Annals of Statistics 38(3), 2010.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from swarmloc.envs.filter.constants import (MIN_RANGE, OMEGA_FLOOR, SPLIT_CI_DEPENDENT_FLOOR, SPLIT_CI_GRID,
                                            SPLIT_CI_STEPS, SPLIT_CI_WARM_MIX, SPLIT_CI_WARM_STEPS)
from swarmloc.envs.filter.ekf_rows import block_update, inv3, joseph_part, scalar_update, tr_asa
from swarmloc.envs.tasks.channels import PEER, PEER_REL
from swarmloc.envs.world.cost import (SPLIT_CI_FLOPS, SPLIT_CI_RANGE_FLOPS, SPLIT_CI_REL_FLOPS, SPLIT_CI_WARM_FLOPS,
                                      SPLIT_CI_WARM_RANGE_FLOPS, SPLIT_CI_WARM_REL_FLOPS)


@njit(cache=True, inline="always")
def row_gain(c, hvec, col, r, k):
    """k = c / s of the scalar row that ``scalar_update`` just applied (c = P⁻ Hᵀ, s = H c + r)."""
    if col >= 0:
        s = c[col] + r
    else:
        s = c[0] * hvec[0] + c[1] * hvec[1] + c[2] * hvec[2] + r
    for a in range(6):
        k[a] = c[a] / s


@njit(cache=True)
def split_ci_peers(x, P, N, work, z, valid, alpha, kind, target, r0, prior_pos, prior_pp, prior_ind_pp,
                   alpha_th, alpha_min, active, x0, c, weights):
    """Step 2 and 3 of the module docstring for one UAV (in place). Returns the FLOPs of its peer channels.

    Args:
        x, P: the UAV's mean and covariance after its absolute channels (step 1).
        N: ``(6, 6)`` N_old, the prior's independent part through step 1; on return N⁺.
        work: ``(8, 6)``: N_new, step 1's own noise, in its first 6 rows; scratch after.
        z ``(L, 3)``, valid, alpha ``(L,)``; kind, target, r0 ``(L,)`` as in ``cekf.update_uav``.
        prior_pos: ``(N, 3)`` the broadcast prior positions.
        prior_pp, prior_ind_pp: ``(N, 3, 3)`` their position covariances P_j and independent parts N_j.
        active: ``(L,)`` output, set for the peer channels that take part.
        x0: ``(6,)`` the prior mean (every row is linearised at it).
        c: scratch 6-vector.
        weights: ``(L + 1,)`` the weights of the UAV's previous update, ω_0 first, then each channel's (0 where
            it took no part); all 0: none (a cold start). Overwritten with this update's.
    """
    n_l = kind.shape[0]
    fresh, k, scratch = work[:6], work[6], work[7]
    rows = np.empty(n_l, dtype=np.int64)  # the peer channels that take part, in channel order
    # one allocation for the rest (views of it)
    buf = np.empty(n_l * 10 + 2 + 15 * 9 + 2 * 18)
    h = buf[:3 * n_l].reshape((n_l, 3))  # range: u at the prior; relative position: m = p̂_j − z
    rng = buf[3 * n_l:4 * n_l]  # range at the prior
    r = buf[4 * n_l:5 * n_l]  # R0 / max(α, α_min)
    a_d = buf[5 * n_l:6 * n_l]  # range: uᵀ D_j u
    a_n = buf[6 * n_l:7 * n_l]  # range: uᵀ N_j u
    share = buf[7 * n_l:8 * n_l]  # Δ_j / Σ Δ
    at = 8 * n_l
    omega = buf[at:at + n_l + 1]  # ω_0, ω_1, …, ω_m
    grad = buf[at + n_l + 1:at + 2 * n_l + 2]  # −∂ tr P⁺_pp / ∂ω
    at += 2 * n_l + 2
    mats = buf[at:at + 72].reshape((8, 3, 3))
    S, Si = mats[0], mats[1]
    pre = buf[at + 72:at + 135].reshape((7, 3, 3))
    gains = buf[at + 135:].reshape((2, 6, 3))
    K, G = gains[0], gains[1]
    flops = 0
    m = 0
    total = 0.0
    warm = weights[0] > 0.0
    dep = 0.0  # the dependent parts the weights act on: Σ uᵀD_j u (ranges) + Σ tr D_j (relative positions)
    for l in range(n_l):
        ch = kind[l]
        if not (valid[l] and alpha[l] > alpha_th and (ch == PEER or ch == PEER_REL)):
            continue
        j = target[l]
        # R = R0 / max(α, α_min)
        rl = r0[l] / max(alpha[l], alpha_min)
        Pj, Nj = prior_pp[j], prior_ind_pp[j]
        if ch == PEER:
            d0, d1, d2 = x0[0] - prior_pos[j, 0], x0[1] - prior_pos[j, 1], x0[2] - prior_pos[j, 2]
            rg = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            if rg < MIN_RANGE:
                continue
            # u = (p̂_i⁻ − p̂_j⁻)ᵀ / ‖p̂_i⁻ − p̂_j⁻‖
            h[m, 0], h[m, 1], h[m, 2] = d0 / rg, d1 / rg, d2 / rg
            rng[m] = rg
            ad = an = pu2 = upu = 0.0
            for u in range(3):
                pu = 0.0
                for v in range(3):
                    ad += h[m, u] * (Pj[u, v] - Nj[u, v]) * h[m, v]
                    an += h[m, u] * Nj[u, v] * h[m, v]
                    pu += P[u, v] * h[m, v]
                pu2 += pu * pu
                upu += h[m, u] * pu
            # a dependent variance that rounding left below 0 counts as 0
            a_d[m], a_n[m] = max(ad, 0.0), an
            dep += a_d[m]
            # Δ_j = ‖P_pp u‖² / (uᵀP u + uᵀP_j u + r)
            share[m] = pu2 / (upu + ad + an + rl)
            flops += SPLIT_CI_WARM_RANGE_FLOPS if warm else SPLIT_CI_RANGE_FLOPS
        else:
            for d in range(3):
                h[m, d] = prior_pos[j, d] - z[l, d]
            # Δ_j = tr(P_pp (P_pp + P_j + r I)⁻¹ P_pp)
            for u in range(3):
                for v in range(3):
                    S[u, v] = P[u, v] + Pj[u, v] + (rl if u == v else 0.0)
            inv3(S, Si)
            share[m] = tr_asa(P, Si)
            dep += max(Pj[0, 0] - Nj[0, 0] + Pj[1, 1] - Nj[1, 1] + Pj[2, 2] - Nj[2, 2], 0.0)
            flops += SPLIT_CI_WARM_REL_FLOPS if warm else SPLIT_CI_REL_FLOPS
        rows[m] = l
        r[m] = rl
        total += share[m]
        active[l] = True
        m += 1
    if m == 0:
        N[:, :] = fresh
        weights[:] = 0.0  # no peers: the next search starts cold
        return flops
    flops += SPLIT_CI_WARM_FLOPS if warm else SPLIT_CI_FLOPS
    for q in range(m):
        share[q] /= total
    # N' = N_old + N_new (D' = P − N')
    for u in range(6):
        for v in range(6):
            N[u, v] += fresh[u, v]
    _prepare(P, N, pre)
    # the weights: the best ω_0 of the grid with the Δ shares (warm: the previous update's weights mixed
    # towards the cold start), then multiplicative steps towards the minimum of tr P⁺ over the simplex
    # (module docstring)
    if warm:
        # (1 − λ) × the previous weights + λ × (ω_0 = 1/2, the neighbours sharing the other half by Δ)
        omega[0] = (1.0 - SPLIT_CI_WARM_MIX) * weights[0] + 0.5 * SPLIT_CI_WARM_MIX
        norm = omega[0]
        for q in range(m):
            omega[q + 1] = (1.0 - SPLIT_CI_WARM_MIX) * weights[rows[q] + 1] + 0.5 * SPLIT_CI_WARM_MIX * share[q]
            norm += omega[q + 1]
        for q in range(m + 1):
            omega[q] /= norm
        n_steps = SPLIT_CI_WARM_STEPS
    else:
        best, best_w = np.inf, 0.5
        for g in range(1, SPLIT_CI_GRID):
            w = g / SPLIT_CI_GRID
            omega[0] = w
            for q in range(m):
                omega[q + 1] = (1.0 - w) * share[q]
            f = _fused_trace(P, N, pre, omega, m, rows, kind, target, h, r, a_d, a_n, prior_pp, prior_ind_pp, mats,
                             grad, False)
            if f < best:
                best, best_w = f, w
        omega[0] = best_w
        for q in range(m):
            omega[q + 1] = (1.0 - best_w) * share[q]
        n_steps = SPLIT_CI_STEPS
    for _ in range(n_steps):
        _fused_trace(P, N, pre, omega, m, rows, kind, target, h, r, a_d, a_n, prior_pp, prior_ind_pp, mats, grad,
                     True)
        _multiplicative_step(omega, grad, m)
    # the next update starts from these weights, unless they act on nothing (no dependent part left: every
    # weight gives the same update, and the steps only followed the gradients' rounding)
    weights[:] = 0.0
    if dep + P[0, 0] - N[0, 0] + P[1, 1] - N[1, 1] + P[2, 2] - N[2, 2] + P[3, 3] - N[3, 3] + P[4, 4] - N[4, 4] \
            + P[5, 5] - N[5, 5] > SPLIT_CI_DEPENDENT_FLOOR * (P[0, 0] + P[1, 1] + P[2, 2] + P[3, 3] + P[4, 4] + P[5, 5]):
        weights[0] = omega[0]
        for q in range(m):
            weights[rows[q] + 1] = omega[q + 1]
    # any weights on the simplex give a consistent update: the last ones, unless no update is better
    f = _fused_trace(P, N, pre, omega, m, rows, kind, target, h, r, a_d, a_n, prior_pp, prior_ind_pp, mats, grad,
                      False)
    if f < P[0, 0] + P[1, 1] + P[2, 2] + P[3, 3] + P[4, 4] + P[5, 5]:
        w = omega[0]
        # P1 = D'/ω_0 + N'
        for u in range(6):
            for v in range(6):
                P[u, v] = (P[u, v] - N[u, v]) / w + N[u, v]
        for q in range(m):
            l = rows[q]
            om = omega[q + 1]
            if kind[l] == PEER:
                hv = h[q]
                # y = z − h(x⁻) − H (x − x⁻), R_j = r + uᵀN_j u + uᵀD_j u / ω_j
                y = z[l, 0] - rng[q] - (hv[0] * (x[0] - x0[0]) + hv[1] * (x[1] - x0[1]) + hv[2] * (x[2] - x0[2]))
                rj = r[q] + a_n[q] + a_d[q] / om
                scalar_update(x, P, hv, -1, y, rj, c)
                # N_new through the row: (I − k H) N_new (I − k H)ᵀ + r k kᵀ (its own noise only)
                row_gain(c, hv, -1, rj, k)
                joseph_part(fresh, k, hv, -1, r[q], scratch)
            else:
                Pj, Nj = prior_pp[target[l]], prior_ind_pp[target[l]]
                # S = P1_pp + R_j, R_j = D_j / ω_j + N_j + r I
                for u in range(3):
                    for v in range(3):
                        S[u, v] = P[u, v] + (Pj[u, v] - Nj[u, v]) / om + Nj[u, v] + (r[q] if u == v else 0.0)
                inv3(S, Si)
                block_update(x, P, h[q], Si, K, G)
                # N_new through the block: N − K N[:3, :] − N[:, :3] Kᵀ + K (N_pp + r I) Kᵀ
                _joseph_block(fresh, K, r[q], G, S)
    N[:, :] = fresh
    return flops


@njit(cache=True)
def _prepare(P, N, pre):
    """The parts of tr P⁺ that do not depend on the weights (D' = P − N'): ``pre`` ``(7, 3, 3)`` gets
    D'_pp, N'_pp, G_DD = A_Dᵀ A_D, G_DN + G_DNᵀ, G_NN (A_D = D'[:, :3], A_N = N'[:, :3]), and [0, 0] of the
    last two holds tr D', tr N'."""
    for u in range(3):
        for v in range(3):
            pre[0, u, v] = P[u, v] - N[u, v]
            pre[1, u, v] = N[u, v]
            dd = dn = nd = nn = 0.0
            for a in range(6):
                du, dv = P[a, u] - N[a, u], P[a, v] - N[a, v]
                dd += du * dv
                dn += du * N[a, v]
                nd += N[a, u] * dv
                nn += N[a, u] * N[a, v]
            pre[2, u, v], pre[3, u, v], pre[4, u, v] = dd, dn + nd, nn
    trd = trn = 0.0
    for a in range(6):
        trd += P[a, a] - N[a, a]
        trn += N[a, a]
    pre[5, 0, 0], pre[6, 0, 0] = trd, trn


@njit(cache=True)
def _fused_trace(P, N, pre, omega, m, rows, kind, target, h, r, a_d, a_n, prior_pp, prior_ind_pp, mats, grad,
                 with_grad):
    """tr P⁺ (the whole state) at the weights ``omega`` (ω_0 the UAV's, ω_{q+1} its q-th peer channel's).

    The rows touch the position only, so with P1 = D'/ω_0 + N' (D' = P − N'), A = P1[:, :3] and
    M = Σ_j H_jᵀ R_j⁻¹ H_j (3×3), the push-through identity turns the 6×6 information form
    (P⁺)⁻¹ = P1⁻¹ + E M Eᵀ into 3×3 algebra:
        P⁺ = P1 − A X Aᵀ,   X = M (I + P1_pp M)⁻¹,   tr P⁺ = tr P1 − tr(X AᵀA),
    where AᵀA = G_DD/ω_0² + (G_DN + G_DNᵀ)/ω_0 + G_NN comes from ``_prepare`` (``pre``).

    With ``with_grad`` also ``grad[k]`` = −∂ tr P⁺ / ∂ω_k ≥ 0 (negative rounding clipped). With
    B = (I + P1_pp M)⁻¹, the position block of P⁺² is Q_pp = B AᵀA Bᵀ, and P⁺ P1⁻¹ = Z = I − A X Eᵀ:
    tr(Z D' Zᵀ)/ω_0² for the UAV, (uᵀQ_pp u) uᵀD_j u/(ω_j R_j)² for a range,
    tr(Q_pp R_j⁻¹ D_j R_j⁻¹)/ω_j² for a relative position. ``mats`` ``(8, 3, 3)``: scratch.
    Returns +inf where I + P1_pp M is singular (rounding on a vanishing D')."""
    S, Si, T, U, Mm, Bi, X, G = mats[0], mats[1], mats[2], mats[3], mats[4], mats[5], mats[6], mats[7]
    w0 = omega[0]
    iw = 1.0 / w0
    # M = Σ_j H_jᵀ R_j⁻¹ H_j
    for u in range(3):
        for v in range(3):
            Mm[u, v] = 0.0
    for q in range(m):
        om = omega[q + 1]
        l = rows[q]
        if kind[l] == PEER:
            # R_j = r + uᵀN_j u + uᵀD_j u / ω_j
            s = r[q] + a_n[q] + a_d[q] / om
            for u in range(3):
                for v in range(3):
                    Mm[u, v] += h[q, u] * h[q, v] / s
        else:
            # R_j = D_j / ω_j + N_j + r I
            Pj, Nj = prior_pp[target[l]], prior_ind_pp[target[l]]
            _rel_noise_inverse(Pj, Nj, om, r[q], S, Si)
            for u in range(3):
                for v in range(3):
                    Mm[u, v] += Si[u, v]
    # T = I + P1_pp M, Bi = T⁻¹, X = M Bi, G = AᵀA
    for u in range(3):
        for v in range(3):
            t = 0.0
            for e in range(3):
                t += (pre[0, u, e] * iw + pre[1, u, e]) * Mm[e, v]
            T[u, v] = t + (1.0 if u == v else 0.0)
            G[u, v] = (pre[2, u, v] * iw + pre[3, u, v]) * iw + pre[4, u, v]
    det = (T[0, 0] * (T[1, 1] * T[2, 2] - T[1, 2] * T[2, 1]) - T[0, 1] * (T[1, 0] * T[2, 2] - T[1, 2] * T[2, 0])
           + T[0, 2] * (T[1, 0] * T[2, 1] - T[1, 1] * T[2, 0]))
    if not det > 0.0:
        return np.inf
    inv3(T, Bi)
    f = pre[5, 0, 0] * iw + pre[6, 0, 0]
    for u in range(3):
        for v in range(3):
            X[u, v] = Mm[u, 0] * Bi[0, v] + Mm[u, 1] * Bi[1, v] + Mm[u, 2] * Bi[2, v]
    for u in range(3):
        for v in range(3):
            f -= X[u, v] * G[v, u]
    if not with_grad:
        return f
    # Q_pp = Bi G Biᵀ (in T)
    _sandwich_t(Bi, G, T, U)
    # g_0 ω_0² = tr(Z D' Zᵀ), Z = I − [A X, 0]: with W = A X (6×3), Z D' = D' − W D'[:3, :], summed
    # elementwise; the expanded 3×3 form tr D' − 2 tr(X A_Dᵀ A) + tr(D'_pp X AᵀA X) is cheaper but cancels
    # catastrophically where the peers dominate (GradualFault's followers: 0.45 m off the reference)
    g0 = 0.0
    for a in range(6):
        w_0 = w_1 = w_2 = 0.0
        for e in range(3):
            ae = (P[a, e] - N[a, e]) * iw + N[a, e]
            w_0 += ae * X[e, 0]
            w_1 += ae * X[e, 1]
            w_2 += ae * X[e, 2]
        for b in range(6):
            zd = (P[a, b] - N[a, b]) - (w_0 * (P[0, b] - N[0, b]) + w_1 * (P[1, b] - N[1, b])
                                        + w_2 * (P[2, b] - N[2, b]))
            zab = 1.0 if a == b else 0.0
            if b == 0:
                zab -= w_0
            elif b == 1:
                zab -= w_1
            elif b == 2:
                zab -= w_2
            g0 += zd * zab
    grad[0] = max(g0, 0.0) * iw * iw
    for q in range(m):
        om = omega[q + 1]
        l = rows[q]
        if kind[l] == PEER:
            s = r[q] + a_n[q] + a_d[q] / om
            uqu = 0.0
            for u in range(3):
                for v in range(3):
                    uqu += h[q, u] * T[u, v] * h[q, v]
            grad[q + 1] = max(uqu * a_d[q], 0.0) / (om * s) ** 2
        else:
            Pj, Nj = prior_pp[target[l]], prior_ind_pp[target[l]]
            _rel_noise_inverse(Pj, Nj, om, r[q], S, Si)
            # S ← D_j, X ← R_j⁻¹ D_j R_j⁻¹
            for u in range(3):
                for v in range(3):
                    S[u, v] = Pj[u, v] - Nj[u, v]
            _sandwich(Si, S, X, U)
            t = 0.0
            for u in range(3):
                for v in range(3):
                    t += T[u, v] * X[v, u]
            grad[q + 1] = max(t, 0.0) / (om * om)
    return f


@njit(cache=True, inline="always")
def _sandwich_t(B, M, out, tmp):
    """out = B M Bᵀ for a 3×3 B and a symmetric 3×3 M (tmp: scratch)."""
    for u in range(3):
        for v in range(3):
            tmp[u, v] = M[u, 0] * B[v, 0] + M[u, 1] * B[v, 1] + M[u, 2] * B[v, 2]
    for u in range(3):
        for v in range(3):
            out[u, v] = B[u, 0] * tmp[0, v] + B[u, 1] * tmp[1, v] + B[u, 2] * tmp[2, v]


@njit(cache=True, inline="always")
def _multiplicative_step(omega, grad, m):
    """ω_k ← ω_k √g_k / Σ_l ω_l √g_l, each at least ``OMEGA_FLOOR`` (then renormalised); no step when every g is 0.

    The multiplicative algorithm of optimal experimental design (Silvey, Titterington and Torsney 1978), with
    the power 1/2 that makes it monotone for the trace (A-optimality; Yu 2010): its fixed points have equal
    gradients wherever ω > 0, the minimum's condition on the simplex."""
    total = 0.0
    for q in range(m + 1):
        total += omega[q] * math.sqrt(grad[q])
    if not total > 0.0:
        return
    norm = 0.0
    for q in range(m + 1):
        omega[q] = max(omega[q] * math.sqrt(grad[q]) / total, OMEGA_FLOOR)
        norm += omega[q]
    for q in range(m + 1):
        omega[q] /= norm


@njit(cache=True, inline="always")
def _sandwich(B, M, out, tmp):
    """out = B M B for symmetric 3×3 B and M (tmp: scratch)."""
    for u in range(3):
        for v in range(3):
            tmp[u, v] = M[u, 0] * B[0, v] + M[u, 1] * B[1, v] + M[u, 2] * B[2, v]
    for u in range(3):
        for v in range(3):
            out[u, v] = B[u, 0] * tmp[0, v] + B[u, 1] * tmp[1, v] + B[u, 2] * tmp[2, v]


@njit(cache=True, inline="always")
def _rel_noise_inverse(Pj, Nj, om, r, S, Si):
    """S = R_j = D_j/ω_j + N_j + r I of a relative-position peer (D_j = P_j − N_j) and Si = R_j⁻¹."""
    for u in range(3):
        for v in range(3):
            S[u, v] = (Pj[u, v] - Nj[u, v]) / om + Nj[u, v] + (r if u == v else 0.0)
    inv3(S, Si)


@njit(cache=True, inline="always")
def _joseph_block(M, K, r, G, F):
    """M ← (I − K H) M (I − K H)ᵀ + r K Kᵀ for H = [I 0] (K ``(6, 3)``); G ``(6, 3)``, F ``(3, 3)`` scratch."""
    for a in range(6):
        for v in range(3):
            G[a, v] = M[a, v]
    for u in range(3):
        for v in range(3):
            F[u, v] = M[u, v] + (r if u == v else 0.0)
    for a in range(6):
        for b in range(a, 6):
            kfk = 0.0
            for u in range(3):
                for v in range(3):
                    kfk += K[a, u] * F[u, v] * K[b, v]
            val = (M[a, b] - (K[a, 0] * G[b, 0] + K[a, 1] * G[b, 1] + K[a, 2] * G[b, 2])
                   - (G[a, 0] * K[b, 0] + G[a, 1] * K[b, 1] + G[a, 2] * K[b, 2]) + kfk)
            M[a, b] = val
            M[b, a] = val
