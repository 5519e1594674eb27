"""Estimate fusion and χ² consistency tests (dtvirm §3.6–3.7, federated §4).

Pure, vectorized numpy in float64; every function broadcasts over leading dims ``...``
(typically B envs, N UAVs). D is the state dimension, m a measurement dimension, S the
number of sub-filters.

- ``ci_fuse``: covariance intersection (dtvirm eq. 38–39) for estimates whose error
  correlation is unknown, with ω* = argmin tr P_CI.
- ``independent_fuse``: the optimal fusion when the errors are independent, for comparison
  (CI is never tighter: P_CI ⪰ P_opt).
- ``chi2_soft_weight``: dtvirm §3.7 UWB adaptive adjustment, w = 1 inside the 95 % χ²
  gate, exponential down-weighting beyond it.
- ``chi2_threshold``, ``normalized_innovation_squared``, ``chi2_fault_test``: residual χ²
  fault detection (federated eq. 13–16), T_D from the false-alarm probability.
- ``residual_ratio``, ``allocation_coefficients``, ``adapted_noise``,
  ``share_information``: the adaptive information-allocation coefficient (federated
  eq. 17–23).
- ``federated_fuse``: the master filter's global fusion (federated eq. 31), with faulty
  sub-filters isolated by a mask.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.stats import chi2

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]


# --------------------------------------------------------------------------- checks


def _finite(name: str, v: FloatArray) -> None:
    if not np.isfinite(v).all():
        idx = tuple(int(i) for i in np.argwhere(~np.isfinite(v))[0])
        raise ValueError(f"{name} must be finite; got {float(v[idx])} at index {idx}")


def _gaussian(name_x: str, x: npt.ArrayLike, name_P: str, P: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Validate a mean (..., D) and covariance (..., D, D); returns float64 arrays."""
    x = np.asarray(x, dtype=np.float64)
    P = np.asarray(P, dtype=np.float64)
    if x.ndim < 1 or x.shape[-1] < 1:
        raise ValueError(f"{name_x} must have shape (..., D) with D >= 1; got {x.shape}")
    D = x.shape[-1]
    if P.ndim < 2 or P.shape[-2:] != (D, D):
        raise ValueError(f"{name_P} must have shape (..., {D}, {D}) to match {name_x} {x.shape}; got {P.shape}")
    _finite(name_x, x)
    _finite(name_P, P)
    return x, P


def _cholesky(name: str, P: FloatArray) -> FloatArray:
    try:
        return np.linalg.cholesky(P)
    except np.linalg.LinAlgError:
        eig_min = float(np.linalg.eigvalsh(0.5 * (P + np.swapaxes(P, -1, -2))).min())
        raise ValueError(
            f"{name} must be symmetric positive definite; smallest eigenvalue is {eig_min:.3g}"
        ) from None


def _sym(P: FloatArray) -> FloatArray:
    # P ← ½ (P + Pᵀ): removes the rounding asymmetry of products like W Λ Wᵀ.
    return 0.5 * (P + np.swapaxes(P, -1, -2))


# --------------------------------------------------------------------------- fusion


