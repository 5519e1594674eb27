"""The information bound's kernels (numba): expected measurement information, prediction, update, inverses.

``pcrlb_kernel`` runs the recursion of ``bound.py`` in covariance form on the blocks
A = C_pp ``(3N, 3N)`` (positions of all UAVs, UAV-major: index 3i + axis), B = C_pr
``(3N, 3N·m)`` and V = C_rr ``(3N·m, 3N·m)``, where r = [v, (b), (f)] stacks the velocities and,
where the task has them, the accelerometer biases b and the IMU-fault biases f of all UAVs
(component c at index c·3N + 3i + axis; m = 1, 2 or 3); see the ``bound`` module docstring for
the maths and why this form.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from swarmloc.envs.tasks.channels import ANCHOR, GPS, LANDMARK, PEER, PEER_REL, TDOA

_MIN_RANGE = 1e-9  # a cubature point at zero distance has no direction: it adds nothing (the CEKF skips it too)
#: √3: the third-degree spherical-radial cubature points of a 3-vector sit at ±√3 L e_c (L Lᵀ = Σ)
_SQRT3 = math.sqrt(3.0)


@njit(cache=True)
def _add_sym(Lam, i, j, M, s):
    """Λ[3i:3i+3, 3j:3j+3] += s·M (M ``(3, 3)``)."""
    for r in range(3):
        for c in range(3):
            Lam[3 * i + r, 3 * j + c] += s * M[r, c]


@njit(cache=True)
def _add_diag(Lam, i, j, s):
    """Λ[3i:3i+3, 3j:3j+3] += s·I."""
    for d in range(3):
        Lam[3 * i + d, 3 * j + d] += s


@njit(cache=True)
def _cholesky3(S, L):
    """L Lᵀ = S of a symmetric positive semi-definite ``(3, 3)`` S (lower triangular L, in place).

    A pivot that is not positive (a direction S does not spread) gives a zero column, so the
    factor of a semi-definite S is still a square root; for a positive-definite S it is the
    unique Cholesky factor (``numpy.linalg.cholesky``).
    """
    L[:] = 0.0
    for j in range(3):
        s = S[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            continue
        L[j, j] = math.sqrt(s)
        for i in range(j + 1, 3):
            t = S[i, j]
            for k in range(j):
                t -= L[i, k] * L[j, k]
            L[i, j] = t / L[j, j]


@njit(cache=True)
def _expected_direction(ch, x0, x1, x2, anchors, ia, ib, L, M):
    """M = E[g gᵀ] ``(3, 3)`` of a range's gradient g over its argument x ~ N(x̄, L Lᵀ), by cubature.

    The third-degree spherical-radial rule (Arasaratnam & Haykin 2009): the six points
    x̄ ± √3 L e_c, weight 1/6 each. For a range (ANCHOR or PEER) x = p_i − q is the
    difference vector and g = x/‖x‖; for a TDOA pair (anchors ia, ib) x = p_i and
    g = (x − a_b)/‖x − a_b‖ − (x − a_a)/‖x − a_a‖. A point at zero distance adds nothing.
    """
    M[:] = 0.0
    for c in range(3):
        for sgn in (1.0, -1.0):
            y0 = x0 + sgn * _SQRT3 * L[0, c]
            y1 = x1 + sgn * _SQRT3 * L[1, c]
            y2 = x2 + sgn * _SQRT3 * L[2, c]
            if ch == TDOA:
                e0, e1, e2 = y0 - anchors[ib, 0], y1 - anchors[ib, 1], y2 - anchors[ib, 2]
                f0, f1, f2 = y0 - anchors[ia, 0], y1 - anchors[ia, 1], y2 - anchors[ia, 2]
                rb = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
                ra = math.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
                if rb < _MIN_RANGE or ra < _MIN_RANGE:
                    continue
                g0, g1, g2 = e0 / rb - f0 / ra, e1 / rb - f1 / ra, e2 / rb - f2 / ra
            else:
                rng = math.sqrt(y0 * y0 + y1 * y1 + y2 * y2)
                if rng < _MIN_RANGE:
                    continue
                g0, g1, g2 = y0 / rng, y1 / rng, y2 / rng
            g = (g0, g1, g2)
            for r in range(3):
                for q in range(3):
                    M[r, q] += g[r] * g[q] / 6.0


@njit(cache=True)
def position_information(pos, use, kind, target, r0, anchors, landmarks, A, Lam):
    """Λ = Σ_c E[H_cᵀ R_c⁻¹ H_c] on the positions ``(3N, 3N)`` of one step, by 3×3 blocks (in place).

    The expectation is over the positions p ~ N(truth, A), A the predicted position covariance
    of the step (the bound's own C⁻_pp); a linear channel's H is constant, a range's is
    averaged by ``_expected_direction`` over its argument's 3×3 covariance (an anchor's
    Σ = A_ii; a peer's d = p_i − p_j has Σ = A_ii + A_jj − A_ij − A_ji; a TDOA's Σ = A_ii).

    Args:
        pos: ``(N, 3)`` true positions; use ``(N, L)``; kind, target, r0 ``(N, L)``.
        anchors ``(A, 3)``, landmarks ``(M, 3)``.
        A: ``(3N, 3N)`` predicted position covariance.
        Lam: ``(3N, 3N)`` output (overwritten).

    Returns:
        The number of channels that entered.
    """
    Lam[:] = 0.0
    n, n_l = kind.shape
    S = np.empty((3, 3))
    L = np.empty((3, 3))
    M = np.empty((3, 3))
    n_a = anchors.shape[0]
    used = 0
    for i in range(n):
        for l in range(n_l):
            if not use[i, l]:
                continue
            ch = kind[i, l]
            j = target[i, l]
            w = 1.0 / r0[i, l]
            if ch == ANCHOR or ch == PEER or ch == TDOA:
                ia, ib = 0, 0
                for r in range(3):
                    for c in range(3):
                        S[r, c] = A[3 * i + r, 3 * i + c]
                if ch == ANCHOR:
                    x0, x1, x2 = pos[i, 0] - anchors[j, 0], pos[i, 1] - anchors[j, 1], pos[i, 2] - anchors[j, 2]
                elif ch == PEER:
                    x0, x1, x2 = pos[i, 0] - pos[j, 0], pos[i, 1] - pos[j, 1], pos[i, 2] - pos[j, 2]
                    for r in range(3):
                        for c in range(3):
                            S[r, c] += (A[3 * j + r, 3 * j + c] - A[3 * i + r, 3 * j + c]
                                        - A[3 * j + r, 3 * i + c])
                else:
                    # the pair code j = a·A + b: h = ‖p_i − a_b‖ − ‖p_i − a_a‖
                    ia, ib = j // n_a, j % n_a
                    x0, x1, x2 = pos[i, 0], pos[i, 1], pos[i, 2]
                _cholesky3(S, L)
                _expected_direction(ch, x0, x1, x2, anchors, ia, ib, L, M)
                # a range: H_i = gᵀ; a peer q = p_j has H_j = −gᵀ
                _add_sym(Lam, i, i, M, w)
                if ch == PEER:
                    _add_sym(Lam, j, j, M, w)
                    _add_sym(Lam, i, j, M, -w)
                    _add_sym(Lam, j, i, M, -w)
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
def predict_covariance(A, B, V, dt, q, act, M):
    """C⁻ = F C Fᵀ + Q in place, on the blocks A = C_pp, B = C_pr, V = C_rr (r = [v, (b), (f)]).

    Per UAV and axis, with a the accelerometer's reading and the IMU model u = a + b + s·f + n
    (n ~ N(0, q)), the motion integrates a = u − b − s·f − n:

        p⁺ = p + dt·v − dt²/2·(b + s·f + n),   v⁺ = v − dt·(b + s·f + n),   b⁺ = b,   f⁺ = f,

    s ∈ {0, 1} whether the UAV's IMU fault is active at this step (``act[c, i]`` for component
    c ≥ 1: 1 for the bias b, s for f). With p⁺ = p + D r, r⁺ = E r (D, E scalar per block):

        M = B + D V,   A⁻ = A + D Bᵀ + M Dᵀ + q·dt⁴/4 I,   B⁻ = M Eᵀ + q·dt³/2 [I 0 …],
        V⁻ = E V Eᵀ + q·dt² [I 0 …; 0 0 …],

    all elementwise on 3N × 3N blocks (F and Q act on each UAV alone): O(m²·(3N)²), no
    product. For m = 1 this is A⁻ = A + dt (B + Bᵀ) + dt² V, B⁻ = B + dt V, V⁻ = V + q dt² I.

    Args:
        A ``(3N, 3N)``, B ``(3N, 3N·m)``, V ``(3N·m, 3N·m)``: updated in place.
        dt, q: step [s] and accelerometer noise variance [m²/s⁴].
        act: ``(m, N)`` the multipliers s of the components c ≥ 1 (row 0 unused).
        M: ``(3N, 3N·m)`` scratch.
    """
    n3 = A.shape[0]
    m = V.shape[0] // n3
    h2 = 0.5 * dt * dt
    # M = B + D V: row x of D V is Σ_c d_c(x) V[c·3N + x, :], d_0 = dt, d_c = −dt²/2·act[c]
    for x in range(n3):
        ui = x // 3
        for col in range(n3 * m):
            s = B[x, col] + dt * V[x, col]
            for c in range(1, m):
                s -= h2 * act[c, ui] * V[c * n3 + x, col]
            M[x, col] = s
    # A⁻ = A + D Bᵀ + M Dᵀ: (D Bᵀ)[x, y] = Σ_c d_c(x) B[y, c·3N + x]; (M Dᵀ)[x, y] = Σ_c M[x, c·3N + y] d_c(y)
    for x in range(n3):
        ux = x // 3
        for y in range(n3):
            uy = y // 3
            s = A[x, y] + dt * B[y, x] + dt * M[x, y]
            for c in range(1, m):
                s -= h2 * (act[c, ux] * B[y, c * n3 + x] + act[c, uy] * M[x, c * n3 + y])
            A[x, y] = s
    # B⁻ = M Eᵀ: the v column of UAV y gains Σ_{c≥1} e_c(y) M[x, c·3N + y], e_c = −dt·act[c]; the others are M's
    for x in range(n3):
        for y in range(n3):
            uy = y // 3
            s = M[x, y]
            for c in range(1, m):
                s -= dt * act[c, uy] * M[x, c * n3 + y]
            B[x, y] = s
            for c in range(1, m):
                B[x, c * n3 + y] = M[x, c * n3 + y]
    # V⁻ = E V Eᵀ: first the v rows (E V), then the v columns ((E V) Eᵀ); the other rows/columns stay
    if m > 1:
        for x in range(n3):
            ux = x // 3
            for col in range(n3 * m):
                s = V[x, col]
                for c in range(1, m):
                    s -= dt * act[c, ux] * V[c * n3 + x, col]
                V[x, col] = s
        for row in range(n3 * m):
            for y in range(n3):
                uy = y // 3
                s = V[row, y]
                for c in range(1, m):
                    s -= dt * act[c, uy] * V[row, c * n3 + y]
                V[row, y] = s
    # Q = q·G Gᵀ on p and v (G = [dt²/2; dt] per axis: the accelerometer noise enters both with the same sign)
    for d in range(n3):
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

    With S = A (the predicted C_pp) and K = C_rp S⁻¹ (the regression of the other states r =
    [v, (b), (f)] on the positions, which a position measurement leaves unchanged):
        P = (S⁻¹ + Λ)⁻¹,  C_rp⁺ = K P,  C_rr⁺ = C_rr − K (S − P) Kᵀ = C_rr − (C_rp − C_rp⁺) Kᵀ
    (K S Kᵀ = C_rp Kᵀ, K P Kᵀ = C_rp⁺ Kᵀ). In terms of B = C_pr ``(3N, 3N·m)`` and Kᵀ = S⁻¹ B:
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
    n_r = V.shape[0]
    for r in range(n_r):
        for c in range(r + 1, n_r):
            m = 0.5 * (V[r, c] + V[c, r])
            V[r, c] = m
            V[c, r] = m
    A[:] = P
    B[:] = B_post
    return True


@njit(cache=True)
def pcrlb_kernel(w, episodes, pos_var, failed_at):
    """The recursion for the listed episodes (serial: a suite computes tasks one after another).

    The state beyond the positions is r = [v, (b), (f)]: the accelerometer bias b where
    ``w.bias_sigma`` > 0, the IMU-fault bias f where any episode of the batch has an IMU fault
    (``w.fault_var``); see ``predict_covariance``.

    Args:
        w: ``BoundInputs``; episodes: ``(E,)`` indices into its batch.
        pos_var: ``(T, B, N)`` output; failed_at: ``(B,)`` output.
    """
    n_t, n = w.pos.shape[0], w.pos.shape[2]
    n3 = 3 * n
    q = w.imu_sigma * w.imu_sigma
    has_b = w.bias_sigma > 0.0
    has_f = False
    for e in range(episodes.shape[0]):
        if (w.fault_var[:, episodes[e]] > 0.0).any():
            has_f = True
    m = 1 + int(has_b) + int(has_f)
    cb = 1 if has_b else -1
    cf = m - 1 if has_f else -1
    act = np.zeros((m, n))
    if has_b:
        act[cb, :] = 1.0
    Lam = np.zeros((n3, n3))
    A = np.zeros((n3, n3))
    B = np.zeros((n3, n3 * m))
    V = np.zeros((n3 * m, n3 * m))
    M = np.zeros((n3, n3 * m))
    for e in range(episodes.shape[0]):
        b = episodes[e]
        # C₀ = P₀ (J₀ = P₀⁻¹): the filter's diagonal initial covariance, the bias prior σ_b² I; f is
        # reset at each fault's onset (its value before does not enter the motion: any variance)
        A[:] = 0.0
        B[:] = 0.0
        V[:] = 0.0
        for x in range(n3):
            A[x, x] = w.p0_diag[x % 3]
            V[x, x] = w.p0_diag[3 + x % 3]
            if has_b:
                V[cb * n3 + x, cb * n3 + x] = w.bias_sigma * w.bias_sigma
            if has_f:
                V[cf * n3 + x, cf * n3 + x] = 1.0
        failed_at[b] = -1
        for k in range(n_t):
            if has_f:
                for i in range(n):
                    fv = w.fault_var[k, b, i]
                    act[cf, i] = 1.0 if fv > 0.0 else 0.0
                    if fv > 0.0 and (k == 0 or w.fault_var[k - 1, b, i] != fv):
                        # onset: f_i ~ N(0, fv I), independent of everything so far
                        for d in range(3):
                            x = cf * n3 + 3 * i + d
                            B[:, x] = 0.0
                            V[:, x] = 0.0
                            V[x, :] = 0.0
                            V[x, x] = fv
            predict_covariance(A, B, V, w.dt, q, act, M)
            used = position_information(w.pos[k, b], w.use[k, b], w.kind, w.target, w.r0, w.anchors,
                                        w.landmarks, A, Lam)
            if used > 0 and not update_covariance(A, B, V, Lam):
                failed_at[b] = k
                pos_var[k:, b, :] = np.nan
                break
            for i in range(n):
                pos_var[k, b, i] = A[3 * i, 3 * i] + A[3 * i + 1, 3 * i + 1] + A[3 * i + 2, 3 * i + 2]
