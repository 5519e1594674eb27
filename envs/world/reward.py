"""Standard reward v0 (docs/reward.md; madrl §2.2.3, see docs/references.md).

Per UAV i at step k: r = R_acc − λ1·P_delay − λ2·P_energy − λ3·P_jitter, λ = (10, 0.1, 5):
  R_acc    = exp(−‖p̂ − p‖² / (2σ_acc²)), σ_acc = 1 m;
  P_delay  = max(0, exp((t_calc − T_max)/T_max) − 1), T_max = 50 ms,
             t_calc = (filter FLOPs + policy FLOPs) / processor FLOP/s;
  P_energy = fraction of valid channels with α > α_th (active channels);
  P_jitter = mean |α(k) − α(k−1)| over valid channels.
Team reward = mean over UAVs. Energy [J] = t_calc × processor watts.

This module holds the weights and the terms (no numba: ``swarmloc --help`` reads the weights);
``reward_kernel.standard_reward`` computes them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import BaseModel, ConfigDict, Field


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


def team_reward(terms: RewardTerms) -> np.ndarray:
    """``(B,)`` team reward: the mean over UAVs of the per-UAV reward."""
    return terms.reward.sum(axis=1) / terms.reward.shape[1]
