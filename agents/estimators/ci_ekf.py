"""Covariance-intersection EKF for anchor-free swarms (dtvirm §3.6–3.7): ``ci-ekf``, ``ci-ekf-no-aa``.

One 6-state EKF per UAV, x = [p, v] (world ENU), in dtvirm's frame (node 0's first
position is the origin; see ``swarmloc.agents.estimators.init.initializer``):

1. **Initialization** (§3.3). During the initializer's window the filter only collects
   ranges and odometry (its output meanwhile is the prior dead-reckoned with the VO);
   then MDS-MAP + odometry refinement sets x and P = diag(σ_init², σ_vo²).
2. **Prediction** with the accelerometer (constant acceleration over dt),
   Q = (σ_imu² + σ_floor²) G Gᵀ; σ_floor absorbs the unmodelled accelerometer bias.
3. **Own-sensor update** with the VO velocity, H = [0 I], R = (σ_vo² + σ_vo,floor²) I.
   Each UAV then broadcasts this estimate and covariance to its neighbours.
4. **Cooperative UWB update** (Algorithm 3). For each valid range dᵢⱼ to neighbour j:
   h = (p̂ᵢ − p̂ⱼ)ᵀ/‖p̂ᵢ − p̂ⱼ‖; covariance intersection of the two position estimates,
   α* = argmin tr P_CI (eq. 38–39, ``ci_fuse``); neighbour-uncertainty-aware noise
   Rᵢⱼ = σ_uwb² + h P_CI hᵀ (§3.6.3; ``ci=False`` uses h Pⱼ hᵀ, §3.6.2). The χ²-based
   adaptive adjustment (§3.7, "UWB_AA") weights each range by w = 1 inside the 95 % χ²
   gate and exp(−(λ − χ²)/(2σ²)) beyond it, λ = y²/(h Pᵢ hᵀ + Rᵢⱼ), and uses R/w. All
   ranges of a UAV then enter one joint EKF update (Jacobians at the broadcast estimates,
   Joseph form). ``ci-ekf-no-aa`` is the ablation without the adjustment (w = 1).

Where we depart from the paper: dtvirm's cumulative UWB measurement collapses the ranges
to one weighted scalar and its χ² test uses a 6-dof residual (12.59); we keep one row per
range and gate each range on its own 1-dof statistic (3.84), so one NLOS link does not
drag a UAV's healthy links down with it. There is no sliding window, no magnetometer and
no visual (PO) model: the world gives the VO velocity directly (landmark-free VO), and
its world frame plays the role of the compass.

``weights`` reports w on every valid peer channel (1 for ``ci-ekf-no-aa``), so the
metrics' anomaly detection rate is dtvirm Table 6's "detected / abnormal".
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np

from swarmloc.envs.tasks.channels import ANCHOR, GPS, KIND_NAMES, LANDMARK, PEER, TDOA

from swarmloc.agents.estimators.federated import imu_prediction
from swarmloc.agents.estimators.fusion import chi2_soft_weight, ci_fuse
from swarmloc.agents.estimators.init.initializer import InitConfig, MdsMapInitializer
from swarmloc.agents.protocols import EstimatorOutput, Measurements, TaskFacts, UnsupportedTask

D = 6
_W_MIN = 1e-12  # the smallest weight: R ≤ 10¹² R, a range that is effectively ignored
#: analytic FLOPs of the per-UAV parts (dense 6-state matrices, 2 per multiply-add)
PREDICT_FLOPS, VO_UPDATE_FLOPS, CI_FLOPS_PER_LINK = 900.0, 1_500.0, 1_400.0


@dataclass(frozen=True)
class CiEkfConfig:
    """Settings of the CI-EKF (defaults: dtvirm §3.6–3.7 and AnchorFree-v0's nominal noise)."""

    ci: bool = True
    """Neighbour noise from the CI-fused covariance (True) or from the neighbour's own P (False)."""
    adaptive_adjustment: bool = True
    """χ²-based UWB adaptive adjustment (UWB_AA, §3.7); False is the ``no-aa`` ablation."""
    aa_confidence: float = 0.95
    """Confidence of the χ² gate of the adjustment (3.84 for one range)."""
    aa_sigma: float = 1.0
    """Softness σ of w = exp(−(λ − χ²)/(2σ²)) beyond the gate."""
    accel_sigma_floor: float = 0.05
    """Added in quadrature to the IMU σ in Q [m/s²]: the unmodelled accelerometer bias."""
    vo_sigma: float | None = None
    """VO velocity std [m/s]; None: the task's nominal ``velocity_sigma``."""
    vo_sigma_floor: float = 0.05
    """Added in quadrature to the VO σ [m/s]: the unmodelled VO bias (drift)."""
    init: Literal["mdsmap", "prior"] = "mdsmap"
    """``mdsmap``: dtvirm's initialization (ignores the prior positions); ``prior``: start from x₀."""
    init_config: InitConfig = field(default_factory=lambda: InitConfig(window=2.0))
    """The MDS-MAP initializer's settings (2 s window: see ``reproduce dtvirm``)."""
    init_pos_sigma: float = 0.5
    """Position std of the state the initializer hands over [m]."""

    def __post_init__(self) -> None:
        if not 0.0 < self.aa_confidence < 1.0:
            raise ValueError(f"aa_confidence must be in (0, 1), got {self.aa_confidence}")
        for name in ("aa_sigma", "init_pos_sigma"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        for name in ("accel_sigma_floor", "vo_sigma_floor"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")
        if self.vo_sigma is not None and not self.vo_sigma > 0:
            raise ValueError(f"vo_sigma must be > 0 or None, got {self.vo_sigma}")
        if self.init not in ("mdsmap", "prior"):
            raise ValueError(f"init must be 'mdsmap' or 'prior', got {self.init!r}")


def _sym(P: np.ndarray) -> np.ndarray:
    return 0.5 * (P + np.swapaxes(P, -1, -2))


def velocity_update(x: np.ndarray, P: np.ndarray, v: np.ndarray, r: float) -> tuple[np.ndarray, np.ndarray]:
    """EKF update with a velocity measurement: H = [0 I], R = r I (Joseph form).

    Args:
        x: (..., 6); P: (..., 6, 6); v: (..., 3) measured velocity; r: its variance per axis.
    """
    H = np.hstack([np.zeros((3, 3)), np.eye(3)])
    # S = P_vv + R,  K = P Hᵀ S⁻¹
    S = P[..., 3:, 3:] + r * np.eye(3)
    K = np.swapaxes(np.linalg.solve(S, P[..., 3:, :]), -1, -2)
    x = x + (K @ (v - x[..., 3:])[..., None])[..., 0]
    A = np.eye(D) - K @ H
    P = A @ P @ np.swapaxes(A, -1, -2) + r * K @ np.swapaxes(K, -1, -2)
    return x, _sym(P)


@dataclass(frozen=True)
class RangeUpdateInfo:
    """Diagnostics of one cooperative update, each (B, N, L): NIS λ, weight w, noise R used."""

    nis: np.ndarray
    weight: np.ndarray
    R: np.ndarray


def range_update(x: np.ndarray, P: np.ndarray, d: np.ndarray, valid: np.ndarray, target: np.ndarray,
                 sigma: np.ndarray, cfg: CiEkfConfig) -> tuple[np.ndarray, np.ndarray, RangeUpdateInfo]:
    """Joint cooperative UWB update of every UAV against its neighbours' broadcast estimates.

    Args:
        x: (B, N, 6) broadcast estimates (each UAV's own prior for the update, its
            neighbours' for their positions); P: (B, N, 6, 6).
        d: (B, N, L) measured ranges; valid: (B, N, L) bool (only peer slots may be True).
        target: (N, L) neighbour index of each slot (any index where never valid).
        sigma: (N, L) nominal range std [m].
        cfg: settings.

    Returns:
        Updated x, P and the per-range diagnostics.
    """
    B, N, L = d.shape
    rows = np.arange(N)[:, None]
    tgt = np.where(target >= 0, target, rows)  # unused slots point at the UAV itself (masked below)
    p_i = np.broadcast_to(x[:, :, None, :3], (B, N, L, 3))
    P_i = np.broadcast_to(P[:, :, None, :3, :3], (B, N, L, 3, 3))
    p_j = x[:, tgt, :3]  # (B, N, L, 3)
    P_j = P[:, tgt, :3, :3]
    u = p_i - p_j
    d_hat = np.maximum(np.linalg.norm(u, axis=-1), 1e-6)
    h = u / d_hat[..., None]  # ∂d/∂pᵢ
    if cfg.ci:
        # P_CI⁻¹ = (1 − α) Pᵢ⁻¹ + α Pⱼ⁻¹, α* = argmin tr P_CI                      (eq. 38–39)
        _, P_n, _ = ci_fuse(p_i, P_i, p_j, P_j)
    else:
        P_n = P_j
    # Rᵢⱼ = σ² + h P hᵀ                                                            (§3.6.2–3.6.3)
    R = sigma**2 + np.einsum("bnli,bnlij,bnlj->bnl", h, P_n, h)
    y = d - d_hat
    # λ = y² / (h Pᵢ hᵀ + Rᵢⱼ)                                                      (§3.7)
    nis = y**2 / (np.einsum("bnli,bnlij,bnlj->bnl", h, P_i, h) + R)
    if cfg.adaptive_adjustment:
        w = np.maximum(chi2_soft_weight(nis, 1, cfg.aa_confidence, cfg.aa_sigma), _W_MIN)
    else:
        w = np.ones_like(nis)
    ok = valid & (target >= 0)[None]
    R_used = np.where(ok, R / w, 1.0)
    H = np.zeros((B, N, L, D))
    H[..., :3] = np.where(ok[..., None], h, 0.0)
    y = np.where(ok, y, 0.0)
    # S = H P Hᵀ + diag(R/w),  K = P Hᵀ S⁻¹,  x = x + K y,  Joseph form for P
    PHt = P @ np.swapaxes(H, -1, -2)  # (B, N, 6, L)
    S = _sym(H @ PHt) + R_used[..., None] * np.eye(L)
    K = np.swapaxes(np.linalg.solve(S, np.swapaxes(PHt, -1, -2)), -1, -2)
    x_new = x + (K @ y[..., None])[..., 0]
    A = np.eye(D) - K @ H
    P_new = A @ P @ np.swapaxes(A, -1, -2) + (K * R_used[..., None, :]) @ np.swapaxes(K, -1, -2)
    return x_new, _sym(P_new), RangeUpdateInfo(nis=np.where(ok, nis, 0.0), weight=np.where(ok, w, 0.0), R=R)


class CiEkfEstimator:
    """Track B estimator: dtvirm's anchor-free cooperative EKF with CI and UWB adaptive adjustment.

    Args:
        config: settings.
    """

    privileged = False
    deterministic = True

    def __init__(self, config: CiEkfConfig | None = None) -> None:
        self.config = config or CiEkfConfig()
        self.initializer: MdsMapInitializer | None = None
        self.last_info: RangeUpdateInfo | None = None
        self._ready = False

    def __repr__(self) -> str:
        return f"CiEkfEstimator(config={self.config!r})"

    def reset(self, facts: TaskFacts, x0: np.ndarray) -> None:
        """Start B episodes.

        Raises:
            UnsupportedTask: the task has no peer ranges, or it has absolute references
                (anchors, TDOA, landmarks, GPS): the CI-EKF estimates in dtvirm's relative frame
                from peer ranges and VO alone, so its positions are not the task's world frame.
            ValueError: ``x0`` is malformed.
        """
        cfg = self.config
        kind = np.asarray(facts.kind)
        self._peer = (kind == PEER) & np.asarray(facts.linked)
        if not self._peer.any():
            raise UnsupportedTask(f"the CI-EKF fuses peer ranges; task {facts.task_id} has none")
        absolute = sorted({KIND_NAMES[k] for k in np.unique(kind) if k in (ANCHOR, TDOA, LANDMARK, GPS)})
        if absolute:
            raise UnsupportedTask(
                f"the CI-EKF is anchor-free: it estimates in dtvirm's relative frame (UAV 0's first position is the "
                f"origin) from peer ranges and VO alone, while task {facts.task_id} has absolute references "
                f"({', '.join(absolute)}) and scores world-frame positions")
        x0 = np.asarray(x0, dtype=np.float64)
        B, N = facts.batch_size, facts.n_uav
        if x0.shape != (B, N, D):
            raise ValueError(f"x0 must have shape ({B}, {N}, {D}), got {x0.shape}")
        self._target = np.where(self._peer, np.asarray(facts.target), -1)
        self._sigma = np.where(self._peer, np.asarray(facts.sigma), 1.0)
        self._dt = facts.dt
        self._accel_var = facts.imu_sigma**2 + cfg.accel_sigma_floor**2
        vo = cfg.vo_sigma if cfg.vo_sigma is not None else facts.velocity_sigma
        self._vo_var = None if vo is None else vo**2 + cfg.vo_sigma_floor**2
        self.x = x0.copy()
        diag = np.r_[np.full(3, facts.init_pos_sigma**2), np.full(3, facts.init_vel_sigma**2)]
        self.P = np.broadcast_to(np.diag(diag), (B, N, D, D)).copy()
        self._L = facts.n_channels
        self.initializer = MdsMapInitializer(facts, cfg.init_config) if cfg.init == "mdsmap" else None
        self._links = float(self._peer.sum(axis=1).mean())
        self._ready = True

    def step(self, meas: Measurements) -> EstimatorOutput:
        """Initializer window, or predict → VO update → cooperative UWB update; returns positions."""
        if not self._ready:
            raise RuntimeError("call reset(facts, x0) before step()")
        B, N = self.x.shape[:2]
        weights = np.zeros((B, N, self._L))
        self.x, self.P, _ = imu_prediction(self.x, self.P, np.asarray(meas.imu), self._dt, self._accel_var)
        if meas.velocity is not None and self._vo_var is not None:
            self.x, self.P = velocity_update(self.x, self.P, np.asarray(meas.velocity), self._vo_var)
        flops = np.full((B, N), PREDICT_FLOPS + VO_UPDATE_FLOPS)
        if self.initializer is not None:
            if self.initializer.observe(meas):
                # hand over: the MDS-MAP state, P = diag(σ_init², σ_vo²)
                self.x = self.initializer.solve()
                vel_var = self._vo_var if self._vo_var is not None else 0.25
                diag = np.r_[np.full(3, self.config.init_pos_sigma**2), np.full(3, vel_var)]
                self.P = np.broadcast_to(np.diag(diag), (B, N, D, D)).copy()
                self.initializer = None
            return EstimatorOutput(positions=self.x[..., :3].copy(), cov=self.P[..., :3, :3].copy(),
                                   weights=np.where(np.asarray(meas.valid) & self._peer[None], 1.0, 0.0),
                                   flops=flops)
        d = np.asarray(meas.z)[..., 0]
        valid = np.asarray(meas.valid) & self._peer[None]
        self.x, self.P, self.last_info = range_update(self.x, self.P, d, valid, self._target, self._sigma,
                                                      self.config)
        weights[valid] = self.last_info.weight[valid]
        flops += CI_FLOPS_PER_LINK * valid.sum(axis=-1)
        return EstimatorOutput(positions=self.x[..., :3].copy(), cov=self.P[..., :3, :3].copy(), weights=weights,
                               flops=flops)


def make_ci_ekf(**overrides) -> CiEkfEstimator:
    """A CI-EKF with ``CiEkfConfig`` field overrides."""
    return CiEkfEstimator(replace(CiEkfConfig(), **overrides))


def ci_ekf(**overrides) -> CiEkfEstimator:
    """``ci-ekf``: CI-enhanced neighbour noise + χ² UWB adaptive adjustment (dtvirm COO_OUR)."""
    return make_ci_ekf(**overrides)


def ci_ekf_no_aa(**overrides) -> CiEkfEstimator:
    """``ci-ekf-no-aa``: the same without the UWB adaptive adjustment (dtvirm COO_OUR without_UWB_AA)."""
    return make_ci_ekf(**{"adaptive_adjustment": False, **overrides})
