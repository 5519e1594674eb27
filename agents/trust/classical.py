"""Classical link-trust baselines (Track A) and the privileged oracle.

Every policy maps the pending update's raw fields to a trust α ∈ [0, 1] per channel; the
environment's CEKF turns it into ``R = R0 / max(α, α_min)`` and skips channels with
``α ≤ α_th`` (0.05). The degrees of freedom of a channel's normalised innovation squared
(NIS) are its scalar rows: 1 for anchor/peer ranges, 3 for landmark, GPS and relative
position channels. On v1 tasks a peer channel's NIS includes the neighbour's broadcast
covariance (``TaskSpec.peer_nis_neighbour_cov``, docs/world.md), so every rule below that reads
the NIS gates peers against the corrected statistic there. Sequential detection and integrity
monitoring (``cusum``, ``raim``) are in ``integrity.py`` (docs/methods.md).

| name | rule | source |
|---|---|---|
| ``uniform`` | α = 1 | standard CEKF |
| ``fixed`` | α = 0.6 | madrl Exp. 3, "fixed trust weight" |
| ``huber`` | α = 1 if u ≤ k else k/u, u = √NIS, k = 1.345 | Huber M-estimator weight |
| ``chi2-gate`` | α = α_min if NIS > χ²₀.₉₅(dof) else 1 | hard χ² gate |
| ``chi2-soft`` | α = 1 if λ < χ²₀.₉₅(dof) else exp(−(λ − χ²)/(2σ²)) | dtvirm §3.7 |
| ``federated-coef`` | α = R0 / R_k from the allocation coefficient | federated eq. 17–21 |
| ``non-cooperative`` | α = 0 on peer channels (skipped), 1 on the absolute ones | each UAV alone |
| ``random`` | α ~ U(0, 1), seeded per episode | the floor |
| ``oracle`` | α = α_min on channels with an error label, else 1 | privileged ceiling of the score |
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
from numba import njit
from scipy.stats import chi2

from swarmloc.envs.tasks.channels import KIND_DIM, PEER, PEER_REL, ChannelLayout
from swarmloc.envs.world.labels import LABEL_SIGMAS, label_thresholds
from swarmloc.envs.tasks.rng import Stream, uniform

from swarmloc.agents.protocols import PrivilegedInfo, TrustInput
from swarmloc.agents.trust.search_space import Param

#: trust floor of the CEKF (``FilterSettings.alpha_min`` default): R inflated 100×
ALPHA_MIN = 0.01


def _check_probability(name: str, value: float, low_open: bool = False) -> float:
    lo_ok = value > 0.0 if low_open else value >= 0.0
    if not (lo_ok and value <= 1.0):
        interval = "(0, 1]" if low_open else "[0, 1]"
        raise ValueError(f"{name} must be in {interval}, got {value!r}")
    return float(value)


class _TrustPolicy:
    """Shared plumbing: layout bookkeeping, per-channel χ² degrees of freedom."""

    privileged: bool = False
    deterministic: bool = True
    flops_per_channel: float = 0.0

    def __init__(self) -> None:
        self._dof: np.ndarray = np.ones((1, 1))
        self._shape: tuple[int, int, int] = (0, 0, 0)

    def reset(self, batch_size: int, layout: ChannelLayout, keys: np.ndarray) -> None:
        """Start B episodes: remember the shape and each channel's degrees of freedom.

        Args:
            batch_size: B.
            layout: the task's channel layout.
            keys: ``(B,)`` per-episode random keys (unused by deterministic rules).
        """
        if batch_size < 1:
            raise ValueError(f"batch_size must be >= 1, got {batch_size}")
        self._dof = KIND_DIM[layout.kind].astype(np.float64)  # (N, L)
        self._shape = (batch_size, *layout.kind.shape)

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"


class UniformTrust(_TrustPolicy):
    """α = 1 on every channel: the standard CEKF (the score's reference: gain 0)."""

    def act(self, inp: TrustInput) -> np.ndarray:
        """Full trust. Returns ``(B, N, L)`` ones."""
        return np.ones(inp.nis.shape)


class FixedTrust(_TrustPolicy):
    """A constant trust on every channel (madrl Exp. 3 uses α = 0.6).

    Args:
        alpha: the constant trust, in [0, 1].
    """

    def __init__(self, alpha: float = 0.6) -> None:
        super().__init__()
        self.alpha = _check_probability("alpha", alpha)

    def act(self, inp: TrustInput) -> np.ndarray:
        """Constant trust. Returns ``(B, N, L)``."""
        return np.full(inp.nis.shape, self.alpha)


class HuberTrust(_TrustPolicy):
    """Huber M-estimator weight of the normalised innovation u = √NIS.

    w(u) = 1 for u ≤ k, k/u beyond: the IRLS weight of the Huber loss, so the update
    behaves like least squares for small residuals and like least absolute deviations
    for large ones. k = 1.345 gives 95 % efficiency under Gaussian noise.

    Args:
        k: Huber threshold in units of the innovation std, > 0.
    """

    flops_per_channel = 4.0  # sqrt, compare, divide, select
    #: what ``swarmloc tune huber`` searches (docs/tuning.md)
    SEARCH_SPACE: ClassVar[tuple[Param, ...]] = (Param("k", 0.5, 4.0, "log"),)

    def __init__(self, k: float = 1.345) -> None:
        super().__init__()
        if not k > 0.0:
            raise ValueError(f"k must be > 0, got {k!r}")
        self.k = float(k)

    def act(self, inp: TrustInput) -> np.ndarray:
        """Huber weights. Returns ``(B, N, L)``."""
        u = np.sqrt(inp.nis)
        # w = k / max(u, k): 1 inside the threshold, k/u beyond
        return self.k / np.maximum(u, self.k)


class Chi2GateTrust(_TrustPolicy):
    """Hard χ² gate: reject (α = α_min) when NIS exceeds the χ² quantile of its dof.

    Args:
        confidence: gate quantile in (0, 1); 0.95 gives 3.84 (1 dof) and 7.81 (3 dof).
        alpha_reject: trust of a gated channel, in (0, 1].
    """

    flops_per_channel = 2.0  # compare, select
    #: what ``swarmloc tune chi2-gate`` searches (docs/tuning.md)
    SEARCH_SPACE: ClassVar[tuple[Param, ...]] = (Param("confidence", 0.8, 0.9999, "log-tail"),
                                                 Param("alpha_reject", 0.01, 0.5, "log"))

    def __init__(self, confidence: float = 0.95, alpha_reject: float = ALPHA_MIN) -> None:
        super().__init__()
        if not 0.0 < confidence < 1.0:
            raise ValueError(f"confidence must be in (0, 1), got {confidence!r}")
        self.confidence = float(confidence)
        self.alpha_reject = _check_probability("alpha_reject", alpha_reject, low_open=True)
        self._threshold = np.ones((1, 1))

    def reset(self, batch_size: int, layout: ChannelLayout, keys: np.ndarray) -> None:
        """Start B episodes; precompute the per-channel gate χ²_conf(dof)."""
        super().reset(batch_size, layout, keys)
        self._threshold = chi2.ppf(self.confidence, self._dof)

    def act(self, inp: TrustInput) -> np.ndarray:
        """Gate. Returns ``(B, N, L)``: α_reject beyond the gate, else 1."""
        return np.where(inp.nis > self._threshold, self.alpha_reject, 1.0)


class Chi2SoftTrust(Chi2GateTrust):
    """dtvirm §3.7 adaptive adjustment: exponential down-weighting beyond the χ² gate.

    w = 1 when λ < χ²_thresh, else w = exp(−(λ − χ²_thresh) / (2σ²)), λ the NIS. The
    paper calls σ "the UWB noise parameter"; λ is dimensionless, so σ acts as a
    dimensionless softness here (σ = 1: the weight halves 1.39 NIS units past the gate),
    the same reading as ``swarmloc.agents.estimators.fusion.chi2_soft_weight``.

    Args:
        confidence: gate quantile in (0, 1) (dtvirm: 95 %).
        softness: σ > 0.
    """

    flops_per_channel = 5.0  # compare, subtract, scale, exp, select
    #: what ``swarmloc tune chi2-soft`` searches (docs/tuning.md)
    SEARCH_SPACE: ClassVar[tuple[Param, ...]] = (Param("confidence", 0.8, 0.9999, "log-tail"),
                                                 Param("softness", 0.25, 8.0, "log"))

    def __init__(self, confidence: float = 0.95, softness: float = 1.0) -> None:
        super().__init__(confidence=confidence)
        if not softness > 0.0:
            raise ValueError(f"softness must be > 0, got {softness!r}")
        self.softness = float(softness)

    def act(self, inp: TrustInput) -> np.ndarray:
        """Soft χ² weights. Returns ``(B, N, L)``."""
        excess = np.maximum(inp.nis - self._threshold, 0.0)
        # w = exp(−(λ − χ²_thresh) / (2σ²)) beyond the gate, 1 inside
        return np.exp(-excess / (2.0 * self.softness**2))


class FederatedCoefTrust(_TrustPolicy):
    """The adaptive information-allocation coefficient (federated eq. 17–21) as trust.

    Each UAV's present channels play the sub-filters. Per channel the observation
    forecast residual statistic ΔV = rᵀr / tr(H P⁻ Hᵀ + R) (eq. 19) is taken as NIS/dof
    (exact for range channels; for 3-vector channels exact when S is isotropic). Then
    β = 1 if |ΔV| ≤ d else d/|ΔV| (eq. 17), normalised over the UAV's n present channels
    β_t = β / Σβ (eq. 20), and the adapted noise R_k = R + n(1/n − β_t) R (eq. 21, the
    paper's n = 2 rule for n sub-filters) is expressed as trust α = R / R_k =
    1 / (2 − n β_t), clipped to [α_min, 1] (a channel whose share grew beyond the equal
    share keeps full trust). A lone channel keeps α = 1; a channel with a vanishing
    share gets at most a 2× inflation (α → 1/2), as in the paper.

    Args:
        d: the residual gate d > 0 (the paper's 0.85).
    """

    flops_per_channel = 8.0  # ΔV, gate, divide, share sum, normalise, 2 − nβ, invert, clip

    def __init__(self, d: float = 0.85) -> None:
        super().__init__()
        if not d > 0.0:
            raise ValueError(f"d must be > 0, got {d!r}")
        self.d = float(d)

    def act(self, inp: TrustInput) -> np.ndarray:
        """Allocation-coefficient trust. Returns ``(B, N, L)``."""
        valid = inp.valid
        delta_v = np.abs(inp.nis) / self._dof
        # β = 1 if |ΔV| ≤ d else d / |ΔV|   (eq. 17)
        beta = np.where(valid, self.d / np.maximum(delta_v, self.d), 0.0)
        n = valid.sum(axis=-1, keepdims=True)
        total = beta.sum(axis=-1, keepdims=True)
        # β_t = β / Σ β   (eq. 20); n β_t is the share relative to the equal share 1/n
        share = np.divide(n * beta, total, out=np.ones_like(beta), where=total > 0.0)
        # R_k = (2 − n β_t) R   (eq. 21)  ⇒  α = 1 / (2 − n β_t)
        scale = 2.0 - share
        alpha = np.divide(1.0, scale, out=np.ones_like(beta), where=scale > 1.0)
        return np.where(valid, np.clip(alpha, ALPHA_MIN, 1.0), 1.0)


@njit(cache=True)
def _random_trust(keys: np.ndarray, step: int, out: np.ndarray) -> None:
    n_b, n, n_l = out.shape
    for b in range(n_b):
        for i in range(n):
            for l in range(n_l):
                out[b, i, l] = uniform(keys[b], step, Stream.POLICY, i * n_l + l)


class NonCooperativeTrust(_TrustPolicy):
    """Each UAV on its own: the peer channels skipped, the absolute ones trusted.

    α = 0 on every peer range and relative position (below α_th, so the CEKF skips the
    channel) and α = 1 on anchors, TDOA, landmarks and GPS: non-cooperative localization,
    the baseline every cooperative method is measured against. It detects nothing; where it
    matches the oracle, a task rewards distrusting a channel *kind*, not finding the faulty
    links (docs/methods.md, "A shortcut baseline").
    """

    def reset(self, batch_size: int, layout: ChannelLayout, keys: np.ndarray) -> None:
        """Start B episodes; mark the peer channels of the layout."""
        super().reset(batch_size, layout, keys)
        self._absolute = ~np.isin(layout.kind, (PEER, PEER_REL))  # (N, L)

    def act(self, inp: TrustInput) -> np.ndarray:
        """Returns ``(B, N, L)``: 1 on absolute channels, 0 on peer channels."""
        return np.broadcast_to(self._absolute, inp.nis.shape).astype(np.float64)


class RandomTrust(_TrustPolicy):
    """α ~ U(0, 1) independently per channel and step: the floor every method should beat.

    Draws come from the counter-based generator keyed by (episode key, step, channel),
    so an episode gives the same trust alone or batched.
    """

    flops_per_channel = 10.0  # one counter-based hash and scaling

    def __init__(self) -> None:
        super().__init__()
        self._keys = np.zeros(1, dtype=np.int64)

    def reset(self, batch_size: int, layout: ChannelLayout, keys: np.ndarray) -> None:
        """Start B episodes with the given per-episode keys."""
        super().reset(batch_size, layout, keys)
        keys = np.asarray(keys, dtype=np.int64)
        if keys.shape != (batch_size,):
            raise ValueError(f"keys must have shape ({batch_size},), got {keys.shape}")
        self._keys = keys.copy()

    def act(self, inp: TrustInput) -> np.ndarray:
        """Uniform random trust. Returns ``(B, N, L)``."""
        out = np.empty(inp.nis.shape)
        _random_trust(self._keys, inp.step, out)
        return out


class OracleTrust(_TrustPolicy):
    """Privileged reference: α_min on channels whose error label is set (``swarmloc.envs.world.labels``).

    It is the ceiling of the trust policies (``oracle``). It reads the labels through
    ``observe_privileged``, which the runner calls before every ``act``; its results are
    shown apart and never ranked.

    Args:
        alpha_reject: trust of a labelled channel, in (0, 1] (default α_min = 0.01,
            below α_th, so the channel is skipped).
        label_sigmas, vector_radius: label at these thresholds instead of the shipped ones
            (``PrivilegedInfo.systematic_sigmas`` above
            ``envs.labels.label_thresholds(kind, label_sigmas, vector_radius)``; either may
            be None for the shipped value). The calibration of the thresholds uses them.
    """

    privileged = True

    def __init__(self, alpha_reject: float = ALPHA_MIN, label_sigmas: float | None = None,
                 vector_radius: float | None = None) -> None:
        super().__init__()
        self.alpha_reject = _check_probability("alpha_reject", alpha_reject, low_open=True)
        self.custom = label_sigmas is not None or vector_radius is not None
        self.label_sigmas, self.vector_radius = label_sigmas, vector_radius
        if self.custom:
            self._k = LABEL_SIGMAS if label_sigmas is None else label_sigmas
            label_thresholds(np.zeros((1, 1), dtype=np.int64), self._k, vector_radius)  # validate now
        self._threshold: np.ndarray | None = None
        self._labels: np.ndarray | None = None

    def reset(self, batch_size: int, layout: ChannelLayout, keys: np.ndarray) -> None:
        """Start B episodes; forget the labels."""
        super().reset(batch_size, layout, keys)
        if self.custom:
            self._threshold = label_thresholds(layout.kind, self._k, self.vector_radius)
        self._labels = None

    def observe_privileged(self, info: PrivilegedInfo) -> None:
        """Receive the pending measurements' error labels ``(B, N, L)`` (at its own thresholds if custom)."""
        if not self.custom:
            labels = info.error_labels
        else:
            sigmas = info.systematic_sigmas
            labels = None if sigmas is None else np.asarray(sigmas) > self._threshold
        if labels is None:
            need = "systematic_sigmas" if self.custom else "error_labels"
            raise ValueError(f"this oracle reads PrivilegedInfo.{need}, which was not provided")
        labels = np.asarray(labels, dtype=bool)
        if labels.shape != self._shape:
            raise ValueError(f"labels must have shape (B, N, L) = {self._shape}, got {labels.shape}")
        self._labels = labels.copy()

    def act(self, inp: TrustInput) -> np.ndarray:
        """Oracle trust. Returns ``(B, N, L)``.

        Raises:
            RuntimeError: if no labels were given for this step (not run as privileged).
        """
        if self._labels is None:
            raise RuntimeError("OracleTrust needs observe_privileged(labels) before every act(); "
                               "run it through the swarmloc runner, which passes labels to privileged methods")
        labels, self._labels = self._labels, None
        return np.where(labels, self.alpha_reject, 1.0)


# --------------------------------------------------------------------------- factories (registry)


def uniform_policy() -> UniformTrust:
    """Registry factory: ``uniform``."""
    return UniformTrust()


def fixed_policy() -> FixedTrust:
    """Registry factory: ``fixed`` (α = 0.6)."""
    return FixedTrust(0.6)


def huber_policy() -> HuberTrust:
    """Registry factory: ``huber`` (k = 1.345)."""
    return HuberTrust(1.345)


def chi2_gate_policy() -> Chi2GateTrust:
    """Registry factory: ``chi2-gate`` (95 %, α_min)."""
    return Chi2GateTrust(0.95, ALPHA_MIN)


def chi2_soft_policy() -> Chi2SoftTrust:
    """Registry factory: ``chi2-soft`` (95 %, σ = 1)."""
    return Chi2SoftTrust(0.95, 1.0)


def federated_coef_policy() -> FederatedCoefTrust:
    """Registry factory: ``federated-coef`` (d = 0.85)."""
    return FederatedCoefTrust(0.85)


def non_cooperative_policy() -> NonCooperativeTrust:
    """Registry factory: ``non-cooperative`` (peer channels skipped)."""
    return NonCooperativeTrust()


def random_policy() -> RandomTrust:
    """Registry factory: ``random``."""
    return RandomTrust()


def oracle_policy() -> OracleTrust:
    """Registry factory: ``oracle`` (privileged, error labels)."""
    return OracleTrust(ALPHA_MIN)
