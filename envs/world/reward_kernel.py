"""The standard reward's terms in one numba pass over the channels (the formulas: ``reward.py``).

``standard_reward`` scores B episodes' updates; the sums run in NumPy's order, so each term is the formula
evaluated as NumPy evaluates it, bit for bit (``tests/test_reward.py``), except that exp is the C library's.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from swarmloc.envs.world.cost import DEFAULT_PROFILE, ProcessorProfile
from swarmloc.envs.world.reward import STANDARD_WEIGHTS, RewardTerms, RewardWeights
from swarmloc.envs.world.sim_kernel import BLOCK, SERIAL_BELOW, block_bounds


def standard_reward(estimate: np.ndarray, truth: np.ndarray, applied: np.ndarray, previous: np.ndarray,
                    valid: np.ndarray, alpha_th: float, filter_flops: np.ndarray,
                    policy_flops: np.ndarray | float = 0.0, weights: RewardWeights = STANDARD_WEIGHTS,
                    profile: ProcessorProfile = DEFAULT_PROFILE, policy_flops_per_channel: float = 0.0) -> RewardTerms:
    """Standard reward v0 per UAV (``reward.py``), every term in one pass over the channels (``_reward_terms``).

    Args:
        estimate, truth: ``(B, N, 3)`` posterior and true positions.
        applied, previous: ``(B, N, L)`` trust applied now and at the previous step.
        valid: ``(B, N, L)`` measurement present.
        alpha_th: activity threshold α_th.
        filter_flops: ``(B, N)`` CEKF FLOPs of the step.
        policy_flops: FLOPs of the method's own computation per UAV (scalar or ``(B, N)``).
        weights: λ and constants (default: the standard).
        profile: processor profile converting FLOPs into seconds and joules.
        policy_flops_per_channel: the method's FLOPs per present channel, added to ``policy_flops``.

    Returns:
        ``RewardTerms`` with the reward and every term, ``(B, N)``.
    """
    n_b, n = estimate.shape[:2]
    policy = np.asarray(policy_flops, dtype=float)
    # one number for every UAV: a (1, 1) array the kernel reads for all (cheaper than a broadcast view at B = 1)
    policy = policy.reshape(1, 1) if policy.ndim == 0 else np.broadcast_to(policy, (n_b, n))
    out = _reward_terms(estimate, truth, applied, previous, valid, float(alpha_th),
                        np.asarray(filter_flops, dtype=float), policy, float(policy_flops_per_channel),
                        2.0 * weights.sigma_acc**2, weights.t_max, profile.effective_flops, profile.power_w,
                        weights.delay, weights.energy, weights.jitter)
    return RewardTerms(reward=out[0], accuracy=out[1], delay_penalty=out[2], energy_penalty=out[3],
                       jitter_penalty=out[4], flops=out[5], delay_ms=out[6], energy_j=out[7])


def _reward_terms(estimate, truth, applied, previous, valid, alpha_th, filter_flops, policy_flops, per_channel,
                  acc_scale, t_max, flops_per_s, watts, l_delay, l_energy, l_jitter) -> np.ndarray:
    """``standard_reward``'s terms ``(8, B, N)``: reward, accuracy, the three penalties, FLOPs, delay [ms],
    energy [J] (``_reward_rows``; threads over blocks of episodes from ``SERIAL_BELOW`` on)."""
    out = np.empty((8, *valid.shape[:2]))
    terms = _reward_serial if valid.shape[0] < SERIAL_BELOW else _reward_threaded
    terms(estimate, truth, applied, previous, valid, alpha_th, filter_flops, policy_flops, per_channel, acc_scale,
          t_max, flops_per_s, watts, l_delay, l_energy, l_jitter, out)
    return out


@njit(cache=True, error_model="numpy", inline="always")
def _reward_rows(estimate, truth, applied, previous, valid, alpha_th, filter_flops, policy_flops, per_channel,
                 acc_scale, t_max, flops_per_s, watts, l_delay, l_energy, l_jitter, out, lo, hi):
    """The terms of episodes lo..hi−1 into ``out`` ``(8, B, N)``.

    The sums run in NumPy's order (its pairwise summation over the channels), so each term is the module
    docstring's formula evaluated as NumPy evaluates it, bit for bit (``tests/test_reward.py``), except that exp
    is the C library's: NumPy's SIMD exp can differ from it in the last bit, and from machine to machine."""
    n, n_l = valid.shape[1], valid.shape[2]
    row = np.empty(n_l)
    for b in range(lo, hi):
        for i in range(n):
            d0 = estimate[b, i, 0] - truth[b, i, 0]
            d1 = estimate[b, i, 1] - truth[b, i, 1]
            d2 = estimate[b, i, 2] - truth[b, i, 2]
            accuracy = math.exp(-(d0 * d0 + d1 * d1 + d2 * d2) / acc_scale)
            n_valid = n_active = 0
            for l in range(n_l):
                v = valid[b, i, l]
                if v:
                    n_valid += 1
                    if applied[b, i, l] > alpha_th:
                        n_active += 1
                row[l] = abs(applied[b, i, l] - previous[b, i, l]) * (1.0 if v else 0.0)
            denom = max(n_valid, 1)
            one = policy_flops.shape[0] == 1 and policy_flops.shape[1] == 1
            policy = policy_flops[0, 0] if one else policy_flops[b, i]
            flops = filter_flops[b, i] + (policy + per_channel * n_valid)
            t_calc = flops / flops_per_s
            # exp(x) − 1 ≤ 0 for x ≤ 0: no exp within the budget
            delay = max(0.0, math.exp((t_calc - t_max) / t_max) - 1.0) if t_calc > t_max else 0.0
            energy = n_active / denom
            jitter = _pairwise_sum(row, 0, n_l) / denom
            out[0, b, i] = accuracy - l_delay * delay - l_energy * energy - l_jitter * jitter
            out[1, b, i], out[2, b, i], out[3, b, i], out[4, b, i] = accuracy, delay, energy, jitter
            out[5, b, i], out[6, b, i], out[7, b, i] = flops, 1e3 * t_calc, t_calc * watts


@njit(cache=True, error_model="numpy")
def _reward_serial(estimate, truth, applied, previous, valid, alpha_th, filter_flops, policy_flops, per_channel,
                   acc_scale, t_max, flops_per_s, watts, l_delay, l_energy, l_jitter, out):
    """``_reward_rows`` over the batch, on the calling thread."""
    _reward_rows(estimate, truth, applied, previous, valid, alpha_th, filter_flops, policy_flops, per_channel,
                 acc_scale, t_max, flops_per_s, watts, l_delay, l_energy, l_jitter, out, 0, valid.shape[0])


@njit(cache=True, error_model="numpy", parallel=True)
def _reward_threaded(estimate, truth, applied, previous, valid, alpha_th, filter_flops, policy_flops, per_channel,
                     acc_scale, t_max, flops_per_s, watts, l_delay, l_energy, l_jitter, out):
    """``_reward_rows`` with threads over blocks of ``BLOCK`` episodes."""
    n_b = valid.shape[0]
    for block in prange((n_b + BLOCK - 1) // BLOCK):
        lo, hi = block_bounds(block, n_b)
        _reward_rows(estimate, truth, applied, previous, valid, alpha_th, filter_flops, policy_flops, per_channel,
                     acc_scale, t_max, flops_per_s, watts, l_delay, l_energy, l_jitter, out, lo, hi)


@njit(cache=True)
def _pairwise_sum(a, lo, n):
    """Σ a[lo:lo + n] as NumPy sums a contiguous axis: in order below 8 terms, eight partial sums up to 128,
    and above, the sum of the two halves (the first a multiple of 8 terms), each summed the same way.

    The halving runs as a loop over the leaves (blocks of at most 128 terms) with a stack of partial sums,
    not as a recursion: numba's cache does not load recursive functions safely."""
    if n <= 128:
        return _block_sum(a, lo, n)
    # depth-first over the tree of halves: (lo, n, state) with state 0 = unvisited, 1 = left summed
    stack_lo, stack_n = np.empty(64, dtype=np.int64), np.empty(64, dtype=np.int64)
    stack_state, partial = np.zeros(64, dtype=np.int64), np.empty(64)
    top = 0
    stack_lo[0], stack_n[0], stack_state[0] = lo, n, 0
    result = 0.0
    while top >= 0:
        m = stack_n[top]
        if m <= 128:
            value = _block_sum(a, stack_lo[top], m)
            top -= 1
            # hand the value to the parent: its left half, or its right half (then the parent is done)
            while top >= 0 and stack_state[top] == 1:
                value = partial[top] + value
                top -= 1
            if top < 0:
                result = value
                break
            partial[top] = value
            stack_state[top] = 1
            half = stack_n[top] // 2
            half -= half % 8
            top += 1
            stack_lo[top], stack_n[top], stack_state[top] = stack_lo[top - 1] + half, stack_n[top - 1] - half, 0
        else:
            half = m // 2
            half -= half % 8
            top += 1
            stack_lo[top], stack_n[top], stack_state[top] = stack_lo[top - 1], half, 0
    return result


@njit(cache=True, inline="always")
def _block_sum(a, lo, n):
    """NumPy's pairwise sum of at most 128 terms: in order below 8, else eight partial sums."""
    if n < 8:
        s = 0.0
        for k in range(lo, lo + n):
            s += a[k]
        return s
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    k = 8
    while k < n - n % 8:
        r0 += a[lo + k]
        r1 += a[lo + k + 1]
        r2 += a[lo + k + 2]
        r3 += a[lo + k + 3]
        r4 += a[lo + k + 4]
        r5 += a[lo + k + 5]
        r6 += a[lo + k + 6]
        r7 += a[lo + k + 7]
        k += 8
    s = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while k < n:
        s += a[lo + k]
        k += 1
    return s
