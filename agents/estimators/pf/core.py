"""Particle-filter kernels (numba): one particle set per UAV, batched over B envs × N UAVs.

State per particle x = [p, v] (world ENU). One filter step (pf-nn §2.2–2.4, Alg. 1–2):

1. **Predict** (constant acceleration from the IMU with process noise, pf-nn eq. 3–4):
   ``p ← p + v·dt + ½(u + w)·dt²``, ``v ← v + (u + w)·dt``, ``w ~ N(0, σ_a² I)``.
   Then every UAV broadcasts its predicted weighted mean (the peer likelihoods of its
   neighbours use it, like the CEKF's broadcast prior).
2. **Weight** in the log domain: ``log w ← log w + Σ_channels log p(z | x)`` (Gaussian,
   constants dropped since they cancel), optionally ``+ log(0.7 + 0.6·(y − 0.5))`` with
   ``y = NN(x − x̂_{k−1})`` (pf-nn eq. 12–15); normalise with log-sum-exp.
3. **Estimate** ``x̂ = Σ w x`` and ``ESS = 1 / Σ w²``.
4. **Adapt / resample.** The count follows pf-nn §2.4: ``M ← min(M + 100, M_max)`` if
   ESS < 0.3·M, ``max(M − 50, M_min)`` if ESS > 0.8·M. If ESS < 0.5·M the set is
   systematically resampled to the new count (Alg. 2 lines 1–7) and roughened with
   ``N(0, Σ_perturb)`` (lines 9–12), weights reset to 1/M. A shrink without resampling
   keeps the top-weight particles (Alg. 2 line 23) and renormalises.

Buffers are static: particles ``(B, N, M_max, 6)`` with the active count ``(B, N)``; slots
at and beyond the count are ignored. All randomness is ``envs.rng`` keyed by
(episode key, step, ``Stream.ESTIMATOR``, ``rng_index(uav, particle, slot)``), so an
episode gives identical numbers alone or batched. ``reference.py`` holds the
straightforward per-UAV numpy version of the same maths; tests hold the two equal.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from swarmloc.envs.tasks.channels import ANCHOR, GPS, LANDMARK, PEER
from swarmloc.envs.tasks.rng import Stream, uniform

# ---------------------------------------------------------------- random-number keys
#: particle index stride of the RNG index space (the largest supported particle buffer)
PARTICLE_STRIDE = 4096
#: random slots per (uav, particle, step)
N_SLOTS = 16
SLOT_PROCESS = 0  # 4 uniforms → 2 Box–Muller pairs → 3 acceleration-noise normals
SLOT_PERTURB = 4  # 6 uniforms → 3 pairs → 6 roughening normals
SLOT_RESAMPLE = 10  # 1 uniform: the systematic-resampling offset (particle 0)
SLOT_INIT = 0  # at step 0: 6 uniforms → 6 normals of the initial spread
SLOT_SELECT = 12  # oracle training: which particles are used (particle = sample index)
SLOT_NN_INIT = 13  # oracle's random initial network (particle = parameter index)

_ESTIMATOR = int(Stream.ESTIMATOR)
_TWO_PI = 2.0 * math.pi

# ---------------------------------------------------------------- FLOP accounting
#: one transcendental (exp, log, sqrt, tanh, cos, sin) counted as this many FLOPs
TRANSCENDENTAL_FLOPS = 20
_T = TRANSCENDENTAL_FLOPS
#: Box–Muller pair: log, sqrt, cos, sin + 4 multiplies
PAIR_FLOPS = 4 * _T + 4
#: prediction of one particle: 2 pairs, a = u + σn (2·3), p (5·3), v (2·3), weighted mean (exp + 6)
PREDICT_PARTICLE_FLOPS = 2 * PAIR_FLOPS + 6 + 15 + 6 + _T + 6
#: one range channel (anchor / peer) of one particle: Δ (3), ‖·‖ (5 + sqrt), residual² / σ² (4)
RANGE_CHANNEL_FLOPS = 12 + _T
#: one 3-vector channel (landmark / GPS / relative position), once per UAV-step: its share of
#: S and Σ c/σ² (1 + 3·3); the mean μ costs 3 more per UAV-step (counted here per channel)
VECTOR_CHANNEL_FLOPS = 13
#: the completed-square term −½ S ‖p − μ‖² of one particle (3 sub, 3 sq, 2 add, 2 mul)
VECTOR_PARTICLE_FLOPS = 10
#: normalisation of one particle: max, exp, sum, subtract, ESS (2), weighted mean (12)
NORMALIZE_PARTICLE_FLOPS = 4 + _T + 2 + 12
#: systematic resampling + roughening of one output particle: cumsum, u_j (2), compare (2), 3 pairs, 6 adds
RESAMPLE_PARTICLE_FLOPS = 5 + 3 * PAIR_FLOPS + 12


def nn_particle_flops(hidden: int) -> int:
    """FLOPs of the 6–H–1 weight-correction network on one particle.

    Features (6 subtractions), hidden layer (H·(12 + 1) + H tanh), output (2H + 1 +
    sigmoid: exp, add, divide), correction 0.7 + 0.6(y − 0.5) (3) and its log.
    """
    return 6 + hidden * 13 + hidden * _T + 2 * hidden + 1 + _T + 2 + 3 + _T


def rng_index(uav: int, particle: int, slot: int) -> int:
    """Index of a random draw of one particle of one UAV (see the module docstring)."""
    return (uav * PARTICLE_STRIDE + particle) * N_SLOTS + slot


@njit(cache=True, inline="always")
def _index(uav, particle, slot):
    return (uav * PARTICLE_STRIDE + particle) * N_SLOTS + slot


@njit(cache=True, inline="always")
def _normal_pair(key, step, index):
    """Two independent standard normals from uniforms ``index`` and ``index + 1`` (Box–Muller)."""
    u1 = uniform(key, step, _ESTIMATOR, index)
    u2 = uniform(key, step, _ESTIMATOR, index + 1)
    r = math.sqrt(-2.0 * math.log(u1))
    return r * math.cos(_TWO_PI * u2), r * math.sin(_TWO_PI * u2)


# ---------------------------------------------------------------- initialisation


@njit(cache=True, parallel=True)
def pf_init(keys, x0, pos_sigma, vel_sigma, n_init, particles, logw, count, est):
    """Draw the initial particle sets around the prior ``x0`` (in place).

    Args:
        keys: ``(B,)`` per-episode random keys.
        x0: ``(B, N, 6)`` initial prior means.
        pos_sigma, vel_sigma: std of the initial prior [m], [m/s].
        n_init: initial particle count per UAV.
        particles: ``(B, N, M_max, 6)`` output; logw ``(B, N, M_max)``; count ``(B, N)``;
            est ``(B, N, 6)`` (set to ``x0``).
    """
    n_b, n = x0.shape[0], x0.shape[1]
    log_w0 = -math.log(n_init)
    for bi in prange(n_b * n):
        b, i = bi // n, bi % n
        key = keys[b]
        for j in range(n_init):
            base = _index(i, j, SLOT_INIT)
            for pair in range(3):
                g0, g1 = _normal_pair(key, 0, base + 2 * pair)
                # pair 0 → (p_x, p_y), pair 1 → (p_z, v_x), pair 2 → (v_y, v_z)
                for h in range(2):
                    d = 2 * pair + h
                    g = g0 if h == 0 else g1
                    s = pos_sigma if d < 3 else vel_sigma
                    particles[b, i, j, d] = x0[b, i, d] + s * g
            logw[b, i, j] = log_w0
        count[b, i] = n_init
        for d in range(6):
            est[b, i, d] = x0[b, i, d]


# ---------------------------------------------------------------- resampling


@njit(cache=True)
def systematic_resample(weights, n_out, offset, out_index):
    """Systematic resampling (pf-nn Alg. 2 lines 1–7) by a merge-style pass.

    ``u_j = (j + U) / n_out``; particle j takes the smallest i with ``C_i ≥ u_j`` where
    ``C = cumsum(weights)``. The u_j are sorted, so one forward pass over C replaces
    ``searchsorted``; indices are clipped to the last particle (C's rounding may leave
    ``C_{M−1}`` a hair below 1).

    Args:
        weights: ``(M,)`` normalised weights.
        n_out: number of particles to draw.
        offset: U in (0, 1).
        out_index: ``(≥ n_out,)`` output ancestor indices.
    """
    m = weights.shape[0]
    i = 0
    c = weights[0]
    for j in range(n_out):
        u = (j + offset) / n_out
        while c < u and i < m - 1:
            i += 1
            c += weights[i]
        out_index[j] = i


@njit(cache=True, inline="always")
def next_count(ess, m, n_min, n_max, grow_below, shrink_above, grow_step, shrink_step):
    """Adaptive particle count (pf-nn §2.4): +grow below ``grow_below·M``, −shrink above ``shrink_above·M``."""
    if ess < grow_below * m:
        return min(m + grow_step, n_max)
    if ess > shrink_above * m:
        return max(m - shrink_step, n_min)
    return m


# ---------------------------------------------------------------- the network


@njit(cache=True, inline="always")
def fast_tanh(a):
    """tanh a = 1 − 2 / (e^{2a} + 1): one exp, ~6× faster than libm's tanh; saturates to ±1."""
    return 1.0 - 2.0 / (math.exp(2.0 * a) + 1.0)