def ci_fuse(
    x_a: npt.ArrayLike, P_a: npt.ArrayLike, x_b: npt.ArrayLike, P_b: npt.ArrayLike, *, iters: int = 64
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Covariance intersection of two estimates with unknown cross-correlation (dtvirm §3.6).

    P_CI⁻¹ = ω P_a⁻¹ + (1−ω) P_b⁻¹ and x_CI = P_CI (ω P_a⁻¹ x_a + (1−ω) P_b⁻¹ x_b), with
    ω* = argmin_{ω∈[0,1]} tr P_CI(ω). (dtvirm eq. 38 weights P_j⁻¹ by α: with a = the
    local estimate i and b = the neighbour j, α = 1 − ω.) Method: simultaneous
    diagonalization. With P_b = L Lᵀ and L⁻¹ P_a L⁻ᵀ = U diag(g) Uᵀ, W = L U gives
    P_CI(ω) = W diag(g / (ω + (1−ω) g)) Wᵀ, so tr P_CI is a scalar rational function of ω,
    convex on [0, 1]; ω* is found by bisection on its derivative (``iters`` halvings,
    64 reach float64 resolution), vectorized over the batch. Only the triangular Cholesky
    factor of P_b is inverted, never a covariance.

    Args:
        x_a: (..., D) first estimate.
        P_a: (..., D, D) its covariance, symmetric positive definite.
        x_b: (..., D) second estimate.
        P_b: (..., D, D) its covariance, symmetric positive definite.
        iters: bisection steps for ω*, ≥ 1.

    Returns:
        x: (..., D) fused estimate; P: (..., D, D) fused covariance; omega: (...) ω*, the
        weight of estimate a.
    """
    x_a, P_a = _gaussian("x_a", x_a, "P_a", P_a)
    x_b, P_b = _gaussian("x_b", x_b, "P_b", P_b)
    if x_a.shape[-1] != x_b.shape[-1]:
        raise ValueError(f"x_a and x_b must have the same D; got {x_a.shape} and {x_b.shape}")
    if iters < 1:
        raise ValueError(f"iters must be >= 1; got {iters}")
    lead = np.broadcast_shapes(x_a.shape[:-1], P_a.shape[:-2], x_b.shape[:-1], P_b.shape[:-2])
    D = x_a.shape[-1]
    _cholesky("P_a", P_a)
    L = _cholesky("P_b", P_b)  # P_b = L Lᵀ
    L_inv = np.linalg.inv(L)
    # G = L⁻¹ P_a L⁻ᵀ = U diag(g) Uᵀ
    g, U = np.linalg.eigh(_sym(L_inv @ P_a @ np.swapaxes(L_inv, -1, -2)))
    g = np.broadcast_to(g, lead + (D,))
    W = L @ U
    c = np.broadcast_to(np.sum(W**2, axis=-2), lead + (D,))  # c_i = ‖W[:, i]‖²

    # f(ω) = Σ_i c_i g_i / (ω + (1−ω) g_i),  f'(ω) = −Σ_i c_i g_i (1 − g_i) / (ω + (1−ω) g_i)²
    # A slope below rounding level (|f'| ≤ 1e-12 f) counts as flat: the bracket stops
    # shrinking there, so equal inputs (f constant) give the symmetric ω* = ½.
    lo = np.zeros(lead)
    hi = np.ones(lead)
    for _ in range(iters):
        w = 0.5 * (lo + hi)
        den = w[..., None] + (1.0 - w[..., None]) * g
        f = np.sum(c * g / den, axis=-1)
        df = -np.sum(c * g * (1.0 - g) / den**2, axis=-1)
        flat = np.abs(df) <= 1e-12 * f
        hi = np.where((df > 0.0) & ~flat, w, hi)
        lo = np.where((df < 0.0) & ~flat, w, lo)
    omega = 0.5 * (lo + hi)

    den = omega[..., None] + (1.0 - omega[..., None]) * g  # (..., D)
    # P_CI = W diag(g / den) Wᵀ
    P = _sym((W * (g / den)[..., None, :]) @ np.swapaxes(W, -1, -2))
    P = np.broadcast_to(P, lead + (D, D)).copy()
    # x_CI = x_b + ω P_CI P_a⁻¹ (x_a − x_b) = x_b + ω W diag(1/den) Uᵀ L⁻¹ (x_a − x_b)
    v = np.swapaxes(U, -1, -2) @ (L_inv @ (x_a - x_b)[..., None])
    x = x_b + omega[..., None] * (W @ (v / den[..., None]))[..., 0]
    return x, P, omega


def independent_fuse(
    x_a: npt.ArrayLike, P_a: npt.ArrayLike, x_b: npt.ArrayLike, P_b: npt.ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Optimal fusion of two estimates with independent errors (the information sum).

    P = (P_a⁻¹ + P_b⁻¹)⁻¹, x = P (P_a⁻¹ x_a + P_b⁻¹ x_b), computed in the equivalent gain
    form K = P_a (P_a + P_b)⁻¹, x = x_a + K (x_b − x_a), P = P_a − K P_a, which needs one
    solve and no inverse of a possibly ill-conditioned covariance. Over-confident when the
    errors are in fact correlated; ``ci_fuse`` is the consistent alternative.

    Args:
        x_a: (..., D) first estimate.
        P_a: (..., D, D) its covariance, symmetric positive definite.
        x_b: (..., D) second estimate.
        P_b: (..., D, D) its covariance, symmetric positive definite.

    Returns:
        x: (..., D) fused estimate; P: (..., D, D) fused covariance.
    """
    x_a, P_a = _gaussian("x_a", x_a, "P_a", P_a)
    x_b, P_b = _gaussian("x_b", x_b, "P_b", P_b)
    if x_a.shape[-1] != x_b.shape[-1]:
        raise ValueError(f"x_a and x_b must have the same D; got {x_a.shape} and {x_b.shape}")
    _cholesky("P_a", P_a)
    _cholesky("P_b", P_b)
    # K = P_a (P_a + P_b)⁻¹ = ((P_a + P_b)⁻¹ P_a)ᵀ since both are symmetric
    S = P_a + P_b
    K = np.swapaxes(np.linalg.solve(S, np.broadcast_to(P_a, np.broadcast_shapes(S.shape, P_a.shape))), -1, -2)
    x = x_a + (K @ (x_b - x_a)[..., None])[..., 0]
    # P = P_a − K P_a (symmetrized)
    P = _sym(P_a - K @ P_a)
    return x, P


# --------------------------------------------------------------------------- χ² tests


def chi2_threshold(p_false_alarm: float, dof: int) -> float:
    """χ² gate T_D with P(λ > T_D) = p_false_alarm for a fault-free residual.

    The federated paper's T_D = 11.34 is ``chi2_threshold(0.01, 3)``; dtvirm's 12.59 is
    ``chi2_threshold(0.05, 6)``.

    Args:
        p_false_alarm: false-alarm probability P_f, in (0, 1).
        dof: degrees of freedom (the residual dimension m), ≥ 1.

    Returns:
        T_D.
    """
    if not 0.0 < p_false_alarm < 1.0:
        raise ValueError(f"p_false_alarm must be in (0, 1); got {p_false_alarm}")
    if int(dof) != dof or dof < 1:
        raise ValueError(f"dof must be an integer >= 1; got {dof}")
    return float(chi2.isf(p_false_alarm, int(dof)))


def normalized_innovation_squared(r: npt.ArrayLike, S: npt.ArrayLike) -> FloatArray:
    """Normalized innovation squared λ = rᵀ S⁻¹ r (dtvirm λ_k, federated eq. 15).

    Args:
        r: (..., m) residual r = z − H x̂⁻.
        S: (..., m, m) its covariance S = H P⁻ Hᵀ + R (federated A), positive definite.

    Returns:
        (...) λ, χ²(m)-distributed when the filter is consistent and fault-free.
    """
    r, S = _gaussian("r", r, "S", S)
    L = _cholesky("S", S)
    # λ = ‖L⁻¹ r‖² with S = L Lᵀ
    y = np.linalg.solve(L, np.broadcast_to(r[..., None], np.broadcast_shapes(L.shape[:-1], r.shape) + (1,)))
    return np.sum(y[..., 0] ** 2, axis=-1)


def chi2_fault_test(
    r: npt.ArrayLike, S: npt.ArrayLike, p_false_alarm: float = 0.01
) -> tuple[FloatArray, BoolArray]:
    """Residual χ² fault detection (federated eq. 13–16).

    Args:
        r: (..., m) sub-filter residual r = z − H x̂⁻ (eq. 13).
        S: (..., m, m) its covariance A = H P⁻ Hᵀ + R (eq. 14).
        p_false_alarm: P_f setting the threshold T_D, in (0, 1).

    Returns:
        lam: (...) fault detection function λ (eq. 15); fault: (...) λ > T_D (eq. 16).
    """
    lam = normalized_innovation_squared(r, S)
    T_D = chi2_threshold(p_false_alarm, np.shape(r)[-1])
    return lam, lam > T_D


def chi2_soft_weight(
    nis: npt.ArrayLike, dof: int = 1, confidence: float = 0.95, sigma: float = 1.0
) -> FloatArray:
    """dtvirm §3.7 UWB adaptive adjustment weight from the χ² statistic.

    w = 1 when λ < χ²_thresh, else w = exp(−(λ − χ²_thresh) / (2σ²)): slightly
    inconsistent ranges still count, strongly inconsistent ones fade out instead of being
    cut at the gate. χ²_thresh is the ``confidence`` quantile of χ²(dof) (3.84 for dof=1
    at 95 %; dtvirm's 6-dof gate is 12.59). The paper calls σ the UWB noise parameter; as
    λ is dimensionless it acts as a dimensionless softness (σ=1: w halves 1.39 NIS units
    past the gate). Apply it as a trust: R ← R / w.

    Args:
        nis: (...) normalized innovation squared λ ≥ 0.
        dof: degrees of freedom of λ, ≥ 1.
        confidence: gate quantile, in (0, 1).
        sigma: softness σ > 0.

    Returns:
        (...) weights in (0, 1].
    """
    nis = np.asarray(nis, dtype=np.float64)
    if np.isnan(nis).any() or (nis < 0).any():
        bad = nis[np.isnan(nis) | (nis < 0)].ravel()[0]
        raise ValueError(f"nis must be >= 0 and not NaN; got {float(bad)}")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1); got {confidence}")
    if not sigma > 0.0:
        raise ValueError(f"sigma must be > 0; got {sigma}")
    thresh = chi2_threshold(1.0 - confidence, dof)
    # w = exp(−(λ − χ²_thresh) / (2σ²)) beyond the gate
    return np.where(nis < thresh, 1.0, np.exp(-(nis - thresh) / (2.0 * sigma**2)))


