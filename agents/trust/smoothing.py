"""Adaptive Markov smoothing of a policy's trust (madrl §2.3.3, eq. 15–17).

A first-order low-pass filter between the policy and the CEKF whose memory shrinks when
the channel's innovation jumps, so steady-state decisions are smoothed but a sudden
fault is isolated within a step:

    Δr(k)    = |r(k) − r(k−1)|                       (eq. 16, r = innovation magnitude)
    β(k)     = β_max · exp(−γ Δr(k))                 (eq. 17)
    α_eff(k) = β(k) α_eff(k−1) + (1 − β(k)) α_raw(k) (eq. 15)

with β_max = 0.85 and γ = 2.0 [1/m] (the paper's values) and, as in madrl Algorithm 1,
α_eff(0) = 1 and r(0) = 0. The smoothed α_eff is what the CEKF applies. A channel whose
measurement is absent keeps its α_eff and r: an absent measurement carries no news.
Smoothing belongs to the method, not the environment (docs/architecture.md), so it wraps
any policy.
"""

from __future__ import annotations

import numpy as np

from swarmloc.envs.tasks.channels import ChannelLayout

from swarmloc.agents.protocols import LinkTrustPolicy, PrivilegedInfo, TrustInput

#: madrl §2.3.3 smoothing parameters: β_max and γ [1/m]
BETA_MAX, SMOOTHING_GAMMA = 0.85, 2.0
#: FLOPs of the smoother per channel: subtract, abs, scale, exp, two multiply-adds
SMOOTHING_FLOPS_PER_CHANNEL = 6.0


class MarkovSmoothing:
    """Wrap a link-trust policy with adaptive Markov smoothing (madrl eq. 15–17).

    Args:
        policy: any ``LinkTrustPolicy``.
        beta_max: maximum memory β_max, in [0, 1).
        gamma: sensitivity γ [1/m], ≥ 0.

    Attributes:
        privileged: that of the wrapped policy.
        flops_per_channel: the wrapped policy's plus the smoother's.
    """

    def __init__(self, policy: LinkTrustPolicy, beta_max: float = 0.85, gamma: float = 2.0) -> None:
        if not 0.0 <= beta_max < 1.0:
            raise ValueError(f"beta_max must be in [0, 1), got {beta_max!r}")
        if not gamma >= 0.0:
            raise ValueError(f"gamma must be >= 0, got {gamma!r}")
        if not callable(getattr(policy, "act", None)):
            raise TypeError(f"policy must be a LinkTrustPolicy (with act()), got {type(policy).__name__}")
        self.policy = policy
        self.beta_max = float(beta_max)
        self.gamma = float(gamma)
        self.privileged = bool(getattr(policy, "privileged", False))
        self.deterministic = bool(getattr(policy, "deterministic", True))
        self.flops_per_channel = float(getattr(policy, "flops_per_channel", 0.0)) + SMOOTHING_FLOPS_PER_CHANNEL
        self._alpha_eff = np.ones((0, 0, 0))
        self._resid = np.zeros((0, 0, 0))

    def reset(self, batch_size: int, layout: ChannelLayout, keys: np.ndarray) -> None:
        """Start B episodes: α_eff(0) = 1, r(0) = 0; resets the wrapped policy."""
        self.policy.reset(batch_size, layout, keys)
        shape = (batch_size, *layout.kind.shape)
        self._alpha_eff = np.ones(shape)
        self._resid = np.zeros(shape)

    def observe_privileged(self, info: PrivilegedInfo) -> None:
        """Forward privileged information to a privileged wrapped policy."""
        if not self.privileged:
            raise RuntimeError("observe_privileged called on a smoother around a non-privileged policy")
        self.policy.observe_privileged(info)  # type: ignore[attr-defined]

    def act(self, inp: TrustInput) -> np.ndarray:
        """Smoothed trust α_eff. Returns ``(B, N, L)``."""
        raw = np.asarray(self.policy.act(inp), dtype=np.float64)
        if raw.shape != self._alpha_eff.shape:
            raise ValueError(f"wrapped policy returned shape {raw.shape}; expected (B, N, L) = "
                             f"{self._alpha_eff.shape}")
        alpha_eff = smooth_step(self._alpha_eff, raw, self._resid, inp.resid, inp.valid, self.beta_max, self.gamma)
        self._alpha_eff = alpha_eff
        self._resid = np.where(inp.valid, inp.resid, self._resid)
        return alpha_eff.copy()

    def __repr__(self) -> str:
        return f"MarkovSmoothing({self.policy!r}, beta_max={self.beta_max}, gamma={self.gamma})"


def smooth_step(alpha_prev: np.ndarray, alpha_raw: np.ndarray, resid_prev: np.ndarray, resid: np.ndarray,
                valid: np.ndarray, beta_max: float, gamma: float) -> np.ndarray:
    """One step of adaptive Markov smoothing (pure function).

    Args:
        alpha_prev: α_eff(k−1), any shape.
        alpha_raw: α_raw(k), same shape.
        resid_prev, resid: r(k−1), r(k) innovation magnitudes [m].
        valid: measurement present (absent channels keep α_eff(k−1)).
        beta_max, gamma: β_max and γ.

    Returns:
        α_eff(k), same shape.
    """
    # Δr = |r(k) − r(k−1)|;  β = β_max exp(−γ Δr)
    beta = beta_max * np.exp(-gamma * np.abs(resid - resid_prev))
    # α_eff(k) = β α_eff(k−1) + (1 − β) α_raw(k)
    smoothed = beta * alpha_prev + (1.0 - beta) * np.clip(alpha_raw, 0.0, 1.0)
    return np.where(valid, smoothed, alpha_prev)
