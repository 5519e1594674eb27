"""The information bound's kernels (numba): measurement information, prediction, update, inverses.

``pcrlb_kernel`` runs the recursion of ``bound.py`` in covariance form on the blocks
A = C_pp, B = C_pv, V = C_vv (each 3N × 3N, positions and velocities of all UAVs, UAV-major:
index 3i + axis); see the ``bound`` module docstring for the maths and why this form.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from swarmloc.envs.tasks.channels import ANCHOR, GPS, LANDMARK, PEER, PEER_REL, TDOA

_MIN_RANGE = 1e-9  # the CEKF skips a range at zero distance (no Jacobian): so does the bound


@njit(cache=True)
def _add_block(Lam, i, j, u0, u1, u2, s):
    """Λ[3i:3i+3, 3j:3j+3] += s·u uᵀ."""
    u = (u0, u1, u2)
    for r in range(3):
        for c in range(3):
            Lam[3 * i + r, 3 * j + c] += s * u[r] * u[c]


@njit(cache=True)
def _add_diag(Lam, i, j, s):
    """Λ[3i:3i+3, 3j:3j+3] += s·I."""
    for d in range(3):
        Lam[3 * i + d, 3 * j + d] += s


@njit(cache=True)
def position_information(pos, use, kind, target, r0, anchors, landmarks, Lam):
    """Λ = Σ_c H_cᵀ R_c⁻¹ H_c on the positions ``(3N, 3N)`` of one step, by 3×3 blocks (in place).

    Args:
        pos: ``(N, 3)`` true positions; use ``(N, L)``; kind, target, r0 ``(N, L)``.
        anchors ``(A, 3)``, landmarks ``(M, 3)``.
        Lam: ``(3N, 3N)`` output (overwritten).

    Returns:
        The number of channels that entered.
    """
    Lam[:] = 0.0
    n, n_l = kind.shape
    used = 0
    for i in range(n):
        for l in range(n_l):
            if not use[i, l]:
                continue
            ch = kind[i, l]
            j = target[i, l]
            w = 1.0 / r0[i, l]
            if ch == ANCHOR or ch == PEER:
                if ch == ANCHOR:
                    d0, d1, d2 = pos[i, 0] - anchors[j, 0], pos[i, 1] - anchors[j, 1], pos[i, 2] - anchors[j, 2]
                else:
                    d0, d1, d2 = pos[i, 0] - pos[j, 0], pos[i, 1] - pos[j, 1], pos[i, 2] - pos[j, 2]
                rng = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                if rng < _MIN_RANGE:
                    continue
                # h = ‖p_i − q‖: H_i = uᵀ, u = (p_i − q)/‖p_i − q‖; a peer q = p_j has H_j = −uᵀ
                u0, u1, u2 = d0 / rng, d1 / rng, d2 / rng
                _add_block(Lam, i, i, u0, u1, u2, w)
                if ch == PEER:
                    _add_block(Lam, j, j, u0, u1, u2, w)
                    _add_block(Lam, i, j, u0, u1, u2, -w)
                    _add_block(Lam, j, i, u0, u1, u2, -w)
            elif ch == TDOA:
                # h = ‖p_i − a_b‖ − ‖p_i − a_a‖ of the pair code j = a·A + b: H_i = (u_b − u_a)ᵀ
                n_a = anchors.shape[0]
                ia, ib = j // n_a, j % n_a
                e0, e1, e2 = pos[i, 0] - anchors[ib, 0], pos[i, 1] - anchors[ib, 1], pos[i, 2] - anchors[ib, 2]
                f0, f1, f2 = pos[i, 0] - anchors[ia, 0], pos[i, 1] - anchors[ia, 1], pos[i, 2] - anchors[ia, 2]
                rb = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
                ra = np.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
                if rb < _MIN_RANGE or ra < _MIN_RANGE:
                    continue
                _add_block(Lam, i, i, e0 / rb - f0 / ra, e1 / rb - f1 / ra, e2 / rb - f2 / ra, w)
            elif ch == GPS or ch == LANDMARK:
                # h = p_i (GPS) or m − p_i (landmark): H_i = ±I, Hᵀ R⁻¹ H = I/r0
                _add_diag(Lam, i, i, w)
            elif ch == PEER_REL:
                # h = p_j − p_i: H_i = −I, H_j = I
                _add_diag(Lam, i, i, w)
                _add_diag(Lam, j, j, w)
                _add_diag(Lam, i, j, -w)
                _add_diag(Lam, j, i, -w)
            used += 1
    return used


@njit(cache=True)
def predict_covariance(A, B, V, dt, q):
    """C⁻ = F C Fᵀ + Q in place, on the blocks A = C_pp, B = C_pv, V = C_vv ``(3N, 3N)``.

    F = [[I, dt I], [0, I]]: A⁻ = A + dt (B + Bᵀ) + dt² V, B⁻ = B + dt V, V⁻ = V; Q = q G Gᵀ
    adds q·dt⁴/4, q·dt³/2 and q·dt² to the diagonals of A, B and V (``cekf.predict_uav``
    for the whole swarm: F and Q act on each UAV alone, so this is O((3N)²)).
    """
    n = A.shape[0]
    h2 = 0.5 * dt * dt
    for r in range(n):
        for c in range(n):
            A[r, c] += dt * (B[r, c] + B[c, r]) + dt * dt * V[r, c]
    for r in range(n):
        for c in range(n):
            B[r, c] += dt * V[r, c]
    for d in range(n):
        A[d, d] += q * h2 * h2
        B[d, d] += q * h2 * dt
        V[d, d] += q * dt * dt


#: matrices up to this size are inverted in plain loops; larger ones by 2×2 blocks (``spd_inverse``)
_LEAF = 24


@njit(cache=True)
def _spd_inverse_leaf(A, X):
    """X = A⁻¹ of a small symmetric positive-definite A by Cholesky (A = L Lᵀ, A⁻¹ = L⁻ᵀ L⁻¹).

    Returns False (X undefined) when a pivot is not positive: A is not positive definite.
    Loops run along rows (L and Wᵀ = L⁻ᵀ are stored row-major the way they are read).
    """
    n = A.shape[0]
    L = np.zeros((n, n))
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:  # also catches NaN
            return False
        L[j, j] = np.sqrt(s)
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
    # Wt = (L⁻¹)ᵀ, upper triangular: row j of Wt is column j of L⁻¹ (forward substitution)
    Wt = np.zeros((n, n))
    for j in range(n):
        Wt[j, j] = 1.0 / L[j, j]
        for i in range(j + 1, n):
            s = 0.0
            for k in range(j, i):
                s -= L[i, k] * Wt[j, k]
            Wt[j, i] = s / L[i, i]
    # A⁻¹ = L⁻ᵀ L⁻¹: X_ij = Σ_k (L⁻¹)_ki (L⁻¹)_kj = Σ_k Wt_ik Wt_jk (upper triangle, mirrored: exactly symmetric)
    for i in range(n):
        for j in range(i, n):
            s = 0.0
            for k in range(j, n):
                s += Wt[i, k] * Wt[j, k]
            X[i, j] = s
            X[j, i] = s
    return True


@njit(cache=True)
def spd_inverse(A, X):
    """X = A⁻¹ of a symmetric positive-definite A ``(n, n)``; False if A is not positive definite.

    Block inversion through the Schur complement, recursively (the work is in matrix
    products, which BLAS does several times faster than LAPACK's triangular solves at these
    sizes): with A = [[A₁₁, A₁₂], [A₂₁, A₂₂]], T = A₁₁⁻¹ A₁₂ and Σ = A₂₂ − A₂₁ T,
        A⁻¹ = [[A₁₁⁻¹ + T Σ⁻¹ Tᵀ, −T Σ⁻¹], [−Σ⁻¹ Tᵀ, Σ⁻¹]].
    A is positive definite iff A₁₁ and Σ are, so the recursion doubles as the test (block
    Cholesky: no pivoting is needed for a positive-definite matrix).
    """
    n = A.shape[0]
    if n <= _LEAF:
        return _spd_inverse_leaf(A, X)
    h = n // 2
    A12 = np.ascontiguousarray(A[:h, h:])
    X11 = np.empty((h, h))
    if not spd_inverse(np.ascontiguousarray(A[:h, :h]), X11):
        return False
    # T = A₁₁⁻¹ A₁₂
    T = X11 @ A12
    # Σ = A₂₂ − A₂₁ T (symmetrised: rounding would otherwise break the exact symmetry)
    Sigma = np.ascontiguousarray(A[h:, h:]) - A12.T @ T
    Sigma = 0.5 * (Sigma + Sigma.T)
    X22 = np.empty((n - h, n - h))
    if not spd_inverse(Sigma, X22):
        return False
    # X₁₂ = −T Σ⁻¹,  X₁₁ = A₁₁⁻¹ + T Σ⁻¹ Tᵀ = A₁₁⁻¹ − X₁₂ Tᵀ
    X12 = -(T @ X22)
    X11 = X11 - X12 @ T.T
    X[:h, :h] = 0.5 * (X11 + X11.T)
    X[:h, h:] = X12
    X[h:, :h] = X12.T
    X[h:, h:] = X22
    return True


@njit(cache=True)
def update_covariance(A, B, V, Lam):
    """Condition C = [[A, B], [Bᵀ, V]] on position information Λ ``(3N, 3N)``, in place (Λ is used as scratch).

    With S = A (the predicted C_pp) and K = C_vp S⁻¹ (the velocities' regression on the
    positions, which a position measurement leaves unchanged):
        P = (S⁻¹ + Λ)⁻¹,  C_vp⁺ = K P,  C_vv⁺ = C_vv − K (S − P) Kᵀ = C_vv − (C_vp − C_vp⁺) Kᵀ
    (K S Kᵀ = C_vp Kᵀ, K P Kᵀ = C_vp⁺ Kᵀ). In terms of B = C_pv and Kᵀ = S⁻¹ B:
    B⁺ = P Kᵀ, V⁺ = V − (B − B⁺)ᵀ Kᵀ. Two symmetric positive-definite inverses of size 3N and
    three products.

    Returns:
        False when S or S⁻¹ + Λ is not positive definite numerically (A, B, V unchanged).
    """
    n = A.shape[0]
    Y = np.empty((n, n))
    P = np.empty((n, n))
    # Y = S⁻¹: the predicted position information
    if not spd_inverse(A, Y):
        return False
    # P = (S⁻¹ + Λ)⁻¹
    Lam += Y
    if not spd_inverse(Lam, P):
        return False
    # Kᵀ = S⁻¹ C_pv
    Kt = Y @ B
    # C_pv⁺ = P Kᵀ
    B_post = P @ Kt
    # C_vv⁺ = C_vv − (C_pv − C_pv⁺)ᵀ Kᵀ, symmetrised (exact symmetry is lost to rounding)
    B -= B_post
    V -= B.T @ Kt
    for r in range(n):
        for c in range(r + 1, n):
            m = 0.5 * (V[r, c] + V[c, r])
            V[r, c] = m
            V[c, r] = m
    A[:] = P
    B[:] = B_post
    return True


@njit(cache=True)
def pcrlb_kernel(w, episodes, pos_var, failed_at):
    """The recursion for the listed episodes (serial: a suite computes tasks one after another).

    Args:
        w: ``BoundInputs``; episodes: ``(E,)`` indices into its batch.
        pos_var: ``(T, B, N)`` output; failed_at: ``(B,)`` output.
    """
    n_t, n = w.pos.shape[0], w.pos.shape[2]
    q = w.imu_sigma * w.imu_sigma
    Lam = np.zeros((3 * n, 3 * n))
    A = np.zeros((3 * n, 3 * n))
    B = np.zeros((3 * n, 3 * n))
    V = np.zeros((3 * n, 3 * n))
    for e in range(episodes.shape[0]):
        b = episodes[e]
        # C₀ = P₀ (J₀ = P₀⁻¹): the filter's diagonal initial covariance
        A[:] = 0.0
        B[:] = 0.0
        V[:] = 0.0
        for i in range(n):
            for d in range(3):
                A[3 * i + d, 3 * i + d] = w.p0_diag[d]
                V[3 * i + d, 3 * i + d] = w.p0_diag[3 + d]
        failed_at[b] = -1
        for k in range(n_t):
            predict_covariance(A, B, V, w.dt, q)
            used = position_information(w.pos[k, b], w.use[k, b], w.kind, w.target, w.r0, w.anchors,
                                        w.landmarks, Lam)
            if used > 0 and not update_covariance(A, B, V, Lam):
                failed_at[b] = k
                pos_var[k:, b, :] = np.nan
                break
            for i in range(n):
                pos_var[k, b, i] = A[3 * i, 3 * i] + A[3 * i + 1, 3 * i + 1] + A[3 * i + 2, 3 * i + 2]