# --------------------------------------------------------------------------- federated filter


def residual_ratio(r: npt.ArrayLike, S: npt.ArrayLike) -> FloatArray:
    """Observation forecast residual statistic ΔV = rᵀ r / tr(H P⁻ Hᵀ + R) (federated eq. 19).

    Args:
        r: (..., m) residual (eq. 18).
        S: (..., m, m) its predicted covariance H P⁻ Hᵀ + R.

    Returns:
        (...) ΔV ≥ 0, about 1 for a consistent fault-free sub-filter.
    """
    r, S = _gaussian("r", r, "S", S)
    tr = np.trace(S, axis1=-2, axis2=-1)
    if (tr <= 0).any():
        raise ValueError(f"S must have a positive trace; got {float(tr.min())}")
    return np.sum(r * r, axis=-1) / tr


def allocation_coefficients(delta_v: npt.ArrayLike, d: float = 0.85) -> FloatArray:
    """Adaptive information-allocation coefficients β_t over sub-filters (federated eq. 17, 20).

    β_i = 1 when |ΔV_i| ≤ d, else d / |ΔV_i| (eq. 17); normalized so Σ_i β_t,i = 1
    (information conservation, eq. 20). A sub-filter whose residual grows gets a smaller
    share. The paper takes d = 0.85.

    Args:
        delta_v: (..., S) ΔV per sub-filter (eq. 19), S ≥ 1, finite.
        d: gate d > 0.

    Returns:
        (..., S) β_t, each in (0, 1], summing to 1 over the last axis.
    """
    delta_v = np.asarray(delta_v, dtype=np.float64)
    if delta_v.ndim < 1 or delta_v.shape[-1] < 1:
        raise ValueError(f"delta_v must have shape (..., S) with S >= 1; got {delta_v.shape}")
    _finite("delta_v", delta_v)
    if not d > 0.0:
        raise ValueError(f"d must be > 0; got {d}")
    a = np.abs(delta_v)
    beta = np.where(a <= d, 1.0, d / np.maximum(a, d))
    # β_t,i = β_i / Σ_j β_j
    return beta / np.sum(beta, axis=-1, keepdims=True)