@njit(cache=True, inline="always")
def nn_output(f0, f1, f2, f3, f4, f5, W1, b1, W2, b2):
    """y = σ(W2 · tanh(W1 f + b1) + b2) of the 6–H–1 network (pf-nn eq. 12–13)."""
    acc = b2
    for h in range(W1.shape[0]):
        a = (b1[h] + W1[h, 0] * f0 + W1[h, 1] * f1 + W1[h, 2] * f2
             + W1[h, 3] * f3 + W1[h, 4] * f4 + W1[h, 5] * f5)
        acc += W2[h] * fast_tanh(a)
    return 1.0 / (1.0 + math.exp(-acc))


# ---------------------------------------------------------------- the step
#
# Settings travel as one float vector ``prm`` (indices below) so the per-UAV functions
# and the two drivers (parallel over B·N, and serial for small batches, where a thread
# pool only adds synchronisation) share one signature.
P_ACCEL, P_PERTURB_POS, P_PERTURB_VEL, P_RESAMPLE, P_GROW, P_SHRINK = 0, 1, 2, 3, 4, 5
P_N_MIN, P_N_MAX, P_GROW_STEP, P_SHRINK_STEP, P_USE_NN, P_CORR_BASE, P_CORR_GAIN, P_DT = 6, 7, 8, 9, 10, 11, 12, 13
N_PRM = 14


