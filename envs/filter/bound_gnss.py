"""The information bound where GNSS errors are correlated in time (``Sensors.gps_correlation_time`` > 0).

The world's GNSS fix of a receiver is z = p + σ e with e a first-order Gauss–Markov process per axis,
e⁺ = φ e + √(1 − φ²) w, φ = exp(−dt/τ), e₀ ~ N(0, I) (``sim_kernel``). A run of such fixes carries
far less position information than as many white ones: the fast path (``bound.pcrlb``), which takes
every fix as white, credits them with information they do not have and reads low. Here the recursion
of ``bound_reference`` (Tichavský, Muravchik and Nehorai 1998, dense, the same models and the same
expected information of every other channel) runs on the joint state augmented with each receiver's
error ε = σ e (3 states per UAV with a GNSS slot):

    ε⁺ = φ ε + w,  w ~ N(0, σ² (1 − φ²) I),  ε₀ ~ N(0, σ² I),   z = p + ε + v.

The fix has no white part in the world (v = 0); the bound gives it a white part of variance
``WHITE_SHARE`` · σ², which keeps the information finite and lowers the information by less than
that share (the bound is then above the exact one by at most that much, on the fixes' part). Dense
(two inverses of the augmented state per step): meant for the few tasks that have such receivers
(GradualFault-v2: 6 UAVs, 300 steps). Reference: the augmented state for coloured measurement noise
is the textbook treatment (Bryson and Henrikson 1968; Bar-Shalom, Li and Kirubarajan 2001, §8.3).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg

from swarmloc.envs.filter.bound import BoundInputs, Pcrlb, distinct_episodes
from swarmloc.envs.filter.bound_reference import (
    joint_model,
    measurement_information,
    position_variances,
    predicted_covariance,
)
from swarmloc.envs.tasks.channels import GPS

#: the white part the bound gives a correlated fix, as a share of its variance σ² (module docstring)
WHITE_SHARE = 1e-6


def pcrlb_correlated_gnss(inputs: BoundInputs) -> Pcrlb:
    """The bound of every UAV at every step with the GNSS errors as states (same contract as ``bound.pcrlb``).

    Args:
        inputs: ``BoundInputs`` with ``gps_tau`` > 0 (the receivers' correlation time [s]).

    Returns:
        ``Pcrlb``: pos_var ``(T, B, N)``, failed_at ``(B,)``.
    """
    w = inputs
    if not w.gps_tau > 0:
        raise ValueError(f"gps_tau={w.gps_tau}: the correlated-GNSS bound needs a correlation time > 0 "
                         "(bound.pcrlb takes white fixes)")
    n_t, n_b, n = w.pos.shape[:3]
    kind = np.asarray(w.kind)
    gps_slot = {i: int(np.flatnonzero(kind[i] == GPS)[0]) for i in range(n) if (kind[i] == GPS).any()}
    receivers = sorted(gps_slot)
    has_bias, has_fault = w.bias_sigma > 0, bool((np.asarray(w.fault_var) > 0).any())
    s = 6 + 3 * has_bias + 3 * has_fault
    d_swarm, d = s * n, s * n + 3 * len(receivers)
    phi = math.exp(-w.dt / w.gps_tau)
    var = np.array([w.r0[i, gps_slot[i]] for i in receivers])  # σ² per receiver (the slot's nominal variance)
    # the receivers' error block: ε⁺ = φ ε + w, and their part of J₀ = P₀⁻¹
    F_e = phi * np.eye(3 * len(receivers))
    Q_e = np.diag(np.repeat(var * (1.0 - phi * phi), 3))
    p0 = np.concatenate([w.p0_diag, [w.bias_sigma**2] * 3 * has_bias, [1.0] * 3 * has_fault])
    J0 = np.diag(np.concatenate([np.tile(1.0 / p0, n), np.repeat(1.0 / var, 3)]))
    pos_idx = np.concatenate([np.arange(s * i, s * i + 3) for i in range(n)])
    # a fix of receiver r: H = [I at p_i, I at ε_r], R = WHITE_SHARE · σ² I
    fix_info = []
    for r, i in enumerate(receivers):
        H = np.zeros((3, d))
        H[:, s * i:s * i + 3] = np.eye(3)
        H[:, d_swarm + 3 * r:d_swarm + 3 * r + 3] = np.eye(3)
        fix_info.append(H.T @ H / (WHITE_SHARE * var[r]))
    pos_var = np.full((n_t, n_b, n), np.nan)
    failed_at = np.full(n_b, -1, dtype=np.int64)
    first, which = distinct_episodes(w)
    use_other = np.asarray(w.use).copy()
    for i in receivers:
        use_other[..., i, gps_slot[i]] = False
    for b in first:
        J = J0.copy()
        fv = np.asarray(w.fault_var[:, b], dtype=float)
        for k in range(n_t):
            onset = np.where((fv[k] > 0) & ((fv[k - 1] != fv[k]) if k > 0 else True), fv[k], 0.0)
            F_s, Q_s = joint_model(n, w.dt, w.imu_sigma, has_bias, has_fault, fv[k] > 0, onset)
            F, Q = scipy.linalg.block_diag(F_s, F_e), scipy.linalg.block_diag(Q_s, Q_e)
            # C⁻ = Q + F J_{k−1}⁻¹ Fᵀ;  J_k = (C⁻)⁻¹ + Σ_c E[H_cᵀ R_c⁻¹ H_c]
            C_prior = predicted_covariance(J, F, Q)
            J = np.linalg.inv(C_prior)
            J[:d_swarm, :d_swarm] += measurement_information(
                w.pos[k, b], use_other[k, b], w.kind, w.target, w.r0, w.anchors, w.landmarks,
                C_prior[np.ix_(pos_idx, pos_idx)], s)
            for r, i in enumerate(receivers):
                if w.use[k, b, i, gps_slot[i]]:
                    J += fix_info[r]
            J = 0.5 * (J + J.T)
            var = position_variances(J, n, s)
            if var is None:
                failed_at[b] = k
                break
            pos_var[k, b] = var
    pos_var[:] = pos_var[:, first[which]]
    failed_at[:] = failed_at[first[which]]
    return Pcrlb(pos_var=pos_var, failed_at=failed_at)
