"""Adaptive fault-tolerant federated filter for leader–follower swarms (federated §3–4).

Leaders run a GPS/IMU Kalman filter and broadcast their posterior position and
covariance. Each follower runs a two-sub-filter federated filter on the common state
x = [p, v] (world ENU), the common system being its IMU (constant-acceleration
prediction from the accelerometer, as the world's INS abstraction):

- sub-filter 1 (INS/GPS, eq. 3–7): z₁ = the follower's GPS fix, H = [I 0], R₁ = σ_gps² I;
- sub-filter 2 (INS/UWB + leader, eq. 8–12): z₂ = p̂_L − z_rel, the follower position
  implied by the leader's broadcast position and the UWB relative-position measurement
  z_rel = p_L − p_F + v (the paper's c − b; its a is our prior), H = [I 0],
  R₂ = σ_uwb² I as printed (V₂ = V_UWB). The leader's position is itself an estimate (its
  1 m GPS filtered), so the printed R₂ is ~10³× over-confident: on GradualFault-v0
  sub-filter 2 fails the χ² test at about half the steps. ``leader_cov_in_R=True`` uses
  the consistent R₂ = σ_uwb² I + P_L,pp (the leader's broadcast covariance); it lowers both
  schemes' error and removes the difference between them (``reproduce federated`` shows
  both).

Per step (eq. 22–31): information allocation x_i = x_g, P_i = P_g/βᵢ, Q_i = Q/βᵢ (eq. 23,
``share_information``); time update in the master (eq. 26–27); residuals r_i = z_i − H x̂⁻
and their covariances A_i (eq. 13–14); the adaptive allocation coefficient from
ΔV_i = r_iᵀr_i / tr(H P_i⁻ Hᵀ + R_i) (eq. 17–20) adapts R_i,k = R_i + 2(½ − β_i) R_i
(eq. 21) before each sub-filter's measurement update (eq. 28–30); χ² fault detection
λ_i = r_iᵀ A_i⁻¹ r_i > T_D (eq. 15–16, T_D from the false-alarm probability: 11.34 for
P_f = 0.01 and 3 dof) isolates a faulty sub-filter from the master fusion (eq. 31). The
allocation used at step k is the normalized β of step k−1 (eq. 23 needs it before the
residuals of step k exist).

Schemes (federated §5.2): ``adaptive`` (the proposed filter, registered ``federated``),
``fdi`` (Scheme 2: equal allocation β = ½, R fixed, FDI only; ``federated-fdi``),
``gps_ins`` (Scheme 1: the follower's own GPS/IMU Kalman filter, no cooperation).

Deviations: the paper's 15-state INS error model (attitude, gyro and accelerometer
biases) becomes the world's 6-state [p, v] with world-frame accelerometer input; its
leader is "high-precision GPS/INS", ours runs the same 6-state KF on its 1 m fix. If
every sub-filter of a follower fails the test, the one with the smaller λ is kept (the
paper switches to another leader, which GradualFault-v0 does not have).

``weights`` reports each used channel's applied trust R_i / R_i,k (clipped to [0, 1],
0 when isolated), so the metrics can score fault detection.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from swarmloc.envs.tasks.channels import GPS, PEER_REL

from swarmloc.agents.estimators.fusion import (
    adapted_noise,
    allocation_coefficients,
    chi2_threshold,
    federated_fuse,
    normalized_innovation_squared,
    residual_ratio,
    share_information,
)
from swarmloc.agents.protocols import EstimatorOutput, Measurements, TaskFacts

Scheme = Literal["adaptive", "fdi", "gps_ins"]
D = 6
_H = np.hstack([np.eye(3), np.zeros((3, 3))])  # position fix = H x
_BETA_EPS = 1e-9
#: analytic FLOPs per UAV-step (dense 6-state matrices, 2 per multiply-add): a GPS/IMU KF
#: step (prediction ≈ 4·6³, Joseph update ≈ 6·6³ + solve) and a two-sub-filter federated
#: cycle (two updates, two χ² tests, the information-form fusion ≈ 3 inversions of 6×6)
KF_FLOPS, FEDERATED_FLOPS = 2_400.0, 7_800.0


@dataclass(frozen=True)
class FederatedConfig:
    """Settings of the federated filter family (defaults: federated §4–5)."""

    scheme: Scheme = "adaptive"
    """``adaptive`` (proposed), ``fdi`` (Scheme 2) or ``gps_ins`` (Scheme 1)."""
    p_false_alarm: float = 0.01
    """False-alarm probability P_f of the χ² fault test; T_D = χ²⁻¹(1 − P_f, 3) = 11.34."""
    d: float = 0.85
    """Gate d of the allocation coefficient (eq. 17)."""
    accel_sigma: float | None = None
    """Process noise: accelerometer σ [m/s²] in Q = σ² G Gᵀ; None: the task's IMU σ."""
    accel_sigma_floor: float = 0.01
    """Added in quadrature to ``accel_sigma``: absorbs the unmodelled accelerometer bias [m/s²]."""
    leader_cov_in_R: bool = False
    """Sub-filter 2: the paper's R₂ = σ_uwb² I (False) or the consistent σ_uwb² I + P_L,pp (True)."""
    isolate: bool = True
    """Exclude sub-filters that fail the χ² test from the master fusion (FDI)."""

    def __post_init__(self) -> None:
        if self.scheme not in ("adaptive", "fdi", "gps_ins"):
            raise ValueError(f"scheme must be 'adaptive', 'fdi' or 'gps_ins', got {self.scheme!r}")
        if not 0.0 < self.p_false_alarm < 1.0:
            raise ValueError(f"p_false_alarm must be in (0, 1), got {self.p_false_alarm}")
        if not self.d > 0.0:
            raise ValueError(f"d must be > 0, got {self.d}")
        if self.accel_sigma is not None and not self.accel_sigma >= 0.0:
            raise ValueError(f"accel_sigma must be >= 0 or None, got {self.accel_sigma}")
        if not self.accel_sigma_floor >= 0.0:
            raise ValueError(f"accel_sigma_floor must be >= 0, got {self.accel_sigma_floor}")