def step_params(dt: float, accel_sigma: float, perturb_pos: float, perturb_vel: float, resample_below: float,
                grow_below: float, shrink_above: float, n_min: int, n_max: int, grow_step: int, shrink_step: int,
                use_nn: bool, corr_base: float, corr_gain: float) -> np.ndarray:
    """Pack the step settings into the ``prm`` vector the kernels take (see ``pf_step``)."""
    prm = np.empty(N_PRM)
    prm[P_DT], prm[P_ACCEL], prm[P_PERTURB_POS], prm[P_PERTURB_VEL] = dt, accel_sigma, perturb_pos, perturb_vel
    prm[P_RESAMPLE], prm[P_GROW], prm[P_SHRINK] = resample_below, grow_below, shrink_above
    prm[P_N_MIN], prm[P_N_MAX], prm[P_GROW_STEP], prm[P_SHRINK_STEP] = n_min, n_max, grow_step, shrink_step
    prm[P_USE_NN], prm[P_CORR_BASE], prm[P_CORR_GAIN] = float(use_nn), corr_base, corr_gain
    return prm


@njit(cache=True)
def predict_uav(b, i, key, step, prm, imu, particles, logw, count, prior_pos):
    """Propagate UAV i's particles (episode b) and write its predicted weighted mean position."""
    dt = prm[P_DT]
    sa = prm[P_ACCEL]
    h1 = 0.5 * dt * dt
    u0, u1, u2 = imu[b, i, 0], imu[b, i, 1], imu[b, i, 2]
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    for j in range(count[b, i]):
        base = _index(i, j, SLOT_PROCESS)
        g0, g1 = _normal_pair(key, step, base)
        g2, _unused = _normal_pair(key, step, base + 2)
        x = particles[b, i, j]
        # a = u + w, w ~ N(0, σ_a² I)
        a0, a1, a2 = u0 + sa * g0, u1 + sa * g1, u2 + sa * g2
        # p ← p + v·dt + ½·a·dt²;  v ← v + a·dt
        x[0] += x[3] * dt + h1 * a0
        x[1] += x[4] * dt + h1 * a1
        x[2] += x[5] * dt + h1 * a2
        x[3] += a0 * dt
        x[4] += a1 * dt
        x[5] += a2 * dt
        w = math.exp(logw[b, i, j])
        s0 += w * x[0]
        s1 += w * x[1]
        s2 += w * x[2]
    prior_pos[b, i, 0] = s0
    prior_pos[b, i, 1] = s1
    prior_pos[b, i, 2] = s2


