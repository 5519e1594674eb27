"""Fault detection and exclusion as link trust (Track A): a CUSUM per channel and RAIM per UAV.

One-step gating (``chi2-gate``, ``chi2-soft``, ``huber``) judges each channel by its own
normalised innovation squared (NIS) at this step only. It misses a bias that stays just
under the gate, and it has no notion of *which* of a UAV's sources is wrong: when the UAV's
own prior has drifted, every channel fails the gate and the UAV is locked out for good. The
two methods here are the classical answers, each with a false-alarm rate stated up front:

| name | detects | decides | readmits |
|---|---|---|---|
| ``cusum`` | a persistent NIS increase on one channel, by accumulating evidence (Page's CUSUM [page]) | per channel, then checked per UAV | a second CUSUM on the healthy hypothesis |
| ``raim`` | an inconsistent UAV: Σ NIS over its channels against χ²(rows) [parkinson] | leave-one-out exclusion, repeated up to a minority [brown] | every step afresh |

**Shared rule: a fault is a minority of the UAV's independent sources.** An innovation
compares a channel with the UAV's prior, so it cannot tell which of the two is wrong; only a
count of independent witnesses can. The witnesses of a UAV's position are its present
*absolute* channels (anchor, TDOA, landmark, GPS: each an independent fix against the world),
its own prior, and its *peer group* (peer ranges and relative positions) counted as **one**
witness: the neighbours' broadcast estimates share the swarm's common error, so however many
peers agree with the prior they only say that the UAV sits where the swarm thinks it is. A
set of excluded (distrusted) channels, k_a absolute of m_a and k_p peer of m_p, claims
k_a + [the peer group is excluded] faulty witnesses, the peer group being excluded when
most of its channels are (2 k_p > m_p); the other explanation, a faulty prior, claims the
prior plus every witness that agrees with it, 1 + (m_a − k_a) + [the peer group is kept].
The set is *admissible* when it is empty, or it claims strictly fewer faults and the kept
channels still carry at least ``MIN_ROWS`` = 3 scalar rows, enough for a 3-D position fix
(ranges have 1 row; landmark, GPS and relative-position channels 3), so that the UAV stays
observable while the excluded channels are out (``admissible``). When a UAV's inconsistency
cannot be explained by an admissible set, the faulty source is the UAV's own prior (a drifted
or dead-reckoned estimate): every present channel gets α = 1 for the step, so the filter
re-acquires instead of locking the UAV out (ties go to the prior for the same reason). The NIS these
methods read is the observation's (``TrustInput.nis``): on v1 tasks a peer channel's
includes the neighbour's broadcast covariance (docs/world.md).

Trust is binary: α = 1 for a kept channel, α_reject = α_min (0.01, below α_th, so the CEKF
skips it) for an excluded one; absent channels get 1 (they carry nothing).
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np
from numba import njit
from scipy.stats import chi2

from swarmloc.envs.tasks.channels import KIND_DIM, PEER, PEER_REL, ChannelLayout

from swarmloc.agents.trust.classical import ALPHA_MIN, _check_probability
from swarmloc.agents.protocols import TrustInput
from swarmloc.agents.trust.search_space import Param

#: scalar rows the kept channels of a UAV must carry after an exclusion (a 3-D position fix)
MIN_ROWS = 3


@njit(cache=True, inline="always")
def admissible_counts(m_abs: int, k_abs: int, m_peer: int, k_peer: int, kept_rows: int) -> bool:
    """Whether excluding k_abs of m_abs absolute and k_peer of m_peer peer channels is admissible.

    The shared rule of the module docstring: the exclusion claims k_abs + [2 k_peer > m_peer]
    faulty witnesses, a faulty prior 1 + (m_abs − k_abs) + [peer group kept]; admissible when
    nothing is excluded, or the exclusion claims strictly fewer and the kept channels carry
    ``kept_rows`` ≥ ``MIN_ROWS`` scalar rows.
    """
    if k_abs + k_peer == 0:
        return True
    peer_out = m_peer > 0 and 2 * k_peer > m_peer
    peer_in = m_peer > 0 and not peer_out
    return k_abs + int(peer_out) < 1 + (m_abs - k_abs) + int(peer_in) and kept_rows >= MIN_ROWS


@njit(cache=True)
def _admissible_sets(excluded: np.ndarray, valid: np.ndarray, dof: np.ndarray, is_peer: np.ndarray,
                     out: np.ndarray) -> None:
    n_b, n, n_l = excluded.shape
    for b in range(n_b):
        for i in range(n):
            m_a, k_a, m_p, k_p, kept_rows = 0, 0, 0, 0, 0
            for l in range(n_l):
                if valid[b, i, l]:
                    out_l = excluded[b, i, l]
                    if is_peer[i, l]:
                        m_p += 1
                        k_p += int(out_l)
                    else:
                        m_a += 1
                        k_a += int(out_l)
                    if not out_l:
                        kept_rows += dof[i, l]
            out[b, i] = admissible_counts(m_a, k_a, m_p, k_p, kept_rows)


def admissible(excluded: np.ndarray, valid: np.ndarray, dof: np.ndarray, is_peer: np.ndarray) -> np.ndarray:
    """Whether each UAV's excluded set is admissible (module docstring, ``admissible_counts``).

    Args:
        excluded: ``(B, N, L)`` bool, the channels to distrust (only present ones count).
        valid: ``(B, N, L)`` bool, present channels.
        dof: ``(N, L)`` int, scalar rows per channel.
        is_peer: ``(N, L)`` bool, peer channels (peer range or relative position).

    Returns:
        ``(B, N)`` bool.
    """
    excluded = np.ascontiguousarray(excluded, dtype=np.bool_)
    out = np.zeros(excluded.shape[:2], dtype=np.bool_)
    _admissible_sets(excluded, np.ascontiguousarray(valid, dtype=np.bool_), np.ascontiguousarray(dof, dtype=np.int64),
                     np.ascontiguousarray(is_peer, dtype=np.bool_), out)
    return out


class _FdeTrust:
    """Shared plumbing of the two detectors: shape, rows per channel, the rejected trust."""

    privileged: bool = False
    deterministic: bool = True
    flops_per_channel: float = 0.0

    def __init__(self, alpha_reject: float) -> None:
        self.alpha_reject = _check_probability("alpha_reject", alpha_reject, low_open=True)
        self._dof = np.ones((1, 1), dtype=np.int64)
        self._is_peer = np.zeros((1, 1), dtype=np.bool_)
        self._shape: tuple[int, int, int] = (0, 0, 0)

    def reset(self, batch_size: int, layout: ChannelLayout, keys: np.ndarray) -> None:
        """Start B episodes: remember the shape, each channel's scalar rows and which are peers.

        Args:
            batch_size: B.
            layout: the task's channel layout.
            keys: ``(B,)`` per-episode random keys (unused: both rules are deterministic).
        """
        if batch_size < 1:
            raise ValueError(f"batch_size must be >= 1, got {batch_size}")
        self._dof = np.ascontiguousarray(KIND_DIM[layout.kind], dtype=np.int64)  # (N, L)
        self._is_peer = np.ascontiguousarray((layout.kind == PEER) | (layout.kind == PEER_REL))
        self._shape = (batch_size, *layout.kind.shape)

    def _check(self, inp: TrustInput) -> None:
        if inp.nis.shape != self._shape:
            raise ValueError(f"TrustInput.nis has shape {inp.nis.shape}; reset() was for (B, N, L) = {self._shape}")


# --------------------------------------------------------------------------- CUSUM


class CusumTrust(_FdeTrust):
    """Page's one-sided CUSUM [page] on each channel's NIS, with readmission by a reverse CUSUM.

    Design (the χ² CUSUM of a variance increase [basseville]). A channel with d scalar
    rows has NIS x ~ χ²(d) when healthy (H0); a persistent bias b (or any excess error)
    raises its mean. The CUSUM is tuned to H1: the innovation's variance multiplied by λ
    (E x = λd; for a range, a bias of √(λ − 1) innovation std). The log-likelihood ratio of
    one step is s = ½[(1 − 1/λ) x − d ln λ]; in NIS units the statistics are

        g⁺(k) = max(0, g⁺(k−1) + x(k) − κ d)      (trusted: evidence of a fault)
        g⁻(k) = max(0, g⁻(k−1) + κ d − x(k))      (distrusted: evidence of health)
        κ = λ ln λ / (λ − 1),   h = 2 ln(ARL₀) λ / (λ − 1)

    A trusted channel whose g⁺ exceeds h is distrusted (g⁻ starts at 0); a distrusted one
    whose g⁻ exceeds h is readmitted (g⁺ restarts at 0). h is the LLR threshold ln ARL₀ in NIS
    units: by Lorden's bound [lorden] the mean time between false alarms on a healthy
    channel is at least ARL₀ steps, and by symmetry a channel still at λ is falsely readmitted
    no more often. With the defaults (λ = 4, ARL₀ = 10⁴ steps, 1000 s at 10 Hz): κ = 1.848,
    h = 24.56; Wald's approximation of the detection delay is h / (E x − κd) steps: 11 steps
    at the design point on a range, 1 step for a 5σ bias; readmission after a fault ends
    takes about h / ((κ − 1) d) = 29 steps on a range (2.9 s), 10 on a 3-row channel. A
    measurement that is absent leaves both statistics as they are.

    The per-channel alarms are then checked per UAV (module docstring): an alarmed set that is
    not admissible is the UAV's prior failing, not its channels, so the evidence is the
    prior's: the UAV's statistics restart (g⁺ = g⁻ = 0, no alarm) and every present channel
    is trusted (re-acquisition).

    Args:
        design_ratio: λ > 1, the NIS mean ratio the test is tuned to detect.
        arl: ARL₀ > 1, the mean steps between false alarms on a healthy channel.
        alpha_reject: trust of a distrusted channel, in (0, 1] (default α_min: skipped).
    """

    flops_per_channel = 6.0  # subtract, add, max, compare, select, per-UAV count
    #: what ``swarmloc tune cusum`` searches (docs/tuning.md)
    SEARCH_SPACE: ClassVar[tuple[Param, ...]] = (Param("design_ratio", 1.5, 16.0, "log"),
                                                 Param("arl", 10.0, 1e6, "log"),
                                                 Param("alpha_reject", 0.01, 0.5, "log"))

    def __init__(self, design_ratio: float = 4.0, arl: float = 1e4, alpha_reject: float = ALPHA_MIN) -> None:
        super().__init__(alpha_reject)
        if not design_ratio > 1.0:
            raise ValueError(f"design_ratio must be > 1, got {design_ratio!r}")
        if not arl > 1.0:
            raise ValueError(f"arl must be > 1 (steps), got {arl!r}")
        self.design_ratio, self.arl = float(design_ratio), float(arl)
        self._g_up = np.zeros((0, 0, 0))
        self._g_down = np.zeros((0, 0, 0))
        self._alarm = np.zeros((0, 0, 0), dtype=bool)

    @property
    def drift(self) -> float:
        """κ = λ ln λ / (λ − 1): the reference value per scalar row (κ d is subtracted from the NIS)."""
        lam = self.design_ratio
        return lam * math.log(lam) / (lam - 1.0)

    @property
    def threshold(self) -> float:
        """h = 2 ln(ARL₀) λ / (λ − 1): the LLR threshold ln ARL₀ in NIS units."""
        lam = self.design_ratio
        return 2.0 * math.log(self.arl) * lam / (lam - 1.0)

    def reset(self, batch_size: int, layout: ChannelLayout, keys: np.ndarray) -> None:
        """Start B episodes: every channel trusted, both statistics at 0."""
        super().reset(batch_size, layout, keys)
        self._g_up = np.zeros(self._shape)
        self._g_down = np.zeros(self._shape)
        self._alarm = np.zeros(self._shape, dtype=bool)

    def act(self, inp: TrustInput) -> np.ndarray:
        """Update the per-channel CUSUMs; distrust alarmed channels where admissible. Returns ``(B, N, L)``."""
        self._check(inp)
        valid = np.asarray(inp.valid, dtype=bool)
        g_up, g_down, alarm = cusum_step(self._g_up, self._g_down, self._alarm, inp.nis, valid,
                                         self.drift * self._dof, self.threshold)
        # an alarmed set no admissible exclusion explains is the prior's fault: the evidence is
        # the prior's, so the UAV's channel statistics restart and every channel is trusted
        prior_fault = ~admissible(alarm, valid, self._dof, self._is_peer)[..., None]
        self._g_up = np.where(prior_fault, 0.0, g_up)
        self._g_down = np.where(prior_fault, 0.0, g_down)
        self._alarm = alarm & ~prior_fault
        return np.where(self._alarm & valid, self.alpha_reject, 1.0)

    @property
    def alarm(self) -> np.ndarray:
        """``(B, N, L)`` bool, the channels whose CUSUM is in the alarmed (distrusted) state (a copy)."""
        return self._alarm.copy()

    def __repr__(self) -> str:
        return f"CusumTrust(design_ratio={self.design_ratio}, arl={self.arl})"


def cusum_step(g_up: np.ndarray, g_down: np.ndarray, alarm: np.ndarray, nis: np.ndarray, valid: np.ndarray,
               reference: np.ndarray | float, threshold: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One step of the two-state CUSUM of :class:`CusumTrust` (pure function).

    Args:
        g_up, g_down: the fault and the health statistics before the step, any shape.
        alarm: bool, same shape: the channel is in the alarmed state.
        nis: the step's NIS x, same shape.
        valid: bool, measurement present (absent channels keep their state).
        reference: κ d, broadcastable (the NIS subtracted per step).
        threshold: h.

    Returns:
        ``(g_up, g_down, alarm)`` after the step (new arrays).
    """
    # g⁺ = max(0, g⁺ + x − κd) while trusted;  g⁻ = max(0, g⁻ + κd − x) while alarmed
    up = np.where(valid & ~alarm, np.maximum(0.0, g_up + nis - reference), g_up)
    down = np.where(valid & alarm, np.maximum(0.0, g_down + reference - nis), g_down)
    raise_ = ~alarm & (up > threshold)
    clear = alarm & (down > threshold)
    new_alarm = (alarm | raise_) & ~clear
    # a new alarm starts the health statistic from 0; a readmission restarts the fault statistic
    down = np.where(raise_, 0.0, down)
    up = np.where(clear, 0.0, up)
    return up, down, new_alarm