def adapted_noise(R: npt.ArrayLike, beta_t: npt.ArrayLike, n_sub: int = 2) -> FloatArray:
    """Measurement noise adapted by the allocation coefficient (federated eq. 21).

    R_k = R + n (1/n − β_t) R = (2 − n β_t) R: unchanged at the equal share β_t = 1/n,
    inflated for a sub-filter whose share dropped, shrunk for the others. The paper has
    n = 2; for n > 2 the same rule is applied, and it stays positive only for β_t < 2/n.

    Args:
        R: (..., m, m) initial measurement noise of the sub-filter.
        beta_t: (...) its normalized allocation coefficient (eq. 20), in [0, 1].
        n_sub: number of sub-filters n ≥ 1.

    Returns:
        (..., m, m) adapted R_k.
    """
    R = np.asarray(R, dtype=np.float64)
    beta_t = np.asarray(beta_t, dtype=np.float64)
    if R.ndim < 2 or R.shape[-1] != R.shape[-2]:
        raise ValueError(f"R must have shape (..., m, m); got {R.shape}")
    _finite("R", R)
    _finite("beta_t", beta_t)
    if n_sub < 1:
        raise ValueError(f"n_sub must be >= 1; got {n_sub}")
    scale = 2.0 - n_sub * beta_t
    if (beta_t < 0).any() or (scale <= 0).any():
        raise ValueError(
            f"beta_t must be in [0, 2/n_sub) = [0, {2.0 / n_sub:.3g}) so that R stays positive; "
            f"got {float(beta_t.min())}..{float(beta_t.max())} with n_sub = {n_sub}"
        )
    # R_k = R + n (1/n − β_t) R
    return scale[..., None, None] * R


