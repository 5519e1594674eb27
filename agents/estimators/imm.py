"""IMM family: IMM-KF, IMM-EKF and IMM-ARKF on GPS fixes (imm-arkf §2.2–2.3).

Each UAV runs one interacting-multiple-model filter on its own GPS fix. Three motion
models, batched as an extra axis M (shapes ``(B, N, M, D)``): constant velocity (CV,
eq. 2) and constant turn left / right (CT±, eq. 3). Per step: mixing (eq. 4, 7–9),
mode-matched prediction and update, mode probabilities from Gaussian likelihoods
(eq. 10–11), combination (eq. 12–13). The three members differ only in the update:

- ``imm-kf``: linear Kalman update on the fix.
- ``imm-ekf``: extended Kalman update on the fix converted to range/bearing about a
  ground station (imm-arkf Table 1: ``z = [√(x²+y²), atan(y/x)]``, Jacobian at the prior).
- ``imm-arkf``: the adaptive robust update (eq. 14–32): correntropy robust weights on the
  whitened residual inflate R (robust to outliers) and a fading factor λ ≥ 1 found by a
  χ² test inflates the propagated covariance (adaptive to manoeuvres).

Our choices where the paper is 2-D or silent (every one is a ``ImmConfig`` field):

- **State and z.** The paper's state is (x, vₓ, y, v_y). Ours is D = 6,
  x = [x, y, z, vₓ, v_y, v_z] (the world's [p, v] order): the CT models turn in the
  horizontal plane and z is a constant-velocity axis in every model, so the fix is used
  in 3-D (m = 3) and the χ² gate of the fading factor is χ²₀.₉₅(3) = 7.81 (the paper's
  5.99 is m = 2).
- **Units of ω.** Eq. 3 multiplies ω by Δt, so ω is a rate: ω = ±2π/180 rad/s (2°/s).
  Reading it as "per step" would make the turn rate depend on the sampling (0.35 rad/s at
  our Δt = 0.1 s, 1.1 rad/s at the paper's 0.032 s); ``turn_rate`` takes any value.
- **Q, P₀, x₀.** Q = 0.01·I per step (Table 1). The initial state is the task's public
  prior (the paper starts from the first fix); P₀ = diag(σ_p², σ_v²) of that prior
  unless ``p0`` (the paper's 0.1) is given.
- **R.** The task's nominal GPS variance σ² per UAV unless ``r`` is given (Table 2
  sweeps R = 0.5, 1.5, 8).
- **ARKF weights (eq. 24).** The kernel is printed exp(+(eᵢ−eⱼ)²/2σ₂²); we use the
  decaying exp(−·). Eq. 27's Γ tends to (h/σ₁²)I + (2(1−h)/σ₂²)(mI − 11ᵀ) ≠ I for a
  zero residual, which with h = 0.15, σ₁ = 2, σ₂ = 8 inflates R 11–27× even for clean
  data (in the CEE filter the same scale multiplies the prior block and cancels; here only
  R is weighted). With ``normalize_gamma`` (default) we use Γ̃ = Γ₀^{-½} Γ Γ₀^{-½}, Γ₀ its
  zero-residual value: Γ̃ = I at e = 0 and for wide kernels, Γ̃ ⪯ I always, so the
  weights only ever inflate R. ``normalize_gamma=False`` is the printed eq. 27.
- **Fading factor (eq. 32).** Printed with a minus sign, which with its positive
  denominator would push λ below 1. We take the Newton step on d²(λ) = χ²:
  λ ← λ + (d² − χ²) / (gᵀ H F P Fᵀ Hᵀ g), g = S_r⁻¹ r; d²(λ) is convex and decreasing, so
  the iterates rise monotonically to the root (``fading_iters`` steps at most).
- **EKF noise.** The paper gives R = r·I₂ also for (range, bearing), i.e. a bearing σ of
  0.7–2.8 rad that discards the bearing. By default (``bearing_noise="converted"``) we use
  the first-order image of the isotropic fix noise, diag(r, r/ρ̂²); ``"paper"`` is r·I.
  The ground station sits at ``ekf_station`` (off the figure-eight, whose crossing point
  is the world origin, where the bearing is singular).

The IMU is not used (the paper's filters are kinematic). Position output is the
combined estimate (eq. 12), with its covariance (eq. 13); ``weights`` reports the GPS
channel's applied trust m / tr(R̄ R⁻¹) mixed over modes (1 for KF/EKF).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from swarmloc.envs.tasks.channels import GPS

from swarmloc.agents.estimators.fusion import chi2_threshold
from swarmloc.agents.protocols import EstimatorOutput, Measurements, TaskFacts

Variant = Literal["kf", "ekf", "arkf"]
D = 6  # state [p, v]
M_DIM = 3  # measurement rows (fix x, y, z)
_LOG_2PI = math.log(2.0 * math.pi)
_KERNEL_FLOOR = 1e-12  # keeps Γ invertible when every component is a gross outlier


@dataclass(frozen=True)
class ImmConfig:
    """Settings of the IMM family (defaults: imm-arkf §2.4 and Table 1)."""

    turn_rate: float = 2.0 * math.pi / 180.0
    """ω of the CT± models [rad/s] (eq. 3: ω = ±2π/180)."""
    transition: tuple[tuple[float, ...], ...] = ((0.4, 0.3, 0.3), (0.3, 0.4, 0.3), (0.3, 0.3, 0.4))
    """Markov mode transition matrix Π (eq. 33), Π[j, i] = P(mode i at k | mode j at k−1)."""
    mu0: tuple[float, ...] = (0.4, 0.3, 0.3)
    """Initial mode probabilities [CV, CT+, CT−] (eq. 6, Table 1)."""
    q: float = 0.01
    """Process noise Q = q·I per step (Table 1)."""
    r: float | None = None
    """GPS noise variance R = r·I [m²]; None: the task's nominal σ² of each UAV's fix."""
    p0: float | None = None
    """Initial covariance P₀ = p0·I; None: the task prior's diag(σ_p², σ_v²)."""
    h: float = 0.15
    """ARKF mixing of the individual and cross-component kernels (eq. 27)."""
    sigma1: float = 2.0
    """ARKF bandwidth of the individual kernel (eq. 22)."""
    sigma2: float = 8.0
    """ARKF bandwidth of the cross-component kernel (eq. 24)."""
    normalize_gamma: bool = True
    """ARKF: Γ̃ = Γ₀^{-½} Γ Γ₀^{-½} (True) or the printed eq. 27 (False); see the module doc."""
    fading: bool = True
    """ARKF: adaptive fading factor λ ≥ 1 from the χ² test (eq. 29–32); False keeps λ = 1."""
    fading_confidence: float = 0.95
    """ARKF: confidence of the χ² gate of the fading factor (eq. 31)."""
    fading_iters: int = 10
    """ARKF: at most this many Newton steps on λ (eq. 32)."""
    bearing_noise: Literal["converted", "paper"] = "converted"
    """EKF: (range, bearing) noise diag(r, r/ρ̂²) (converted) or r·I (the paper's Table 1)."""
    ekf_station: tuple[float, float] = (0.0, -40.0)
    """EKF: horizontal position of the range/bearing reference [m]."""

    def __post_init__(self) -> None:
        Pi = np.asarray(self.transition, dtype=float)
        mu0 = np.asarray(self.mu0, dtype=float)
        if Pi.shape != (3, 3) or (Pi < 0).any() or not np.allclose(Pi.sum(axis=1), 1.0):
            raise ValueError(f"transition must be a 3×3 row-stochastic matrix, got {self.transition}")
        if mu0.shape != (3,) or (mu0 < 0).any() or not math.isclose(mu0.sum(), 1.0):
            raise ValueError(f"mu0 must be 3 probabilities summing to 1, got {self.mu0}")
        for name in ("q", "sigma1", "sigma2"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        for name in ("r", "p0"):
            v = getattr(self, name)
            if v is not None and not v > 0:
                raise ValueError(f"{name} must be > 0 or None, got {v}")
        if not 0.0 < self.h <= 1.0:
            raise ValueError(f"h must be in (0, 1], got {self.h}")
        if not 0.0 < self.fading_confidence < 1.0:
            raise ValueError(f"fading_confidence must be in (0, 1), got {self.fading_confidence}")
        if self.fading_iters < 0:
            raise ValueError(f"fading_iters must be >= 0, got {self.fading_iters}")


# --------------------------------------------------------------------------- models


def transition_matrices(turn_rate: float, dt: float) -> np.ndarray:
    """F of the CV, CT+ and CT− models on x = [x, y, z, vₓ, v_y, v_z] (eq. 2–3).

    Args:
        turn_rate: ω > 0 [rad/s]; CT+ turns left (counter-clockwise) at +ω, CT− at −ω.
        dt: step [s].

    Returns:
        (3, 6, 6) transition matrices [CV, CT+, CT−].
    """
    F = np.zeros((3, D, D))
    for m, w in enumerate((0.0, turn_rate, -turn_rate)):
        F[m] = np.eye(D)
        F[m, 2, 5] = dt  # z: constant velocity in every model
        if w == 0.0:
            F[m, 0, 3] = F[m, 1, 4] = dt  # eq. 2
            continue
        s, c = math.sin(w * dt), math.cos(w * dt)
        # eq. 3 in our order: p' = p + [[s/ω, −(1−c)/ω], [(1−c)/ω, s/ω]] v,  v' = [[c, −s], [s, c]] v
        F[m, 0, 3], F[m, 0, 4] = s / w, -(1.0 - c) / w
        F[m, 1, 3], F[m, 1, 4] = (1.0 - c) / w, s / w
        F[m, 3, 3], F[m, 3, 4] = c, -s
        F[m, 4, 3], F[m, 4, 4] = s, c
    return F


def _sym(P: np.ndarray) -> np.ndarray:
    return 0.5 * (P + np.swapaxes(P, -1, -2))


def imm_mix(x: np.ndarray, P: np.ndarray, mu: np.ndarray, Pi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """IMM interaction step (eq. 4, 7–9).

    Args:
        x: (B, N, M, D) mode-conditioned posteriors at k−1.
        P: (B, N, M, D, D) their covariances.
        mu: (B, N, M) mode probabilities at k−1.
        Pi: (M, M) transition matrix, Pi[j, i] = P(i | j).

    Returns:
        x̄: (B, N, M, D) mixed initial states; P̄: (B, N, M, D, D); c: (B, N, M) predicted
        mode probabilities μ̂_{k|k−1}.
    """
    # μ̂⁽ⁱ⁾_{k|k−1} = Σ_j π_ji μ⁽ʲ⁾_{k−1}                                  (eq. 4)
    c = np.einsum("ji,bnj->bni", Pi, mu)
    # μ^{j|i} = π_ji μ⁽ʲ⁾ / μ̂⁽ⁱ⁾                                           (eq. 7)
    w = Pi[None, None] * mu[..., :, None] / np.maximum(c[..., None, :], 1e-300)  # (B, N, j, i)
    # x̄⁽ⁱ⁾ = Σ_j μ^{j|i} x⁽ʲ⁾                                               (eq. 8)
    x_bar = np.einsum("bnji,bnjd->bnid", w, x)
    # P̄⁽ⁱ⁾ = Σ_j μ^{j|i} [P⁽ʲ⁾ + (x̄⁽ⁱ⁾ − x⁽ʲ⁾)(x̄⁽ⁱ⁾ − x⁽ʲ⁾)ᵀ]                  (eq. 9)
    dx = x_bar[:, :, :, None, :] - x[:, :, None, :, :]  # (B, N, i, j, D)
    P_bar = np.einsum("bnji,bnjde->bnide", w, P) + np.einsum("bnji,bnijd,bnije->bnide", w, dx, dx)
    return x_bar, _sym(P_bar), c


def imm_combine(x: np.ndarray, P: np.ndarray, mu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """IMM combination (eq. 12–13): (B, N, M, D), (B, N, M, D, D), (B, N, M) → (B, N, D), (B, N, D, D)."""
    # x̂ = Σ_i μ⁽ⁱ⁾ x̂⁽ⁱ⁾                                                   (eq. 12)
    xc = np.einsum("bnm,bnmd->bnd", mu, x)
    # P = Σ_i μ⁽ⁱ⁾ [P⁽ⁱ⁾ + (x̂ − x̂⁽ⁱ⁾)(x̂ − x̂⁽ⁱ⁾)ᵀ]                             (eq. 13)
    dx = xc[:, :, None, :] - x
    Pc = np.einsum("bnm,bnmde->bnde", mu, P) + np.einsum("bnm,bnmd,bnme->bnde", mu, dx, dx)
    return xc, _sym(Pc)


def mode_probabilities(c: np.ndarray, log_lik: np.ndarray) -> np.ndarray:
    """μ⁽ⁱ⁾ = μ̂⁽ⁱ⁾ Λ⁽ⁱ⁾ / Σ_j μ̂⁽ʲ⁾ Λ⁽ʲ⁾ (eq. 11), in the log domain for stability.

    Args:
        c: (..., M) predicted mode probabilities.
        log_lik: (..., M) log Λ.

    Returns:
        (..., M) updated probabilities, summing to 1.
    """
    a = np.log(np.maximum(c, 1e-300)) + log_lik
    a = a - a.max(axis=-1, keepdims=True)
    e = np.exp(a)
    return e / e.sum(axis=-1, keepdims=True)


def gaussian_log_likelihood(r: np.ndarray, S: np.ndarray) -> np.ndarray:
    """log Λ = −½ rᵀS⁻¹r − ½ log|2πS| (eq. 10), through a Cholesky factor of S."""
    L = np.linalg.cholesky(S)
    y = np.linalg.solve(L, r[..., None])[..., 0]
    log_det = 2.0 * np.sum(np.log(np.diagonal(L, axis1=-2, axis2=-1)), axis=-1)
    return -0.5 * np.sum(y * y, axis=-1) - 0.5 * (r.shape[-1] * _LOG_2PI + log_det)


def joseph_update(x: np.ndarray, P: np.ndarray, r: np.ndarray, H: np.ndarray, R: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Kalman update in Joseph form; returns x, P and S = H P Hᵀ + R.

    Args:
        x: (..., D) prior; P: (..., D, D); r: (..., m) innovation z − h(x⁻);
        H: (..., m, D) Jacobian at the prior; R: (..., m, m) noise.
    """
    Ht = np.swapaxes(H, -1, -2)
    PHt = P @ Ht
    # S = H P⁻ Hᵀ + R
    S = _sym(H @ PHt + R)
    # K = P⁻ Hᵀ S⁻¹ (= (S⁻¹ H P⁻)ᵀ, S and P symmetric)
    K = np.swapaxes(np.linalg.solve(S, np.swapaxes(PHt, -1, -2)), -1, -2)
    x_new = x + (K @ r[..., None])[..., 0]
    # P = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ: symmetric and PSD by construction (Joseph form)
    A = np.eye(P.shape[-1]) - K @ H
    P_new = _sym(A @ P @ np.swapaxes(A, -1, -2) + K @ R @ np.swapaxes(K, -1, -2))
    return x_new, P_new, S


# --------------------------------------------------------------------------- ARKF pieces


def correntropy_gain(e: np.ndarray, h: float, sigma1: float, sigma2: float, normalize: bool = True) -> np.ndarray:
    """The ARKF robust weight matrix Γ of a whitened residual (eq. 22–27).

    Args:
        e: (..., m) whitened residual e = R^{-½}(z − H x⁻) (eq. 21).
        h: mixing parameter in (0, 1].
        sigma1, sigma2: kernel bandwidths of eq. 22 and eq. 24.
        normalize: return Γ̃ = Γ₀^{-½} Γ Γ₀^{-½} (Γ̃ = I at e = 0), else the printed Γ.

    Returns:
        (..., m, m) symmetric positive definite Γ.
    """
    m = e.shape[-1]
    eye = np.eye(m)
    a = h / sigma1**2
    b = 2.0 * (1.0 - h) / sigma2**2
    # M = diag{exp(−eᵢ²/(2σ₁²))}                                          (eq. 22–23)
    G1 = np.maximum(np.exp(-(e**2) / (2.0 * sigma1**2)), _KERNEL_FLOOR)
    # θᵢⱼ = exp(−(eᵢ − eⱼ)²/(2σ₂²))                                       (eq. 24)
    diff = e[..., :, None] - e[..., None, :]
    theta = np.exp(-(diff**2) / (2.0 * sigma2**2))
    # N = E − θ, E = diag{Σⱼ θᵢⱼ}                                          (eq. 25–26)
    Nk = eye * theta.sum(axis=-1)[..., None] - theta
    # Γ = h/σ₁² M + 2(1−h)/σ₂² N                                          (eq. 27)
    Gamma = a * (eye * G1[..., None]) + b * Nk
    if not normalize:
        return Gamma
    # Γ₀ = a I + b (m I − 11ᵀ): eigenvalue a along 1, a + b m on its complement
    J = np.full((m, m), 1.0 / m)
    G0_isqrt = J / math.sqrt(a) + (eye - J) / math.sqrt(a + b * m)
    return _sym(G0_isqrt @ Gamma @ G0_isqrt)


def _sqrt_and_isqrt(R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """R^{½} and R^{-½} = V D^{-½} Vᵀ (eq. 18) of SPD matrices (..., m, m)."""
    lam, V = np.linalg.eigh(R)
    Vt = np.swapaxes(V, -1, -2)
    return (V * np.sqrt(lam)[..., None, :]) @ Vt, (V / np.sqrt(lam)[..., None, :]) @ Vt


def robust_noise(r: np.ndarray, R: np.ndarray, cfg: ImmConfig) -> tuple[np.ndarray, np.ndarray]:
    """R̄ from R̄⁻¹ = (R^{-½})ᵀ Γ R^{-½} (eq. 18–28) and the applied trust m / tr(R̄ R⁻¹).

    Args:
        r: (..., m) innovation z − H x⁻ (whitening it equals d − W x⁻ of eq. 19–21).
        R: (..., m, m) nominal noise.
        cfg: the ARKF settings.

    Returns:
        R̄: (..., m, m); trust: (...) in (0, 1] when Γ is normalized.
    """
    R_half, R_ihalf = _sqrt_and_isqrt(R)
    # e = R^{-½}(z − H x⁻)                                                  (eq. 21)
    e = (R_ihalf @ r[..., None])[..., 0]
    Gamma = correntropy_gain(e, cfg.h, cfg.sigma1, cfg.sigma2, cfg.normalize_gamma)
    # R̄ = R^{½} Γ⁻¹ R^{½}  ⇔  R̄⁻¹ = R^{-½} Γ R^{-½}                          (eq. 28)
    R_bar = _sym(R_half @ np.linalg.solve(Gamma, R_half))
    trust = r.shape[-1] / np.trace(np.linalg.solve(Gamma, np.broadcast_to(np.eye(r.shape[-1]), Gamma.shape)),
                                   axis1=-2, axis2=-1)
    return R_bar, trust


def fading_factor(r: np.ndarray, H: np.ndarray, P_f: np.ndarray, Q: np.ndarray, R_bar: np.ndarray,
                  chi2_gate: float, iters: int) -> np.ndarray:
    """Adaptive fading factor λ ≥ 1 (eq. 29–32) so that rᵀ S_r(λ)⁻¹ r ≤ χ²_α,m.

    S_r(λ) = H (λ F P Fᵀ + Q) Hᵀ + R̄. Where the test (eq. 31) fails, Newton steps on
    d²(λ) = χ² raise λ; d² is convex and decreasing in λ, so the steps never overshoot.

    Args:
        r: (..., m) innovation; H: (m, D) or (..., m, D); P_f: (..., D, D) the propagated
        part F P Fᵀ; Q: (D, D); R_bar: (..., m, m); chi2_gate: χ²_α,m; iters: ≥ 0 steps.

    Returns:
        (...) λ ≥ 1.
    """
    Ht = np.swapaxes(H, -1, -2)
    HPH = H @ P_f @ Ht
    base = H @ Q @ Ht + R_bar
    lam = np.ones(r.shape[:-1])
    for _ in range(iters):
        # S_r = λ H F P Fᵀ Hᵀ + H Q Hᵀ + R̄                                   (eq. 29–30)
        S = lam[..., None, None] * HPH + base
        g = np.linalg.solve(S, r[..., None])[..., 0]
        d2 = np.sum(r * g, axis=-1)  # (eq. 31)
        exceed = d2 > chi2_gate
        if not exceed.any():
            break
        # λ ← λ + (d² − χ²) / (gᵀ H F P Fᵀ Hᵀ g)                            (eq. 32, Newton)
        slope = np.einsum("...i,...ij,...j->...", g, HPH, g)
        lam = np.where(exceed, lam + (d2 - chi2_gate) / np.maximum(slope, 1e-300), lam)
    return lam


# --------------------------------------------------------------------------- EKF pieces


def polar_measurement(p: np.ndarray, station: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """h(x) = [ρ, θ, z] about a ground station and its Jacobian on x = [p, v].

    Args:
        p: (..., 3) positions; station: (2,) horizontal reference point.

    Returns:
        h: (..., 3) [range ρ, bearing θ, altitude]; H: (..., 3, 6).
    """
    dx = p[..., 0] - station[0]
    dy = p[..., 1] - station[1]
    rho2 = np.maximum(dx * dx + dy * dy, 1e-12)
    rho = np.sqrt(rho2)
    h = np.stack([rho, np.arctan2(dy, dx), p[..., 2]], axis=-1)
    H = np.zeros(p.shape[:-1] + (3, D))
    # ∂ρ/∂(x, y) = (dx, dy)/ρ,  ∂θ/∂(x, y) = (−dy, dx)/ρ²,  ∂z/∂z = 1
    H[..., 0, 0], H[..., 0, 1] = dx / rho, dy / rho
    H[..., 1, 0], H[..., 1, 1] = -dy / rho2, dx / rho2
    H[..., 2, 2] = 1.0
    return h, H


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2.0 * np.pi) - np.pi


# --------------------------------------------------------------------------- one IMM step


@dataclass
class ImmState:
    """Mode-conditioned posteriors of B×N IMM filters.

    Attributes:
        x: (B, N, M, D) states; P: (B, N, M, D, D) covariances; mu: (B, N, M) probabilities.
    """

    x: np.ndarray
    P: np.ndarray
    mu: np.ndarray


@dataclass(frozen=True)
class ImmStepInfo:
    """Diagnostics of one step: per-mode log-likelihoods, fading factors and GPS trust (B, N, M)."""

    log_lik: np.ndarray
    fading: np.ndarray
    trust: np.ndarray


_H_FIX = np.hstack([np.eye(3), np.zeros((3, 3))])  # fix = H x


def imm_step(state: ImmState, z: np.ndarray, valid: np.ndarray, R: np.ndarray, variant: Variant,
             cfg: ImmConfig, F: np.ndarray, Q: np.ndarray) -> tuple[ImmState, ImmStepInfo]:
    """One IMM cycle for B×N filters: mix, predict, mode-matched update, mode probabilities.

    Args:
        state: posteriors at k−1.
        z: (B, N, 3) GPS fixes at k.
        valid: (B, N) fix present (no update and Λ = 1 otherwise).
        R: (B, N, 3, 3) nominal fix noise.
        variant: "kf", "ekf" or "arkf".
        cfg: settings.
        F: (M, D, D) model transition matrices (``transition_matrices``).
        Q: (D, D) process noise per step.

    Returns:
        The posteriors at k and the step's diagnostics.
    """
    Pi = np.asarray(cfg.transition)
    x_bar, P_bar, c = imm_mix(state.x, state.P, state.mu, Pi)
    # x⁻ = F x̄,  F P̄ Fᵀ (the propagated part; eq. 14–15 add Q)
    x_pred = np.einsum("mde,bnme->bnmd", F, x_bar)
    P_f = _sym(F[None, None] @ P_bar @ np.swapaxes(F, -1, -2)[None, None])
    M = F.shape[0]
    zM = np.broadcast_to(z[:, :, None, :], x_pred.shape[:3] + (M_DIM,))
    RM = np.broadcast_to(R[:, :, None], x_pred.shape[:3] + (M_DIM, M_DIM))
    fading = np.ones(x_pred.shape[:3])
    trust = np.ones(x_pred.shape[:3])
    if variant == "ekf":
        station = np.asarray(cfg.ekf_station, dtype=float)
        h, H = polar_measurement(x_pred[..., :3], station)
        zp, _ = polar_measurement(zM, station)
        # r = [ρ − ρ̂, wrap(θ − θ̂), z − ẑ]
        r = zp - h
        r[..., 1] = _wrap(r[..., 1])
        if cfg.bearing_noise == "converted":
            # isotropic fix noise r·I maps to diag(r, r/ρ̂², r) in (range, bearing, altitude)
            scale = np.ones(h.shape)
            scale[..., 1] = 1.0 / np.maximum(h[..., 0], 1e-6) ** 2
            R_used = RM * scale[..., :, None]  # R is diagonal r·I here
        else:
            R_used = np.array(RM)
        P_pred = P_f + Q
    else:
        H = np.broadcast_to(_H_FIX, x_pred.shape[:3] + (M_DIM, D))
        # r = z − H x⁻                                                       (eq. 16)
        r = zM - x_pred[..., :3]
        R_used = np.array(RM)
        if variant == "arkf":
            R_used, trust = robust_noise(r, RM, cfg)
            if cfg.fading:
                gate = chi2_threshold(1.0 - cfg.fading_confidence, M_DIM)
                fading = fading_factor(r, _H_FIX, P_f, Q, R_used, gate, cfg.fading_iters)
                # a lost fix is no evidence of a manoeuvre: its residual must not inflate P
                fading = np.where(valid[:, :, None], fading, 1.0)
        # P⁻ = λ F P Fᵀ + Q                                                   (eq. 15, 29)
        P_pred = fading[..., None, None] * P_f + Q
    x_new, P_new, S = joseph_update(x_pred, P_pred, r, H, R_used)
    log_lik = gaussian_log_likelihood(r, S)
    ok = valid[:, :, None]
    x_new = np.where(ok[..., None], x_new, x_pred)
    P_new = np.where(ok[..., None, None], P_new, P_pred)
    log_lik = np.where(ok, log_lik, 0.0)
    mu = mode_probabilities(c, log_lik)
    return ImmState(x_new, P_new, mu), ImmStepInfo(log_lik=log_lik, fading=fading, trust=np.where(ok, trust, 0.0))


def imm_flops(variant: Variant, n_models: int = 3, fading_iters: int = 0) -> float:
    """Analytic FLOPs of one IMM step of one UAV (dense matrices, 2 per multiply-add).

    Counts mixing (M² blends of D and D² entries), prediction (F P Fᵀ: 4D³), the update
    (S, K by an m×m solve, Joseph form: ≈ 6D³ + 4mD² + m³) and the likelihood; the ARKF adds
    whitening and Γ (≈ 10m³ + 6m²) and each fading iteration (≈ 2m²D + m³).
    """
    m, M = M_DIM, n_models
    mix = M * M * (2 * D + 4 * D * D)
    predict = M * (4 * D**3 + 2 * D)
    update = M * (6 * D**3 + 4 * m * D * D + 2 * m**3 + 4 * m * D + m**3 // 3 + 4 * m)
    combine = M * (2 * D + 4 * D * D)
    extra = 0
    if variant == "ekf":
        extra = M * 30
    elif variant == "arkf":
        extra = M * (10 * m**3 + 6 * m * m + fading_iters * (2 * m * m * D + 2 * m**3))
    return float(mix + predict + update + combine + extra)


# --------------------------------------------------------------------------- estimator


class ImmEstimator:
    """Track B estimator: one IMM filter per UAV on its GPS fix (``imm-kf/-ekf/-arkf``).

    Args:
        variant: "kf", "ekf" or "arkf".
        config: settings (defaults: the paper's).
    """

    privileged = False
    deterministic = True

    def __init__(self, variant: Variant = "arkf", config: ImmConfig | None = None) -> None:
        if variant not in ("kf", "ekf", "arkf"):
            raise ValueError(f"variant must be 'kf', 'ekf' or 'arkf', got {variant!r}")
        self.variant: Variant = variant
        self.config = config or ImmConfig()
        self.state: ImmState | None = None
        self.last_info: ImmStepInfo | None = None

    def __repr__(self) -> str:
        return f"ImmEstimator(variant={self.variant!r}, config={self.config!r})"

    def reset(self, facts: TaskFacts, x0: np.ndarray) -> None:
        """Start B episodes from the public prior ``x0`` (B, N, 6); every mode starts there.

        Raises:
            ValueError: the task gives some UAV no GPS channel, or ``x0`` has a bad shape.
        """
        cfg = self.config
        gps = np.asarray(facts.kind) == GPS
        missing = np.flatnonzero(~gps.any(axis=1))
        if missing.size:
            raise ValueError(f"IMM filters need a GPS channel on every UAV; task {facts.task_id} gives none to "
                             f"UAVs {missing.tolist()}")
        x0 = np.asarray(x0, dtype=np.float64)
        if x0.shape != (facts.batch_size, facts.n_uav, D):
            raise ValueError(f"x0 must have shape ({facts.batch_size}, {facts.n_uav}, {D}), got {x0.shape}")
        self._col = np.argmax(gps, axis=1)  # (N,) the GPS slot of each UAV
        n = facts.n_uav
        var = np.asarray(facts.sigma)[np.arange(n), self._col] ** 2 if cfg.r is None else np.full(n, cfg.r)
        self._R = np.broadcast_to(var[None, :, None, None] * np.eye(M_DIM), (facts.batch_size, n, M_DIM, M_DIM))
        self._F = transition_matrices(cfg.turn_rate, facts.dt)
        self._Q = cfg.q * np.eye(D)
        if cfg.p0 is None:
            diag = np.r_[np.full(3, facts.init_pos_sigma**2), np.full(3, facts.init_vel_sigma**2)]
        else:
            diag = np.full(D, cfg.p0)
        B, M = facts.batch_size, self._F.shape[0]
        self.state = ImmState(
            x=np.repeat(x0[:, :, None, :], M, axis=2),
            P=np.broadcast_to(np.diag(diag), (B, n, M, D, D)).copy(),
            mu=np.broadcast_to(np.asarray(cfg.mu0, dtype=float), (B, n, M)).copy(),
        )
        self._L = facts.n_channels
        iters = cfg.fading_iters if (self.variant == "arkf" and cfg.fading) else 0
        self._flops = imm_flops(self.variant, M, iters)

    def step(self, meas: Measurements) -> EstimatorOutput:
        """One IMM cycle on every UAV's GPS fix; returns combined positions and covariances."""
        if self.state is None:
            raise RuntimeError("call reset(facts, x0) before step()")
        n = self._col.shape[0]
        idx = np.arange(n)
        z = meas.z[:, idx, self._col]  # (B, N, 3)
        valid = meas.valid[:, idx, self._col]
        self.state, self.last_info = imm_step(self.state, z, valid, self._R, self.variant, self.config,
                                              self._F, self._Q)
        xc, Pc = imm_combine(self.state.x, self.state.P, self.state.mu)
        weights = np.zeros(meas.valid.shape)
        weights[:, idx, self._col] = np.einsum("bnm,bnm->bn", self.state.mu, self.last_info.trust)
        flops = np.full(valid.shape, self._flops)
        return EstimatorOutput(positions=xc[..., :3].copy(), cov=Pc[..., :3, :3].copy(), weights=weights,
                               flops=flops)

    @property
    def mode_probabilities(self) -> np.ndarray:
        """(B, N, M) current mode probabilities [CV, CT+, CT−]."""
        if self.state is None:
            raise RuntimeError("no episode running; call reset first")
        return self.state.mu


def make_imm(variant: Variant, **overrides) -> ImmEstimator:
    """An IMM estimator with ``ImmConfig`` field overrides (e.g. ``r=1.5``)."""
    return ImmEstimator(variant, replace(ImmConfig(), **overrides))


def imm_kf(**overrides) -> ImmEstimator:
    """``imm-kf``: IMM with linear Kalman updates (imm-arkf Table 1, middle column)."""
    return make_imm("kf", **overrides)


def imm_ekf(**overrides) -> ImmEstimator:
    """``imm-ekf``: IMM with EKF updates on range/bearing (imm-arkf Table 1, right column)."""
    return make_imm("ekf", **overrides)


def imm_arkf(**overrides) -> ImmEstimator:
    """``imm-arkf``: IMM with adaptive robust updates (imm-arkf §2.3, the proposed filter)."""
    return make_imm("arkf", **overrides)
