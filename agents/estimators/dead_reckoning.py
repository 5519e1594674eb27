"""``dead-reckoning``: IMU-only integration from the initial prior (Track B floor).

Each UAV integrates its accelerometer with the constant-acceleration model of the CEKF
backbone (x⁻ = F x + G u, P⁻ = F P Fᵀ + Q) and never uses a channel, so its error grows
without bound: the "Pure DR" row of madrl Table 3.
"""

from __future__ import annotations

import numpy as np

from swarmloc.envs.filter import cekf
from swarmloc.envs.world.cost import PREDICT_FLOPS

from swarmloc.agents.protocols import EstimatorOutput, Measurements, TaskFacts


def cekf_prior(facts: TaskFacts, x0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The CEKF backbone's start: the mean ``x`` ``(B, N, 6)`` (a float64 copy of the prior ``x0``) and the
    covariance ``P`` ``(B, N, 6, 6)`` of the task's stated initial std (also ``TrustEstimator``'s start).

    Raises:
        ValueError: ``x0`` is not ``(B, N, 6)``.
    """
    n_b, n = facts.batch_size, facts.n_uav
    if np.shape(x0) != (n_b, n, 6):
        raise ValueError(f"x0 must have shape (B, N, 6) = {(n_b, n, 6)}, got {np.shape(x0)}")
    return np.array(x0, dtype=np.float64), cekf.initial_covariance(n_b, n, facts.init_pos_sigma, facts.init_vel_sigma)


class DeadReckoning:
    """IMU dead reckoning from the initial prior mean (no channel is ever used)."""

    privileged = False
    deterministic = True

    def __init__(self) -> None:
        self._facts: TaskFacts | None = None

    def reset(self, facts: TaskFacts, x0: np.ndarray) -> None:
        """Start B episodes at the prior ``x0`` ``(B, N, 6)`` with the stated initial std."""
        self.x, self.P = cekf_prior(facts, x0)
        self._facts = facts
        n_b, n = facts.batch_size, facts.n_uav
        self._prior_pos = np.zeros((n_b, n, 3))
        self._flops = np.full((n_b, n), float(PREDICT_FLOPS))

    def step(self, meas: Measurements) -> EstimatorOutput:
        """Integrate one IMU reading. Returns positions, position covariances and FLOPs."""
        f = self._facts
        if f is None:
            raise RuntimeError("call reset(facts, x0) before step()")
        imu = np.ascontiguousarray(meas.imu, dtype=np.float64)
        cekf.cekf_predict(self.x, self.P, imu, f.dt, f.imu_sigma, self._prior_pos)
        return EstimatorOutput(positions=self.x[..., :3].copy(), cov=self.P[..., :3, :3].copy(),
                               flops=self._flops.copy())


def dead_reckoning() -> DeadReckoning:
    """Registry factory: ``dead-reckoning``."""
    return DeadReckoning()