def share_information(
    x_g: npt.ArrayLike, P_g: npt.ArrayLike, Q: npt.ArrayLike, beta_t: npt.ArrayLike
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Reset the sub-filters from the global estimate (federated eq. 23).

    x_i = x_g, P_i = P_g / β_t,i, Q_i = Q / β_t,i: each sub-filter receives the share β_t,i
    of the global information (the variance upper-bound technique that keeps the
    sub-filters' errors formally uncorrelated).

    Args:
        x_g: (..., D) global estimate.
        P_g: (..., D, D) global covariance.
        Q: (..., D, D) process noise of the common system.
        beta_t: (..., S) allocation coefficients, each in (0, 1].

    Returns:
        x: (..., S, D), P: (..., S, D, D), Q: (..., S, D, D) per sub-filter.
    """
    x_g, P_g = _gaussian("x_g", x_g, "P_g", P_g)
    Q = np.asarray(Q, dtype=np.float64)
    if Q.shape[-2:] != P_g.shape[-2:]:
        raise ValueError(f"Q must have shape (..., D, D) = {P_g.shape[-2:]}; got {Q.shape}")
    _finite("Q", Q)
    beta_t = np.asarray(beta_t, dtype=np.float64)
    if beta_t.ndim < 1 or not ((beta_t > 0) & (beta_t <= 1)).all():
        raise ValueError(
            f"beta_t must have shape (..., S) with values in (0, 1]; got shape {beta_t.shape}, "
            f"values {float(beta_t.min(initial=np.inf))}..{float(beta_t.max(initial=-np.inf))}"
        )
    inv_b = (1.0 / beta_t)[..., None, None]
    S = beta_t.shape[-1]
    x = np.broadcast_to(x_g[..., None, :], np.broadcast_shapes(x_g.shape[:-1], beta_t.shape[:-1]) + (S, x_g.shape[-1]))
    return x.copy(), inv_b * P_g[..., None, :, :], inv_b * Q[..., None, :, :]


def federated_fuse(
    x: npt.ArrayLike, P: npt.ArrayLike, valid: npt.ArrayLike | None = None
) -> tuple[FloatArray, FloatArray]:
    """Master-filter global fusion of S sub-filters (federated eq. 31).

    P_g = (Σ_i P_i⁻¹)⁻¹, x_g = P_g Σ_i P_i⁻¹ x_i over the sub-filters that passed fault
    detection (``valid``); isolated ones do not take part (federated §4.1). Information
    form through Cholesky factors of each P_i.

    Args:
        x: (..., S, D) sub-filter estimates.
        P: (..., S, D, D) their covariances, symmetric positive definite.
        valid: (..., S) bool, False for isolated sub-filters; None = all valid.

    Returns:
        x_g: (..., D) global estimate; P_g: (..., D, D) global covariance.

    Raises:
        ValueError: bad shapes, NaN/inf, non-PD covariance, or an element with no valid
            sub-filter.
    """
    x, P = _gaussian("x", x, "P", P)
    if x.ndim < 2:
        raise ValueError(f"x must have shape (..., S, D); got {x.shape}")
    S = x.shape[-2]
    if P.ndim < 3 or P.shape[-3] != S:
        raise ValueError(f"P must have shape (..., S, D, D) with S = {S}; got {P.shape}")
    lead = np.broadcast_shapes(x.shape[:-2], P.shape[:-3])
    if valid is None:
        v = np.ones(lead + (S,), dtype=bool)
    else:
        v = np.asarray(valid, dtype=bool)
        try:
            v = np.broadcast_to(v, lead + (S,))
        except ValueError:
            raise ValueError(f"valid must broadcast to (..., S) = {lead + (S,)}; got {v.shape}") from None
    none = ~v.any(axis=-1)
    if none.any():
        raise ValueError(
            f"every sub-filter is isolated (valid all False) at batch index "
            f"{tuple(int(i) for i in np.argwhere(none)[0])}; the global estimate is undefined"
        )
    L = _cholesky("P", P)
    L_inv = np.linalg.inv(L)
    # P_i⁻¹ = L⁻ᵀ L⁻¹
    Y = np.swapaxes(L_inv, -1, -2) @ L_inv
    m = v[..., None, None].astype(np.float64)
    # Y_g = Σ_i P_i⁻¹,  y_g = Σ_i P_i⁻¹ x_i
    Y_g = np.sum(m * Y, axis=-3)
    y_g = np.sum(m[..., 0] * (Y @ x[..., None])[..., 0], axis=-2)
    L_g = np.linalg.cholesky(_sym(Y_g))
    L_g_inv = np.linalg.inv(L_g)
    # P_g = Y_g⁻¹ = L_g⁻ᵀ L_g⁻¹,  x_g = P_g y_g
    P_g = _sym(np.swapaxes(L_g_inv, -1, -2) @ L_g_inv)
    x_g = (P_g @ y_g[..., None])[..., 0]
    return x_g, P_g
