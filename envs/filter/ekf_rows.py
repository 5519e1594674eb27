"""The update primitives the CEKF's peer updates share (``cekf``, ``peer_ci``, ``split_ci``).

One scalar row of a joint update linearised at the prior, a 3-row position block, tr(A S⁻¹ A),
covariance scaling, 3×3 and
symmetric 6×6 inverses, the independent part of a split covariance carried through a row's
gain (the search constants are in ``constants``). All are inlined into the kernels
that call them.
"""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True, inline="always")
def scalar_update(x, P, hvec, col, y, r, c):
    """One scalar row: H = hvec on the position block (or e_col if col >= 0).

    Leaves c = P⁻ Hᵀ (the covariance before the row) in the scratch ``c``; s = H c + r.
    """
    # c = P Hᵀ
    if col >= 0:
        for a in range(6):
            c[a] = P[a, col]
        s = c[col] + r  # s = H P Hᵀ + r
    else:
        for a in range(6):
            c[a] = P[a, 0] * hvec[0] + P[a, 1] * hvec[1] + P[a, 2] * hvec[2]
        s = c[0] * hvec[0] + c[1] * hvec[1] + c[2] * hvec[2] + r
    # x ← x + k y, k = c / s
    g = y / s
    for a in range(6):
        x[a] += c[a] * g
    # P ← P − c cᵀ / s (upper triangle, mirrored: exact symmetry)
    inv_s = 1.0 / s
    for a in range(6):
        for b2 in range(a, 6):
            v = P[a, b2] - c[a] * c[b2] * inv_s
            P[a, b2] = v
            P[b2, a] = v


@njit(cache=True, inline="always")
def scale_cov(P, inv_w):
    """P ← P / ω."""
    for a in range(6):
        for b2 in range(6):
            P[a, b2] *= inv_w


@njit(cache=True, inline="always")
def inv3(S, out):
    """out = S⁻¹ of a symmetric positive definite 3×3 (adjugate over determinant)."""
    out[0, 0] = S[1, 1] * S[2, 2] - S[1, 2] * S[2, 1]
    out[0, 1] = S[0, 2] * S[2, 1] - S[0, 1] * S[2, 2]
    out[0, 2] = S[0, 1] * S[1, 2] - S[0, 2] * S[1, 1]
    out[1, 0] = S[1, 2] * S[2, 0] - S[1, 0] * S[2, 2]
    out[1, 1] = S[0, 0] * S[2, 2] - S[0, 2] * S[2, 0]
    out[1, 2] = S[0, 2] * S[1, 0] - S[0, 0] * S[1, 2]
    out[2, 0] = S[1, 0] * S[2, 1] - S[1, 1] * S[2, 0]
    out[2, 1] = S[0, 1] * S[2, 0] - S[0, 0] * S[2, 1]
    out[2, 2] = S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0]
    det = S[0, 0] * out[0, 0] + S[0, 1] * out[1, 0] + S[0, 2] * out[2, 0]
    for u in range(3):
        for v in range(3):
            out[u, v] /= det


@njit(cache=True, inline="always")
def joseph_part(M, k, hvec, col, r, a):
    """A part M of the covariance through one scalar row's gain k: M ← (I − k H) M (I − k H)ᵀ + r k kᵀ.

    H = hvec on the position block (or e_col if col >= 0), as in ``scalar_update``; r is the
    part's share of the row's noise (0 for a part that takes none of it). a: scratch 6-vector.
    """
    # a = M Hᵀ, β = H M Hᵀ
    if col >= 0:
        for u in range(6):
            a[u] = M[u, col]
        beta = a[col]
    else:
        for u in range(6):
            a[u] = M[u, 0] * hvec[0] + M[u, 1] * hvec[1] + M[u, 2] * hvec[2]
        beta = a[0] * hvec[0] + a[1] * hvec[1] + a[2] * hvec[2]
    # (I − k H) M (I − k H)ᵀ + r k kᵀ = M − k aᵀ − a kᵀ + (β + r) k kᵀ (upper triangle, mirrored)
    q = beta + r
    for u in range(6):
        for v in range(u, 6):
            m = M[u, v] - k[u] * a[v] - a[u] * k[v] + q * k[u] * k[v]
            M[u, v] = m
            M[v, u] = m


@njit(cache=True, inline="always")
def inv_spd6(A, out, L):
    """out = A⁻¹ of a symmetric positive definite 6×6 by Cholesky (A = L Lᵀ, L: scratch 6×6).

    Returns False (``out`` then unspecified) where A is not positive definite."""
    for j in range(6):
        d = A[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        if not d > 0.0:
            return False
        L[j, j] = math.sqrt(d)
        for i in range(j + 1, 6):
            t = A[i, j]
            for k in range(j):
                t -= L[i, k] * L[j, k]
            L[i, j] = t / L[j, j]
    # L⁻¹ in the lower triangle of out, by forward substitution
    for j in range(6):
        out[j, j] = 1.0 / L[j, j]
        for i in range(j + 1, 6):
            t = 0.0
            for k in range(j, i):
                t -= L[i, k] * out[k, j]
            out[i, j] = t / L[i, i]
    # A⁻¹ = L⁻ᵀ L⁻¹ (symmetric: the lower triangle from L⁻¹, mirrored)
    for i in range(6):
        for j in range(i + 1):
            t = 0.0
            for k in range(i, 6):
                t += out[k, i] * out[k, j]
            L[i, j] = t
    for i in range(6):
        for j in range(i + 1):
            out[i, j] = L[i, j]
            out[j, i] = L[i, j]
    return True


@njit(cache=True, inline="always")
def tr_asa(P, Si):
    """tr(A S⁻¹ A) with A = P_pp (symmetric) and Si = S⁻¹."""
    t = 0.0
    for u in range(3):
        for v in range(3):
            av = 0.0
            for q in range(3):
                av += Si[u, q] * P[q, v]
            t += P[v, u] * av
    return t


@njit(cache=True, inline="always")
def block_update(x, P, meas, Si, K, top):
    """A 3-row block with H = [I 0] and S⁻¹ = Si: K = P[:, :3] S⁻¹, x ← x + K (meas − p), P ← P − K P[:3, :].

    K: ``(6, 3)`` output (the gain); top: ``(6, 3)`` scratch.
    """
    for a in range(6):
        for v in range(3):
            K[a, v] = P[a, 0] * Si[0, v] + P[a, 1] * Si[1, v] + P[a, 2] * Si[2, v]
    y0, y1, y2 = meas[0] - x[0], meas[1] - x[1], meas[2] - x[2]
    for a in range(6):
        x[a] += K[a, 0] * y0 + K[a, 1] * y1 + K[a, 2] * y2
    # P[:3, :]ᵀ = P[:, :3], read from a copy (upper triangle, mirrored)
    for a in range(6):
        for v in range(3):
            top[a, v] = P[a, v]
    for a in range(6):
        for b in range(a, 6):
            v = P[a, b] - (K[a, 0] * top[b, 0] + K[a, 1] * top[b, 1] + K[a, 2] * top[b, 2])
            P[a, b] = v
            P[b, a] = v