# --------------------------------------------------------------------------- RAIM


class RaimTrust(_FdeTrust):
    """RAIM-style fault detection and exclusion per UAV and step [parkinson] [brown].

    Detection: the UAV's present channels are consistent when T = Σ_c NIS_c ≤ χ²_{1−P_fa}(r),
    r = Σ_c d_c their scalar rows (the sum of the squared normalised innovations is χ²(r)
    when the channels are healthy and independent; channels of one UAV share its prior, so
    their innovations are positively correlated and the false-alarm rate is above the stated
    P_fa when the prior's covariance dominates R). Exclusion, when inconsistent: leave one out,
    repeatedly — remove the channel whose removal restores consistency most (the smallest
    (T − NIS_c) / χ²_{1−P_fa}(r − d_c)) among those that keep the set admissible (module
    docstring: the excluded channels stay a minority of the UAV's independent witnesses), until
    the kept channels pass the test. If no admissible
    exclusion restores consistency, the inconsistency is the UAV's own prior: every present
    channel is trusted for the step (re-acquisition). Each step is decided afresh, so an
    excluded channel is readmitted as soon as it is consistent again (no hysteresis).

    P_fa = 10⁻³ per UAV and step (one false exclusion per 100 s of a UAV at 10 Hz, if the χ²
    model held; GNSS RAIM states its rate per independent sample in the same way). χ²₀.₉₉₉:
    10.83 (r = 1), 16.27 (3), 22.46 (6), 31.26 (11).

    Args:
        false_alarm: P_fa in (0, 1).
        alpha_reject: trust of an excluded channel, in (0, 1] (default α_min: skipped).
    """

    flops_per_channel = 8.0  # the sum and test (2) and, in a step that excludes, 3 per round (two rounds declared)
    #: what ``swarmloc tune raim`` searches (docs/tuning.md)
    SEARCH_SPACE: ClassVar[tuple[Param, ...]] = (Param("false_alarm", 1e-6, 0.1, "log"),
                                                 Param("alpha_reject", 0.01, 0.5, "log"))

    def __init__(self, false_alarm: float = 1e-3, alpha_reject: float = ALPHA_MIN) -> None:
        super().__init__(alpha_reject)
        if not 0.0 < false_alarm < 1.0:
            raise ValueError(f"false_alarm must be in (0, 1), got {false_alarm!r}")
        self.false_alarm = float(false_alarm)
        self._quantile = np.ones(1)

    def reset(self, batch_size: int, layout: ChannelLayout, keys: np.ndarray) -> None:
        """Start B episodes; tabulate χ²_{1−P_fa}(r) for r = 0 … the UAVs' most rows."""
        super().reset(batch_size, layout, keys)
        rows = np.arange(int(self._dof.sum(axis=-1).max()) + 1)
        # r = 0 has no test (an empty set is consistent): +inf
        self._quantile = np.concatenate([[np.inf], chi2.ppf(1.0 - self.false_alarm, rows[1:])])

    def act(self, inp: TrustInput) -> np.ndarray:
        """Per UAV: test, exclude by leave-one-out, or trust all. Returns ``(B, N, L)``."""
        self._check(inp)
        excluded = np.zeros(self._shape, dtype=np.bool_)
        raim_exclude(np.ascontiguousarray(inp.nis, dtype=np.float64), np.ascontiguousarray(inp.valid, dtype=np.bool_),
                     self._dof, self._is_peer, self._quantile, excluded)
        return np.where(excluded, self.alpha_reject, 1.0)

    def __repr__(self) -> str:
        return f"RaimTrust(false_alarm={self.false_alarm})"


