"""Standard reward v0 (docs/reward.md; madrl §2.2.3, see docs/references.md).

Per UAV i at step k: r = R_acc − λ1·P_delay − λ2·P_energy − λ3·P_jitter, λ = (10, 0.1, 5):
  R_acc    = exp(−‖p̂ − p‖² / (2σ_acc²)), σ_acc = 1 m;
  P_delay  = max(0, exp((t_calc − T_max)/T_max) − 1), T_max = 50 ms,
             t_calc = (filter FLOPs + policy FLOPs) / processor FLOP/s;
  P_energy = fraction of valid channels with α > α_th (active channels);
  P_jitter = mean |α(k) − α(k−1)| over valid channels.
Team reward = mean over UAVs. Energy [J] = t_calc × processor watts.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from swarmloc.envs.world.cost import DEFAULT_PROFILE, ProcessorProfile

REWARD_VERSION = 0


class RewardWeights(BaseModel):
    """Weights and constants of the standard reward; the defaults are the standard (v0)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    delay: float = Field(default=10.0, ge=0.0, description="λ1")
    energy: float = Field(default=0.1, ge=0.0, description="λ2")
    jitter: float = Field(default=5.0, ge=0.0, description="λ3")
    sigma_acc: float = Field(default=1.0, gt=0.0, description="σ_acc [m]")
    t_max: float = Field(default=0.05, gt=0.0, description="T_max [s]")


STANDARD_WEIGHTS = RewardWeights()


@dataclass
class RewardTerms:
    """Every term of the reward, ``(B, N)`` each."""

    reward: np.ndarray
    accuracy: np.ndarray
    delay_penalty: np.ndarray
    energy_penalty: np.ndarray
    jitter_penalty: np.ndarray
    flops: np.ndarray
    delay_ms: np.ndarray
    energy_j: np.ndarray


def standard_reward(estimate: np.ndarray, truth: np.ndarray, applied: np.ndarray, previous: np.ndarray,
                    valid: np.ndarray, alpha_th: float, filter_flops: np.ndarray,
                    policy_flops: np.ndarray | float = 0.0, weights: RewardWeights = STANDARD_WEIGHTS,
                    profile: ProcessorProfile = DEFAULT_PROFILE) -> RewardTerms:
    """Standard reward v0 per UAV.

    Args:
        estimate, truth: ``(B, N, 3)`` posterior and true positions.
        applied, previous: ``(B, N, L)`` trust applied now and at the previous step.
        valid: ``(B, N, L)`` measurement present.
        alpha_th: activity threshold α_th.
        filter_flops: ``(B, N)`` CEKF FLOPs of the step.
        policy_flops: FLOPs of the method's own computation per UAV (scalar or ``(B, N)``).
        weights: λ and constants (default: the standard).
        profile: processor profile converting FLOPs into seconds and joules.

    Returns:
        ``RewardTerms`` with the reward and every term, ``(B, N)``.
    """
    err2 = np.sum((estimate - truth) ** 2, axis=-1)
    accuracy = np.exp(-err2 / (2.0 * weights.sigma_acc**2))
    flops = filter_flops + policy_flops
    t_calc = profile.seconds(flops)
    delay_penalty = np.maximum(0.0, np.exp((t_calc - weights.t_max) / weights.t_max) - 1.0)
    n_valid = valid.sum(axis=-1)
    denom = np.maximum(n_valid, 1)
    energy_penalty = ((applied > alpha_th) & valid).sum(axis=-1) / denom
    jitter_penalty = (np.abs(applied - previous) * valid).sum(axis=-1) / denom
    reward = accuracy - weights.delay * delay_penalty - weights.energy * energy_penalty \
        - weights.jitter * jitter_penalty
    return RewardTerms(reward=reward, accuracy=accuracy, delay_penalty=delay_penalty,
                       energy_penalty=energy_penalty, jitter_penalty=jitter_penalty, flops=np.asarray(flops, float)
                       * np.ones_like(accuracy), delay_ms=1e3 * t_calc * np.ones_like(accuracy),
                       energy_j=profile.joules(flops) * np.ones_like(accuracy))


def team_reward(terms: RewardTerms) -> np.ndarray:
    """``(B,)`` team reward: the mean over UAVs of the per-UAV reward."""
    return terms.reward.sum(axis=1) / terms.reward.shape[1]
