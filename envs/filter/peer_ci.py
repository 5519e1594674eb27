"""The ``"ci"`` peer update: covariance intersection, peer by peer (the equations in ``cekf``'s docstring).

Julier and Uhlmann 1997. After the absolute channels, each peer channel in channel order: the
joint prior of (x_i, p_j) is bounded by blockdiag(P_i/ω, P_j/(1 − ω)), ω chosen per channel on
a grid; the UAV's covariance is rescaled by 1/ω once per peer.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from swarmloc.envs.filter.constants import CI_GRID
from swarmloc.envs.filter.constants import MIN_RANGE as _MIN_RANGE
from swarmloc.envs.filter.ekf_rows import block_update as _block_update
from swarmloc.envs.filter.ekf_rows import inv3 as _inv3
from swarmloc.envs.filter.ekf_rows import scalar_update as _scalar_update
from swarmloc.envs.filter.ekf_rows import scale_cov as _scale_cov
from swarmloc.envs.filter.ekf_rows import tr_asa as _tr_asa
from swarmloc.envs.tasks.channels import PEER, PEER_REL
from swarmloc.envs.world.cost import CI_RANGE_FLOPS, CI_REL_FLOPS, RANGE_ROW_FLOPS


@njit(cache=True, inline="always")
def _ci_range_row(x, P, hvec, Pj, y, r, c):
    """One peer range by covariance intersection (module docstring). Returns ω (1: no update)."""
    a = 0.0  # hᵀ P_i h
    b = 0.0  # hᵀ P_j h
    cc = 0.0  # ‖(P_i h)_pos‖²
    for u in range(3):
        cu = 0.0
        for v in range(3):
            a += hvec[u] * P[u, v] * hvec[v]
            b += hvec[u] * Pj[u, v] * hvec[v]
            cu += P[u, v] * hvec[v]
        cc += cu * cu
    tr = P[0, 0] + P[1, 1] + P[2, 2]
    # tr of P⁺'s position block: (tr − ‖(P h)_pos‖² / (ω S)) / ω; ω = 1 is no update (tr)
    best, best_w = tr, 1.0
    for k in range(1, CI_GRID):
        w = k / CI_GRID
        f = (tr - cc / (a + w * r + w * b / (1.0 - w))) / w
        if f < best:
            best, best_w = f, w
    if best_w < 1.0:
        _scalar_update(x, P, hvec, -1, y, best_w * r + best_w * b / (1.0 - best_w), c)
        _scale_cov(P, 1.0 / best_w)
    return best_w


@njit(cache=True, inline="always")
def _ci_rel_block(x, P, Pj, m, r, S, Si, K, top):
    """A relative position by covariance intersection, m = p̂_j − z a measurement of p_i. Returns ω.

    S, Si: scratch 3×3; K, top: scratch 6×3.
    """
    tr = P[0, 0] + P[1, 1] + P[2, 2]
    best, best_w = tr, 1.0
    for k in range(1, CI_GRID):
        w = k / CI_GRID
        for u in range(3):
            for v in range(3):
                S[u, v] = P[u, v] / w + Pj[u, v] / (1.0 - w) + (r if u == v else 0.0)
        _inv3(S, Si)
        # tr(A S⁻¹ A) with A = P_pp (symmetric)
        f = tr / w - _tr_asa(P, Si) / (w * w)
        if f < best:
            best, best_w = f, w
    if best_w >= 1.0:
        return 1.0
    w = best_w
    for u in range(3):
        for v in range(3):
            S[u, v] = P[u, v] / w + Pj[u, v] / (1.0 - w) + (r if u == v else 0.0)
    _inv3(S, Si)
    _scale_cov(P, 1.0 / w)
    # K = P[:, :3] S⁻¹ (on the scaled P), x ← x + K (m − p), P ← P − K P[:3, :]
    _block_update(x, P, m, Si, K, top)
    return w


@njit(cache=True)
def ci_peers(x, P, z, valid, alpha, kind, target, r0, prior_pos, prior_pp, alpha_th, alpha_min, active, x0, hvec, c):
    """The peer channels of one UAV by covariance intersection, in channel order (after its absolute
    channels; the arguments as ``update_uav``'s). Returns their FLOPs."""
    flops = 0
    S, Si, K, top = np.empty((3, 3)), np.empty((3, 3)), np.empty((6, 3)), np.empty((6, 3))
    for l in range(kind.shape[0]):
        ch = kind[l]
        if not (valid[l] and alpha[l] > alpha_th and (ch == PEER or ch == PEER_REL)):
            continue
        r = r0[l] / max(alpha[l], alpha_min)
        j = target[l]
        if ch == PEER_REL:
            for d in range(3):
                hvec[d] = prior_pos[j, d] - z[l, d]  # m = p̂_j − z, a measurement of p_i
            _ci_rel_block(x, P, prior_pp[j], hvec, r, S, Si, K, top)
            flops += CI_REL_FLOPS
        else:
            d0, d1, d2 = x0[0] - prior_pos[j, 0], x0[1] - prior_pos[j, 1], x0[2] - prior_pos[j, 2]
            rng = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            if rng < _MIN_RANGE:
                continue
            # at the prior, as every row: H = (p⁻ − p̂_j)ᵀ/‖p⁻ − p̂_j‖, y = z − h(x⁻) − H (x − x⁻)
            hvec[0], hvec[1], hvec[2] = d0 / rng, d1 / rng, d2 / rng
            y = z[l, 0] - rng - (hvec[0] * (x[0] - x0[0]) + hvec[1] * (x[1] - x0[1]) + hvec[2] * (x[2] - x0[2]))
            _ci_range_row(x, P, hvec, prior_pp[j], y, r, c)
            flops += RANGE_ROW_FLOPS + CI_RANGE_FLOPS
        active[l] = True
    return flops
