"""``TrustEstimator``: any link-trust policy as a full (Track B) estimator.

Policy + the environment's CEKF, driven from measurements alone: per step it predicts
with the IMU, computes the per-channel innovation features at the prior, asks the policy
for trust and applies it in the trust-weighted joint update — the same kernels
(``swarmloc.envs.filter.cekf``) and the same observation (``build_observation``) as
``LinkTrustCore``, so a policy gives the same estimates on both paths. Use it to run a
Track A method wherever only measurements are available (recorded data, another
estimator's harness).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmloc.envs.filter import cekf
from swarmloc.envs.world.observation import N_FEATURES, build_observation, kind_one_hot

from swarmloc.agents.estimators.dead_reckoning import cekf_prior
from swarmloc.agents.protocols import EstimatorOutput, LinkTrustPolicy, Measurements, PrivilegedInfo, TaskFacts, TrustInput


@dataclass
class _Features:
    """The raw fields ``build_observation`` reads (named as in ``CoreStep``)."""

    resid: np.ndarray
    pred: np.ndarray
    nis: np.ndarray
    applied: np.ndarray
    jerk: np.ndarray
    valid: np.ndarray


class TrustEstimator:
    """A ``LinkTrustPolicy`` plus the CEKF backbone, as an ``Estimator``.

    Args:
        policy: the link-trust policy.

    Attributes:
        privileged: that of the policy (labels are forwarded through ``observe_privileged``).
    """

    def __init__(self, policy: LinkTrustPolicy) -> None:
        if not callable(getattr(policy, "act", None)):
            raise TypeError(f"policy must be a LinkTrustPolicy (with act()), got {type(policy).__name__}")
        self.policy = policy
        self.privileged = bool(getattr(policy, "privileged", False))
        self.deterministic = bool(getattr(policy, "deterministic", True))
        self._facts: TaskFacts | None = None

    def reset(self, facts: TaskFacts, x0: np.ndarray) -> None:
        """Start B episodes from the prior ``x0`` ``(B, N, 6)`` with the stated initial std."""
        self.x, self.P = cekf_prior(facts, x0)
        self._facts = facts
        # the task's peer update; "split_ci" carries the independent parts (all of P0: the initial errors are
        # drawn independently)
        self._peer_update = cekf.PEER_UPDATE_CODES[facts.peer_update]
        self._P_ind = self.P.copy() if facts.peer_update == "split_ci" else None
        self._split_w = np.zeros((facts.batch_size, facts.n_uav, facts.n_channels + 1)) \
            if facts.peer_update == "split_ci" else None
        n_b, n, n_l = facts.batch_size, facts.n_uav, facts.n_channels
        self._prior_pos = np.zeros((n_b, n, 3))
        self._prev_imu = np.zeros((n_b, n, 3))
        self._r0 = np.ascontiguousarray(facts.sigma**2)
        self._kind = np.ascontiguousarray(facts.kind)
        self._target = np.ascontiguousarray(facts.target)
        self._anchors = np.ascontiguousarray(facts.anchors)
        self._landmarks = np.ascontiguousarray(facts.landmarks)
        self._one_hot = kind_one_hot(self._kind)
        self._feat = _Features(resid=np.zeros((n_b, n, n_l)), pred=np.zeros((n_b, n, n_l)),
                               nis=np.zeros((n_b, n, n_l)), applied=np.ones((n_b, n, n_l)),
                               jerk=np.zeros((n_b, n)), valid=np.zeros((n_b, n, n_l), dtype=bool))
        self._obs = np.zeros((n_b, n, n_l, N_FEATURES), dtype=np.float32)
        self._active = np.zeros((n_b, n, n_l), dtype=bool)
        self._flops = np.zeros((n_b, n))
        self.policy.reset(n_b, facts.layout, np.asarray(facts.keys))

    def observe_privileged(self, info: PrivilegedInfo) -> None:
        """Forward the pending measurements' fault labels to a privileged policy."""
        if not self.privileged:
            raise RuntimeError("observe_privileged called on a TrustEstimator around a non-privileged policy")
        self.policy.observe_privileged(info)  # type: ignore[attr-defined]

    def step(self, meas: Measurements) -> EstimatorOutput:
        """Predict, ask the policy for trust, update. Returns positions, covariances, trust, FLOPs."""
        f = self._facts
        if f is None:
            raise RuntimeError("call reset(facts, x0) before step()")
        feat = self._feat
        z = np.ascontiguousarray(meas.z, dtype=np.float64)
        valid = np.ascontiguousarray(meas.valid, dtype=np.bool_)
        imu = np.ascontiguousarray(meas.imu, dtype=np.float64)
        # x⁻ = F x + G u, P⁻ = F P Fᵀ + Q; broadcast priors for the peer channels
        cekf.cekf_predict(self.x, self.P, imu, f.dt, f.imu_sigma, self._prior_pos, self._P_ind)
        cekf.channel_features(self.x, self.P, z, valid, self._kind, self._target, self._r0, self._anchors,
                              self._landmarks, self._prior_pos, f.peer_nis_neighbour_cov, feat.resid, feat.pred,
                              feat.nis)
        feat.jerk[:] = np.linalg.norm(imu - self._prev_imu, axis=-1)
        feat.valid[:] = valid
        self._prev_imu[:] = imu
        build_observation(feat, self._one_hot, out=self._obs)  # type: ignore[arg-type]
        inp = TrustInput.view(self._obs, feat.resid, feat.pred, feat.nis, feat.applied, feat.jerk, feat.valid,
                              meas.t, meas.step)
        alpha = np.asarray(self.policy.act(inp), dtype=np.float64)
        if alpha.shape != feat.valid.shape:
            raise ValueError(f"policy returned trust of shape {alpha.shape}; expected (B, N, L) = {feat.valid.shape}")
        if not np.isfinite(alpha).all():
            bad = tuple(np.argwhere(~np.isfinite(alpha))[0].tolist())
            raise ValueError(f"policy returned non-finite trust {alpha[bad]} at index {bad}")
        alpha = np.clip(alpha, 0.0, 1.0)
        cekf.cekf_update(self.x, self.P, z, valid, alpha, self._kind, self._target, self._r0, self._anchors,
                         self._landmarks, self._prior_pos, f.alpha_th, f.alpha_min, self._active, self._flops,
                         self._peer_update, self._P_ind, self._split_w)
        feat.applied[:] = alpha
        policy_flops = float(getattr(self.policy, "flops_per_channel", 0.0)) * valid.sum(axis=-1)
        return EstimatorOutput(positions=self.x[..., :3].copy(), cov=self.P[..., :3, :3].copy(),
                               weights=alpha.copy(), flops=self._flops + policy_flops)