@njit(cache=True)
def update_uav(b, i, key, step, prm, z, valid, kind, target, sigma, anchors, landmarks, W1, b1, W2, b2,
               particles, logw, count, est, prior_pos, scratch, wbuf, index, ess_out, used_out, resampled_out):
    """Weight, estimate, adapt and resample UAV i's particle set (episode b), in place."""
    n_l = z.shape[2]
    m = count[b, i]
    used_out[b, i] = m
    lw = logw[b, i]
    e0, e1, e2, e3, e4, e5 = est[b, i, 0], est[b, i, 1], est[b, i, 2], est[b, i, 3], est[b, i, 4], est[b, i, 5]
    # Range channels (anchor, peer) stay per particle. The 3-vector channels are all
    # ‖p + c_l‖² / σ_l² in p (landmark c = z − m, GPS c = −z, relative position
    # c = z − p̂_j), and Σ_l ‖p + c_l‖² / σ_l² = S ‖p − μ‖² + const with S = Σ 1/σ_l²,
    # μ = −Σ (c_l / σ_l²) / S: completing the square once per UAV turns them into one
    # O(1) term per particle (the constant cancels in the normalisation).
    ranges = np.empty((n_l, 5))  # q0, q1, q2, z, 1/σ²
    n_rng = 0
    s_vec = 0.0
    c0 = 0.0
    c1 = 0.0
    c2 = 0.0
    for l in range(n_l):
        if not valid[b, i, l]:
            continue
        ch = kind[i, l]
        t = target[i, l]
        inv_var = 1.0 / (sigma[i, l] * sigma[i, l])
        if ch == PEER or ch == ANCHOR:
            for d in range(3):
                ranges[n_rng, d] = prior_pos[b, t, d] if ch == PEER else anchors[t, d]
            ranges[n_rng, 3] = z[b, i, l, 0]
            ranges[n_rng, 4] = inv_var
            n_rng += 1
        else:
            s_vec += inv_var
            for d in range(3):
                if ch == LANDMARK:  # z = m − p + v
                    c = z[b, i, l, d] - landmarks[t, d]
                elif ch == GPS:  # z = p + v
                    c = -z[b, i, l, d]
                else:  # PEER_REL: z = p̂_j − p + v
                    c = z[b, i, l, d] - prior_pos[b, t, d]
                if d == 0:
                    c0 += c * inv_var
                elif d == 1:
                    c1 += c * inv_var
                else:
                    c2 += c * inv_var
    mu0, mu1, mu2 = 0.0, 0.0, 0.0
    if s_vec > 0.0:
        mu0, mu1, mu2 = -c0 / s_vec, -c1 / s_vec, -c2 / s_vec
    use_nn = prm[P_USE_NN] != 0.0
    cb, cg = prm[P_CORR_BASE], prm[P_CORR_GAIN]
    w1, bb1, w2, bb2 = W1[b, i], b1[b, i], W2[b, i], b2[b, i]
    top = -np.inf
    for j in range(m):
        x = particles[b, i, j]
        # log p(z | x) = −½ Σ_range (z − ‖p − q‖)²/σ² − ½ S ‖p − μ‖²  (+ const)
        d0, d1, d2 = x[0] - mu0, x[1] - mu1, x[2] - mu2
        ll = -0.5 * s_vec * (d0 * d0 + d1 * d1 + d2 * d2)
        for k in range(n_rng):
            d0, d1, d2 = x[0] - ranges[k, 0], x[1] - ranges[k, 1], x[2] - ranges[k, 2]
            r = ranges[k, 3] - math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            ll -= 0.5 * r * r * ranges[k, 4]
        if use_nn:
            y = nn_output(x[0] - e0, x[1] - e1, x[2] - e2, x[3] - e3, x[4] - e4, x[5] - e5, w1, bb1, w2, bb2)
            # w̃ = w · [0.7 + 0.6 (y − 0.5)]  (pf-nn eq. 14)
            ll += math.log(cb + cg * (y - 0.5))
        v = lw[j] + ll
        lw[j] = v
        if v > top:
            top = v
    # log-sum-exp normalisation: w_j = exp(log w_j − max) / Σ exp(log w − max)
    total = 0.0
    for j in range(m):
        e = math.exp(lw[j] - top)
        wbuf[b, i, j] = e
        total += e
    lse = top + math.log(total)
    inv_total = 1.0 / total
    sq = 0.0
    x0, x1, x2, x3, x4, x5 = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    for j in range(m):
        lw[j] -= lse
        w = wbuf[b, i, j] * inv_total
        wbuf[b, i, j] = w
        sq += w * w
        x = particles[b, i, j]
        # x̂ = Σ w x
        x0 += w * x[0]
        x1 += w * x[1]
        x2 += w * x[2]
        x3 += w * x[3]
        x4 += w * x[4]
        x5 += w * x[5]
    est[b, i, 0], est[b, i, 1], est[b, i, 2], est[b, i, 3], est[b, i, 4], est[b, i, 5] = x0, x1, x2, x3, x4, x5
    # ESS = 1 / Σ w²
    ess = 1.0 / sq
    ess_out[b, i] = ess
    m_new = next_count(ess, m, int(prm[P_N_MIN]), int(prm[P_N_MAX]), prm[P_GROW], prm[P_SHRINK],
                       int(prm[P_GROW_STEP]), int(prm[P_SHRINK_STEP]))
    if ess < prm[P_RESAMPLE] * m:
        resampled_out[b, i] = True
        anc = index[b, i]
        systematic_resample(wbuf[b, i, :m], m_new, uniform(key, step, _ESTIMATOR, _index(i, 0, SLOT_RESAMPLE)), anc)
        for j in range(m_new):
            for d in range(6):
                scratch[b, i, j, d] = particles[b, i, anc[j], d]
        # roughening: x ← x + N(0, Σ_perturb)  (pf-nn Alg. 2 lines 9–12); w = 1/M
        sp, sv = prm[P_PERTURB_POS], prm[P_PERTURB_VEL]
        log_w0 = -math.log(m_new)
        for j in range(m_new):
            base = _index(i, j, SLOT_PERTURB)
            g0, g1 = _normal_pair(key, step, base)
            g2, g3 = _normal_pair(key, step, base + 2)
            g4, g5 = _normal_pair(key, step, base + 4)
            x = particles[b, i, j]
            y = scratch[b, i, j]
            x[0], x[1], x[2] = y[0] + sp * g0, y[1] + sp * g1, y[2] + sp * g2
            x[3], x[4], x[5] = y[3] + sv * g3, y[4] + sv * g4, y[5] + sv * g5
            lw[j] = log_w0
    else:
        resampled_out[b, i] = False
        if m_new < m:
            # keep the m_new highest-weight particles (stable order) and renormalise
            order = np.argsort(-lw[:m], kind="mergesort")
            kept = 0.0
            for j in range(m_new):
                o = order[j]
                wbuf[b, i, j] = lw[o]
                kept += math.exp(lw[o])
                for d in range(6):
                    scratch[b, i, j, d] = particles[b, i, o, d]
            log_kept = math.log(kept)
            for j in range(m_new):
                lw[j] = wbuf[b, i, j] - log_kept
                for d in range(6):
                    particles[b, i, j, d] = scratch[b, i, j, d]
    count[b, i] = m_new


