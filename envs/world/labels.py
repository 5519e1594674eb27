"""Error labels: the systematic error of a measurement as the filter uses it.

A channel-step is labelled faulty when its *systematic* error exceeds k·σ_eff
(``LABEL_SIGMAS`` = k = 1.5). Systematic is everything but the channel's nominal white noise:

* the measurement's own error (``SenseBuffers.systematic``, signed, written by the world):
  injected range bias (scheduled, uniform and Gauss–Markov NLOS), GPS drift and the
  heavy-tail excess of hybrid GPS noise (``specs.HybridNoise``: in the weighted sum its
  Student-t component a·σ_t·t_ν, the Gaussian component being the nominal white noise; in
  the mixture the whole of a Student-t draw, a Gaussian draw being the nominal noise, so a
  t draw is labelled when it lands outside the fix's 3σ-equivalent radius);
* for a peer channel, the neighbour's broadcast-estimate error as the filter uses it: a
  peer range is fused as z = ‖p_i − p̂_j‖ + v with the neighbour's prior p̂_j taken as a
  known point, so its error is e = b + ‖p_i − p_j‖ − ‖p_i − p̂_j‖ ≈ b + uᵀ(p̂_j − p_j)
  (u the unit vector from p̂_j to p_i), and a relative position z = p̂_j − p_i + v has
  e = b + p_j − p̂_j. A link to a drifted neighbour therefore stays labelled while the
  neighbour's estimate is off, not only while its IMU is faulty.

GNSS error correlated in time (``Sensors.gps_correlation_time``) is not systematic: it is the
fix's nominal noise, zero-mean with the stationary variance σ² the filter is told, only not
independent from one fix to the next; a fault is what the scenario injects on top of it (a
drift, a heavy tail). It stays out of ``systematic`` and of the labels, so a label still
marks a fault and not an unlucky stretch of noise.

σ_eff is the spread the filter should expect of e without a fault: σ for the own error,
σ_eff² = σ² + uᵀ P_j u for a peer range, and for 3-vector channels the Mahalanobis norm
with S = σ² I (GPS) or S = σ² I + P_j,pp (relative position), P_j the neighbour's prior
covariance. Landmarks are known points: they carry no systematic error.

``systematic_sigmas`` is ‖e‖ in units of σ_eff (scalar channels: |e| / σ_eff); the label is
``valid and systematic_sigmas > threshold`` with the threshold of the channel's dimension
(``label_thresholds``): k = ``LABEL_SIGMAS`` for a scalar range; for a 3-vector channel
(GPS, relative position) the Mahalanobis radius whose false-alarm probability for a
consistent error (χ² with 3 degrees of freedom) is that of a scalar at
``VECTOR_LABEL_SIGMAS`` σ (3σ: 0.27 %, radius 3.76).

Both are calibrated on the standard-v0 tasks (``swarmloc reproduce labels``,
docs/reproduce/labels.md) so that the oracle on these labels is a ceiling of the trust
policies and still an estimator: no shipped non-privileged method better on any task
(paired 95 % CI), CascadedFault's healthy nodes below mappo's, and the task-mean RMSE
above the information bound. Below k ≈ 1.3 the oracle cuts so many links by the truth of
the neighbours' errors that it beats the bound (VisionLoss, Ideal): it then picks
favourable noise rather than faults; above k ≈ 1.6 uniform down-weighting (VisionLoss),
the learned trust (NLOSStep, Ideal) or mappo (CascadedFault, k = 3) beat it. A
relative-position link to a healthy neighbour must almost never be cut (GradualFault's
followers have nothing else to lean on): the Mahalanobis radius 1.5 would cut 52 % of
them (χ²₃ > 2.25), hence the 3σ false-alarm radius for 3-vector channels.

The world writes the measurement's own part
(``SenseBuffers.error_label``, what a Track B estimator's privileged channel gets: its
estimates are its own); the link-trust core adds the neighbour part from the CEKF priors
it holds (``CoreStep.error_label`` and ``LinkTrustCore.pending_error_label``). Both are
privileged: metrics and ``observe_privileged`` only, never an observation.

They are not the world's injected-fault labels (``SenseBuffers.label``: a fault the scenario
injected, what the detection metrics count: ``anomaly_detection_rate`` judges every method against
the same set), which every task keeps as they were.

On the consistent backbone (``FilterSettings.peer_update = "split_ci"``, the v2 default) the same
definition labels what it should: σ_eff's uᵀP_j u is then a covariance the neighbour's error
respects. With the neighbour fused as a known point its covariance shrinks below its error, and
in a fault-free HybridNoise30-v1 world (heavy tail removed, uniform trust, 4 dev seeds) 41.7 % of
the valid peer channel-steps are labelled; under split CI 3.9 % (``tests/test_labels.py``).
``labels_reference`` holds the readable numpy version of the rule; tests hold the two equal.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from scipy.stats import chi2, norm

from swarmloc.envs.tasks.channels import ANCHOR, GPS, KIND_DIM, PEER, PEER_REL, TDOA

#: k: a scalar channel-step (anchor or peer range) is labelled when its systematic error
#: exceeds k·σ_eff (calibrated: docs/reproduce/labels.md)
LABEL_SIGMAS = 1.5
#: a 3-vector channel-step is labelled at the false-alarm probability of a scalar at this
#: many σ (calibrated: docs/reproduce/labels.md)
VECTOR_LABEL_SIGMAS = 3.0


def equivalent_radius(sigmas: float, dof: int) -> float:
    """The Mahalanobis radius r with P(χ²_dof > r²) = P(|N(0, 1)| > sigmas).

    Args:
        sigmas: the scalar threshold [σ], > 0.
        dof: the channel's dimension (1: r = sigmas).
    """
    if not sigmas > 0 or dof < 1:
        raise ValueError(f"need sigmas > 0 and dof >= 1, got {sigmas!r}, {dof!r}")
    return float(np.sqrt(chi2.isf(2.0 * norm.sf(sigmas), dof)))


def label_thresholds(kind: np.ndarray, label_sigmas: float = LABEL_SIGMAS,
                     vector_radius: float | None = None) -> np.ndarray:
    """Per channel, the ``systematic_sigmas`` above which a present channel-step is labelled.

    Args:
        kind: ``(N, L)`` channel kinds.
        label_sigmas: k of the scalar channels.
        vector_radius: Mahalanobis radius of the 3-vector channels (default:
            ``equivalent_radius(VECTOR_LABEL_SIGMAS, 3)``).

    Returns:
        ``(N, L)`` float64 (landmarks get the vector radius; they are never labelled).
    """
    if not label_sigmas > 0:
        raise ValueError(f"label_sigmas must be > 0, got {label_sigmas!r}")
    r = equivalent_radius(VECTOR_LABEL_SIGMAS, 3) if vector_radius is None else float(vector_radius)
    if not r > 0:
        raise ValueError(f"vector_radius must be > 0, got {vector_radius!r}")
    return np.ascontiguousarray(np.where(KIND_DIM[np.asarray(kind)] == 1, float(label_sigmas), r))

_MIN_RANGE = 1e-9


@njit(cache=True, inline="always")
def own_sigmas(ch: int, e0: float, e1: float, e2: float, sg: float) -> float:
    """The measurement's own systematic error in units of its nominal σ.

    Args:
        ch: channel kind; e0, e1, e2: its systematic error (ranges in e0) [m]; sg: σ [m].

    Returns:
        |e0| / σ for ranges, ‖e‖ / σ for GPS, 0 for landmarks and relative positions (their
        own error is nil; a relative position's error is its neighbour's, ``peer_rel_sigmas``).
    """
    if ch == ANCHOR or ch == PEER or ch == TDOA:
        return abs(e0) / sg
    if ch == GPS:
        return math.sqrt(e0 * e0 + e1 * e1 + e2 * e2) / sg
    return 0.0


@njit(cache=True, inline="always")
def peer_range_sigmas(pi, pj, qj, Pj, bias: float, sg: float) -> float:
    """A peer range's systematic error as fused at the neighbour's prior, in units of σ_eff.

    Args:
        pi, pj: ``(3,)`` true positions of the receiver i and the neighbour j [m].
        qj: ``(3,)`` the neighbour's broadcast prior position p̂_j [m].
        Pj: ``(6, 6)`` the neighbour's prior covariance (its position block is read).
        bias: the range's own systematic error [m]; sg: its nominal σ [m].

    Returns:
        |e| / σ_eff with e = b + ‖p_i − p_j‖ − ‖p_i − p̂_j‖ and σ_eff² = σ² + uᵀ P_j,pp u.
    """
    t0, t1, t2 = pi[0] - pj[0], pi[1] - pj[1], pi[2] - pj[2]
    d0, d1, d2 = pi[0] - qj[0], pi[1] - qj[1], pi[2] - qj[2]
    r_true = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    r_used = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    e = bias + r_true - r_used
    s2 = sg * sg
    if r_used > _MIN_RANGE:
        u0, u1, u2 = d0 / r_used, d1 / r_used, d2 / r_used
        # σ_eff² = σ² + uᵀ P_j,pp u
        s2 += (u0 * (Pj[0, 0] * u0 + Pj[0, 1] * u1 + Pj[0, 2] * u2)
               + u1 * (Pj[1, 0] * u0 + Pj[1, 1] * u1 + Pj[1, 2] * u2)
               + u2 * (Pj[2, 0] * u0 + Pj[2, 1] * u1 + Pj[2, 2] * u2))
    return abs(e) / math.sqrt(s2)


@njit(cache=True, inline="always")
def peer_rel_sigmas(pj, qj, Pj, sg: float) -> float:
    """A relative position's systematic error p_j − p̂_j in the Mahalanobis norm of S = σ² I + P_j,pp.

    Args:
        pj: ``(3,)`` the neighbour's true position; qj ``(3,)`` its broadcast prior [m].
        Pj: ``(6, 6)`` the neighbour's prior covariance; sg: the channel's σ per axis [m].

    Returns:
        sqrt(eᵀ S⁻¹ e) (Cholesky of the 3×3 S, which is SPD as σ > 0).
    """
    e0, e1, e2 = pj[0] - qj[0], pj[1] - qj[1], pj[2] - qj[2]
    s2 = sg * sg
    a00, a11, a22 = Pj[0, 0] + s2, Pj[1, 1] + s2, Pj[2, 2] + s2
    a10, a20, a21 = Pj[1, 0], Pj[2, 0], Pj[2, 1]
    # S = L Lᵀ; eᵀ S⁻¹ e = ‖L⁻¹ e‖²
    l00 = math.sqrt(a00)
    l10 = a10 / l00
    l20 = a20 / l00
    l11 = math.sqrt(a11 - l10 * l10)
    l21 = (a21 - l20 * l10) / l11
    l22 = math.sqrt(a22 - l20 * l20 - l21 * l21)
    w0 = e0 / l00
    w1 = (e1 - l10 * w0) / l11
    w2 = (e2 - l20 * w0 - l21 * w1) / l22
    return math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)


@njit(cache=True, inline="always")
def channel_sigmas(ch: int, j: int, sg: float, e0: float, e1: float, e2: float, pos_b, prior_b, P_b,
                   i: int) -> float:
    """One channel's systematic error in units of σ_eff (``own_sigmas`` or the peer forms).

    Args:
        ch, j, sg: the channel's kind, target and nominal σ.
        e0, e1, e2: its own systematic error (``SenseBuffers.systematic``; ranges in e0) [m].
        pos_b: ``(N, 3)`` true positions; prior_b ``(N, 3)`` broadcast priors; P_b ``(N, 6, 6)``
            prior covariances of the episode.
        i: the receiving UAV.
    """
    if ch == PEER:
        return peer_range_sigmas(pos_b[i], pos_b[j], prior_b[j], P_b[j], e0, sg)
    if ch == PEER_REL:
        return peer_rel_sigmas(pos_b[j], prior_b[j], P_b[j], sg)
    return own_sigmas(ch, e0, e1, e2, sg)
