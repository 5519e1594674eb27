"""The standard reward's one-pass kernel against its definition in NumPy (docs/reward.md).

The sums follow NumPy's pairwise order, so every term without an exponential is NumPy's bit for bit; the
accuracy and delay terms use the C library's exp, which may differ from NumPy's SIMD exp in the last bit.
"""

from __future__ import annotations

import numpy as np
import pytest

from swarmloc.envs.world.cost import DEFAULT_PROFILE
from swarmloc.envs.world.reward import STANDARD_WEIGHTS, RewardWeights
from swarmloc.envs.world.reward_kernel import standard_reward
from swarmloc.envs.world.sim_kernel import SERIAL_BELOW


def _reference(estimate, truth, applied, previous, valid, alpha_th, filter_flops, policy_flops, per_channel, w, prof):
    """The module docstring's formulas as NumPy expressions."""
    err2 = np.sum((estimate - truth) ** 2, axis=-1)
    accuracy = np.exp(-err2 / (2.0 * w.sigma_acc**2))
    flops = filter_flops + (policy_flops + per_channel * valid.sum(axis=-1))
    t_calc = prof.seconds(flops)
    delay = np.maximum(0.0, np.exp((t_calc - w.t_max) / w.t_max) - 1.0)
    denom = np.maximum(valid.sum(axis=-1), 1)
    energy = ((applied > alpha_th) & valid).sum(axis=-1) / denom
    jitter = (np.abs(applied - previous) * valid).sum(axis=-1) / denom
    reward = accuracy - w.delay * delay - w.energy * energy - w.jitter * jitter
    return dict(reward=reward, accuracy=accuracy, delay_penalty=delay, energy_penalty=energy, jitter_penalty=jitter,
                flops=flops, delay_ms=1e3 * t_calc, energy_j=prof.joules(flops))


# channel counts below 8, up to 128 and above (NumPy's three summation regimes); batches on the calling thread
# and threaded
@pytest.mark.parametrize("shape", [(3, 4, 5), (5, 6, 13), (SERIAL_BELOW + 3, 8, 39), (2, 2, 300)])
def test_the_kernel_is_the_numpy_definition(shape):
    rng = np.random.default_rng(sum(shape))
    n_b, n, n_l = shape
    est, truth = rng.normal(size=(n_b, n, 3)), rng.normal(size=(n_b, n, 3))
    applied, previous = rng.uniform(size=shape), rng.uniform(size=shape)
    valid = rng.uniform(size=shape) < 0.7
    # FLOPs around the delay budget: some steps within it (no penalty), some over
    filter_flops = rng.uniform(0.0, 2.0, size=(n_b, n)) * DEFAULT_PROFILE.effective_flops * STANDARD_WEIGHTS.t_max
    w = RewardWeights(delay=3.0, energy=0.2, jitter=4.0, sigma_acc=0.7)
    got = standard_reward(est, truth, applied, previous, valid, 0.1, filter_flops, 250.0, w, DEFAULT_PROFILE, 12.5)
    want = _reference(est, truth, applied, previous, valid, 0.1, filter_flops, 250.0, 12.5, w, DEFAULT_PROFILE)
    for name in ("energy_penalty", "jitter_penalty", "flops", "delay_ms", "energy_j"):
        assert np.array_equal(getattr(got, name), want[name]), name
    for name in ("accuracy", "delay_penalty", "reward"):
        np.testing.assert_allclose(getattr(got, name), want[name], rtol=1e-14, atol=1e-15, err_msg=name)
    assert (got.delay_penalty == 0.0).sum() == (filter_flops + 250.0 + 12.5 * valid.sum(-1)
                                                <= DEFAULT_PROFILE.effective_flops * STANDARD_WEIGHTS.t_max).sum()


def test_an_episode_gets_the_same_terms_in_any_batch():
    rng = np.random.default_rng(3)
    shape = (SERIAL_BELOW + 4, 5, 11)
    args = (rng.normal(size=shape[:2] + (3,)), rng.normal(size=shape[:2] + (3,)), rng.uniform(size=shape),
            rng.uniform(size=shape), rng.uniform(size=shape) < 0.6, 0.1, rng.uniform(1e5, 1e7, size=shape[:2]))
    batched = standard_reward(*args)
    for b in (0, 17, shape[0] - 1):
        alone = standard_reward(*(a[b:b + 1] if isinstance(a, np.ndarray) else a for a in args))
        for name in ("reward", "accuracy", "delay_penalty", "jitter_penalty", "energy_j"):
            assert np.array_equal(getattr(alone, name)[0], getattr(batched, name)[b]), name


def test_policy_flops_as_one_number_or_per_uav():
    rng = np.random.default_rng(4)
    shape = (1, 3, 6)
    args = (rng.normal(size=(1, 3, 3)), rng.normal(size=(1, 3, 3)), rng.uniform(size=shape), rng.uniform(size=shape),
            rng.uniform(size=shape) < 0.8, 0.1, np.full((1, 3), 1e5))
    per_uav = np.array([[1e3, 2e6, 3e3]])
    assert np.array_equal(standard_reward(*args, per_uav).flops, 1e5 + per_uav)
    assert np.array_equal(standard_reward(*args, 7.0).flops, np.full((1, 3), 1e5 + 7.0))