@njit(cache=True, parallel=True)
def pf_step(keys, step, prm, imu, z, valid, kind, target, sigma, anchors, landmarks, W1, b1, W2, b2,
            particles, logw, count, est, prior_pos, scratch, wbuf, index, ess_out, used_out, resampled_out):
    """One particle-filter step for every UAV of every episode (in place), parallel over B·N.

    Args:
        keys: ``(B,)`` per-episode random keys; step: filter step k (≥ 1).
        prm: settings vector from :func:`step_params` (dt, σ_a, Σ_perturb, ESS fractions
            0.5/0.3/0.8, count bounds and steps, network switch and correction range).
        imu: ``(B, N, 3)``; z: ``(B, N, L, 3)``; valid: ``(B, N, L)``.
        kind, target, sigma: ``(N, L)`` channel layout; anchors ``(A, 3)``, landmarks ``(M, 3)``.
        W1 ``(B, N, H, 6)``, b1 ``(B, N, H)``, W2 ``(B, N, H)``, b2 ``(B, N)``: per-UAV networks.
        particles ``(B, N, M_max, 6)``, logw ``(B, N, M_max)``, count ``(B, N)``, est ``(B, N, 6)``:
            the filter state, updated in place (est holds x̂_{k−1} on entry, x̂_k on exit).
        prior_pos ``(B, N, 3)``, scratch ``(B, N, M_max, 6)``, wbuf ``(B, N, M_max)``, index
            ``(B, N, M_max)`` int64: work buffers.
        ess_out ``(B, N)``: ESS after the update; used_out ``(B, N)``: particle count used this
            step; resampled_out ``(B, N)``: whether the set was resampled.
    """
    n_b, n = z.shape[0], z.shape[1]
    # 1. predict every UAV, then (barrier) broadcast the predicted means to the neighbours
    for bi in prange(n_b * n):
        predict_uav(bi // n, bi % n, keys[bi // n], step, prm, imu, particles, logw, count, prior_pos)
    # 2. weight, estimate, adapt and resample each UAV
    for bi in prange(n_b * n):
        update_uav(bi // n, bi % n, keys[bi // n], step, prm, z, valid, kind, target, sigma, anchors, landmarks,
                   W1, b1, W2, b2, particles, logw, count, est, prior_pos, scratch, wbuf, index, ess_out,
                   used_out, resampled_out)


@njit(cache=True)
def pf_step_serial(keys, step, prm, imu, z, valid, kind, target, sigma, anchors, landmarks, W1, b1, W2, b2,
                   particles, logw, count, est, prior_pos, scratch, wbuf, index, ess_out, used_out, resampled_out):
    """``pf_step`` on one thread (same arguments, identical results): for small batches."""
    n_b, n = z.shape[0], z.shape[1]
    for bi in range(n_b * n):
        predict_uav(bi // n, bi % n, keys[bi // n], step, prm, imu, particles, logw, count, prior_pos)
    for bi in range(n_b * n):
        update_uav(bi // n, bi % n, keys[bi // n], step, prm, z, valid, kind, target, sigma, anchors, landmarks,
                   W1, b1, W2, b2, particles, logw, count, est, prior_pos, scratch, wbuf, index, ess_out,
                   used_out, resampled_out)