# --------------------------------------------------------------------------- building blocks


def imu_prediction(x: np.ndarray, P: np.ndarray, u: np.ndarray, dt: float, accel_var: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Constant-acceleration prediction with the accelerometer: the common (INS) system.

    Args:
        x: (..., 6) [p, v]; P: (..., 6, 6); u: (..., 3) accelerometer [m/s²];
        dt: step [s]; accel_var: σ_a² of the acceleration noise [m²/s⁴].

    Returns:
        x⁻, P⁻ = F P Fᵀ + Q and Q = σ_a² G Gᵀ (6, 6).
    """
    F = np.eye(D)
    F[:3, 3:] = dt * np.eye(3)
    G = np.vstack([0.5 * dt * dt * np.eye(3), dt * np.eye(3)])
    Q = accel_var * (G @ G.T)
    # x⁻ = F x + G u
    x_pred = x @ F.T + u @ G.T
    # P⁻ = F P Fᵀ + Q
    P_pred = F @ P @ F.T + Q
    return x_pred, 0.5 * (P_pred + np.swapaxes(P_pred, -1, -2)), Q


def position_update(x: np.ndarray, P: np.ndarray, z: np.ndarray, R: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Kalman update with a position fix (eq. 28–30), Joseph form.

    Args:
        x: (..., 6) prior; P: (..., 6, 6); z: (..., 3) fix; R: (..., 3, 3) its noise.

    Returns:
        x, P, the residual r = z − H x⁻ (eq. 13) and A = H P⁻ Hᵀ + R (eq. 14).
    """
    r = z - x[..., :3]
    A = P[..., :3, :3] + R
    # K = P⁻ Hᵀ A⁻¹
    K = np.swapaxes(np.linalg.solve(A, P[..., :3, :]), -1, -2)
    x_new = x + (K @ r[..., None])[..., 0]
    # P = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ
    IKH = np.eye(D) - K @ _H
    P_new = IKH @ P @ np.swapaxes(IKH, -1, -2) + K @ R @ np.swapaxes(K, -1, -2)
    return x_new, 0.5 * (P_new + np.swapaxes(P_new, -1, -2)), r, A


def _column_of(kind: np.ndarray, linked: np.ndarray, wanted: int) -> np.ndarray:
    """(N,) first linked slot of kind ``wanted`` per UAV, −1 where none."""
    hit = (kind == wanted) & linked
    return np.where(hit.any(axis=1), np.argmax(hit, axis=1), -1)


@dataclass(frozen=True)
class CycleInfo:
    """Diagnostics of one federated cycle, each (..., S) over the S = 2 sub-filters.

    Attributes:
        beta: normalized allocation coefficients β_t (eq. 20) of this step.
        lam: fault detection function λ (eq. 15), 0 where a sub-filter had no measurement.
        fault: λ > T_D (eq. 16).
        used: sub-filters that took part in the master fusion.
    """

    beta: np.ndarray
    lam: np.ndarray
    fault: np.ndarray
    used: np.ndarray


def federated_cycle(x_pred: np.ndarray, P_pred: np.ndarray, Q: np.ndarray, z: np.ndarray, R: np.ndarray,
                    has: np.ndarray, beta: np.ndarray, cfg: FederatedConfig, T_D: float
                    ) -> tuple[np.ndarray, np.ndarray, CycleInfo]:
    """One federated cycle (eq. 13–31) after the master's time update of the global state.

    Args:
        x_pred: (..., 6) global prediction x_g⁻; P_pred: (..., 6, 6) P_g⁻ = F P_g Fᵀ + Q.
        Q: (6, 6) process noise of the common system.
        z: (..., S, 3) sub-filter position measurements; R: (..., S, 3, 3) their initial noise.
        has: (..., S) bool, measurement present.
        beta: (..., S) allocation of the previous step (eq. 20), summing to 1.
        cfg: settings (``scheme`` "adaptive" or "fdi", ``d``, ``isolate``).
        T_D: χ² threshold.

    Returns:
        x_g: (..., 6), P_g: (..., 6, 6) and the cycle's ``CycleInfo``.
    """
    # information allocation (eq. 23): x_i = x_g, P_i⁻ = P_g⁻ / β_i (Q_i = Q / β_i folded in, eq. 27)
    x_i, P_i, _ = share_information(x_pred, P_pred, Q, beta)
    # residuals and their covariances with the initial R (eq. 13–14, 18–19)
    r = z - x_i[..., :3]
    A0 = P_i[..., :3, :3] + R
    if cfg.scheme == "adaptive":
        # ΔV_i = r_iᵀ r_i / tr(H P_i⁻ Hᵀ + R_i)                               (eq. 19)
        dV = np.where(has, residual_ratio(r, A0), 0.0)
        # β_i = 1 if |ΔV_i| ≤ d else d/|ΔV_i|, normalized to Σ β = 1           (eq. 17, 20)
        beta_t = allocation_coefficients(dV, cfg.d)
        # a share of exactly 0 or 1 would make eq. 21 singular; float rounding can reach both
        beta_t = np.clip(beta_t, _BETA_EPS, 1.0 - _BETA_EPS)
        # R_i,k = R_i + 2 (½ − β_i) R_i                                         (eq. 21)
        R_k = adapted_noise(R, beta_t, n_sub=2)
    else:
        beta_t = np.full(has.shape, 0.5)
        R_k = R
    # sub-filter measurement updates (eq. 28–30)
    x_u, P_u, r, A = position_update(x_i, P_i, z, R_k)
    x_u = np.where(has[..., None], x_u, x_i)
    P_u = np.where(has[..., None, None], P_u, P_i)
    # χ² fault detection λ_i = r_iᵀ A_i⁻¹ r_i > T_D                           (eq. 15–16)
    lam = np.where(has, normalized_innovation_squared(r, A), 0.0)
    fault = (lam > T_D) & has
    use = ~fault if cfg.isolate else np.ones_like(fault)
    nobody = ~use.any(axis=-1)
    if nobody.any():  # both failed: keep the less inconsistent one
        best = np.argmin(np.where(has, lam, np.inf), axis=-1)
        use = np.where(nobody[..., None], np.arange(has.shape[-1]) == best[..., None], use)
    # master fusion P_g = (Σ P_i⁻¹)⁻¹, x_g = P_g Σ P_i⁻¹ x_i over non-isolated sub-filters (eq. 31)
    x_g, P_g = federated_fuse(x_u, P_u, use)
    return x_g, P_g, CycleInfo(beta=beta_t, lam=lam, fault=fault, used=use)


# --------------------------------------------------------------------------- estimator


class FederatedEstimator:
    """Track B estimator: leader GPS/IMU KFs + follower federated filters (``federated``, ``federated-fdi``).

    Leaders are the UAVs without a linked relative-position channel; each follower uses the
    first leader its relative-position channel links to.

    Args:
        config: settings (default: the adaptive fault-tolerant federated filter).
    """

    privileged = False
    deterministic = True

    def __init__(self, config: FederatedConfig | None = None) -> None:
        self.config = config or FederatedConfig()
        self._ready = False
        self.last_lambda: np.ndarray | None = None
        self.last_beta: np.ndarray | None = None
        self.last_fault: np.ndarray | None = None

    def __repr__(self) -> str:
        return f"FederatedEstimator(config={self.config!r})"

    def reset(self, facts: TaskFacts, x0: np.ndarray) -> None:
        """Start B episodes from the public prior ``x0`` (B, N, 6).

        Raises:
            ValueError: some UAV has no GPS channel, no UAV is a leader, or ``x0`` is malformed.
        """
        kind, linked = np.asarray(facts.kind), np.asarray(facts.linked)
        self._gps = _column_of(kind, linked, GPS)
        if (self._gps < 0).any():
            raise ValueError(f"the federated filter needs a GPS fix on every UAV; task {facts.task_id} gives none "
                             f"to UAVs {np.flatnonzero(self._gps < 0).tolist()}")
        self._rel = _column_of(kind, linked, PEER_REL)
        self._followers = np.flatnonzero(self._rel >= 0)
        self._leaders = np.flatnonzero(self._rel < 0)
        if self._leaders.size == 0:
            raise ValueError(f"task {facts.task_id}: every UAV has a relative-position link, so none is a leader")
        self._leader_of = np.asarray(facts.target)[self._followers, self._rel[self._followers]]
        x0 = np.asarray(x0, dtype=np.float64)
        n_b, n = facts.batch_size, facts.n_uav
        if x0.shape != (n_b, n, D):
            raise ValueError(f"x0 must have shape ({n_b}, {n}, {D}), got {x0.shape}")
        cfg = self.config
        sa = facts.imu_sigma if cfg.accel_sigma is None else cfg.accel_sigma
        self._accel_var = sa**2 + cfg.accel_sigma_floor**2
        sigma = np.asarray(facts.sigma)
        idx = np.arange(n)
        self._R_gps = sigma[idx, self._gps][:, None, None] ** 2 * np.eye(3)  # (N, 3, 3)
        self._rel_var = np.where(self._rel >= 0, sigma[idx, np.maximum(self._rel, 0)] ** 2, 0.0)
        self._dt = facts.dt
        self._T_D = chi2_threshold(cfg.p_false_alarm, 3)
        self.x = x0.copy()
        diag = np.r_[np.full(3, facts.init_pos_sigma**2), np.full(3, facts.init_vel_sigma**2)]
        self.P = np.broadcast_to(np.diag(diag), (n_b, n, D, D)).copy()
        # normalized allocation coefficients of the followers' two sub-filters (eq. 20, 22)
        self.beta = np.full((n_b, self._followers.size, 2), 0.5)
        self._L = facts.n_channels
        self._ready = True

    # ---- one step
    def step(self, meas: Measurements) -> EstimatorOutput:
        """Leaders' KF update, then every follower's federated cycle; returns positions and covariances."""
        if not self._ready:
            raise RuntimeError("call reset(facts, x0) before step()")
        cfg = self.config
        n_b, n = self.x.shape[:2]
        idx = np.arange(n)
        weights = np.zeros((n_b, n, self._L))
        gps_z = meas.z[:, idx, self._gps]
        gps_ok = meas.valid[:, idx, self._gps]
        x_pred, P_pred, Q = imu_prediction(self.x, self.P, np.asarray(meas.imu), self._dt, self._accel_var)

        # ---- leaders (and Scheme 1 followers): GPS/IMU Kalman filter
        solo = self._leaders if cfg.scheme != "gps_ins" else idx
        xs, Ps, _, _ = position_update(x_pred[:, solo], P_pred[:, solo], gps_z[:, solo],
                                       np.broadcast_to(self._R_gps[solo], (n_b, solo.size, 3, 3)))
        ok = gps_ok[:, solo]
        self.x[:, solo] = np.where(ok[..., None], xs, x_pred[:, solo])
        self.P[:, solo] = np.where(ok[..., None, None], Ps, P_pred[:, solo])
        weights[:, solo, self._gps[solo]] = ok
        if cfg.scheme != "gps_ins" and self._followers.size:
            self._federated_followers(meas, x_pred, P_pred, Q, gps_z, gps_ok, weights)
        flops = np.full((n_b, n), KF_FLOPS)
        if cfg.scheme != "gps_ins":
            flops[:, self._followers] = FEDERATED_FLOPS
        return EstimatorOutput(positions=self.x[..., :3].copy(), cov=self.P[..., :3, :3].copy(), weights=weights,
                               flops=flops)

    def _federated_followers(self, meas: Measurements, x_pred: np.ndarray, P_pred: np.ndarray, Q: np.ndarray,
                             gps_z: np.ndarray, gps_ok: np.ndarray, weights: np.ndarray) -> None:
        """The federated cycle (eq. 13–31) of every follower, batched over (B, followers)."""
        cfg = self.config
        f, lead = self._followers, self._leader_of
        n_b, n_f = self.x.shape[0], f.size
        rel_cols = self._rel[f]
        # sub-filter measurements: z₁ = GPS fix, z₂ = p̂_L − z_rel (eq. 5, 11)
        z_rel = meas.z[:, f, rel_cols]
        rel_ok = meas.valid[:, f, rel_cols]
        z = np.stack([gps_z[:, f], self.x[:, lead, :3] - z_rel], axis=2)  # (B, F, 2, 3)
        has = np.stack([gps_ok[:, f], rel_ok], axis=2)  # (B, F, 2)
        R2 = self._rel_var[f][:, None, None] * np.eye(3)
        if cfg.leader_cov_in_R:
            R2 = R2 + self.P[:, lead, :3, :3]
        R = np.stack([np.broadcast_to(self._R_gps[f], (n_b, n_f, 3, 3)), np.broadcast_to(R2, (n_b, n_f, 3, 3))],
                     axis=2)  # (B, F, 2, 3, 3) initial R_i
        x_g, P_g, cyc = federated_cycle(x_pred[:, f], P_pred[:, f], Q, z, R, has, self.beta, cfg, self._T_D)
        self.x[:, f], self.P[:, f] = x_g, P_g
        self.beta = cyc.beta
        self.last_lambda, self.last_beta, self.last_fault = cyc.lam, cyc.beta, cyc.fault
        trust = np.clip(1.0 / (2.0 - 2.0 * cyc.beta), 0.0, 1.0) * cyc.used * has  # R_i / R_i,k
        weights[:, f, self._gps[f]] = trust[..., 0]
        weights[:, f, rel_cols] = trust[..., 1]


def make_federated(**overrides) -> FederatedEstimator:
    """A federated estimator with ``FederatedConfig`` field overrides (e.g. ``scheme="fdi"``)."""
    return FederatedEstimator(replace(FederatedConfig(), **overrides))


def federated(**overrides) -> FederatedEstimator:
    """``federated``: the adaptive fault-tolerant federated filter (the paper's proposed scheme)."""
    return make_federated(**{"scheme": "adaptive", **overrides})


def federated_fdi(**overrides) -> FederatedEstimator:
    """``federated-fdi``: the paper's Scheme 2, equal allocation (β = ½), χ² FDI only."""
    return make_federated(**{"scheme": "fdi", **overrides})


def gps_ins(**overrides) -> FederatedEstimator:
    """The paper's Scheme 1: every UAV on its own GPS/IMU Kalman filter (no cooperation)."""
    return make_federated(**{"scheme": "gps_ins", **overrides})