@njit(cache=True)
def raim_exclude(nis: np.ndarray, valid: np.ndarray, dof: np.ndarray, is_peer: np.ndarray, quantile: np.ndarray,
                 excluded: np.ndarray) -> None:
    """Leave-one-out fault exclusion of :class:`RaimTrust` for every UAV (in place).

    Args:
        nis: ``(B, N, L)`` NIS; valid ``(B, N, L)`` bool.
        dof: ``(N, L)`` scalar rows; is_peer ``(N, L)`` bool, peer channels.
        quantile: ``(R + 1,)`` χ²_{1−P_fa}(r) for r = 0 … R (r = 0: +inf).
        excluded: ``(B, N, L)`` bool output (False in, True where excluded).
    """
    n_b, n, n_l = nis.shape
    for b in range(n_b):
        for i in range(n):
            # T = Σ NIS, r = Σ d over the present channels; m and k: present and excluded, absolute and peer
            t, r, m_a, m_p = 0.0, 0, 0, 0
            for l in range(n_l):
                if valid[b, i, l]:
                    t += nis[b, i, l]
                    r += dof[i, l]
                    if is_peer[i, l]:
                        m_p += 1
                    else:
                        m_a += 1
            if r == 0 or t <= quantile[r]:
                continue
            k_a, k_p = 0, 0
            restored = False
            while True:
                best, best_ratio = -1, np.inf
                for l in range(n_l):
                    if not valid[b, i, l] or excluded[b, i, l]:
                        continue
                    peer = is_peer[i, l]
                    if not admissible_counts(m_a, k_a + int(not peer), m_p, k_p + int(peer), r - dof[i, l]):
                        continue
                    # the kept set's statistic against its own quantile: ≤ 1 is consistent
                    ratio = (t - nis[b, i, l]) / quantile[r - dof[i, l]]
                    if ratio < best_ratio:
                        best, best_ratio = l, ratio
                if best < 0:
                    break
                excluded[b, i, best] = True
                t -= nis[b, i, best]
                r -= dof[i, best]
                if is_peer[i, best]:
                    k_p += 1
                else:
                    k_a += 1
                if best_ratio <= 1.0:
                    restored = True
                    break
            if not restored:
                # no admissible exclusion explains it: the prior is the faulty source, trust every channel
                for l in range(n_l):
                    excluded[b, i, l] = False


# --------------------------------------------------------------------------- factories (registry)


def cusum_policy() -> CusumTrust:
    """Registry factory: ``cusum`` (λ = 4, ARL₀ = 10⁴ steps, α_min)."""
    return CusumTrust(4.0, 1e4, ALPHA_MIN)


def raim_policy() -> RaimTrust:
    """Registry factory: ``raim`` (P_fa = 10⁻³ per UAV and step, α_min)."""
    return RaimTrust(1e-3, ALPHA_MIN)
