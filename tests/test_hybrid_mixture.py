"""Hybrid GPS noise as a contamination mixture (``HybridNoise(model="mixture")``, the v1 tasks):
the draws' statistics, kernel == a readable transcription, batched == single, error labels of the
Student-t draws, and the v0 weighted sum left bit for bit as it was."""

from __future__ import annotations

import hashlib
import math

import numpy as np
import pydantic
import pytest

from swarmloc.envs.tasks.channels import GPS
from swarmloc.envs.world.labels_reference import own_error_labels_reference
from swarmloc.envs.tasks.rng import Stream, normal, uniform
from swarmloc.envs.tasks.specs import HybridNoise
from swarmloc.envs.tasks.catalogue import get_spec
from swarmloc.envs.world.sim import World
from swarmloc.envs.world.sim_kernel import SERIAL_BELOW

FOLLOWERS = list(range(1, 9))


def mixture_spec(ratio: float = 0.3, duration: float = 20.0, **fields):
    """HybridNoise30-v0 with its GPS noise switched to the mixture model."""
    h = {"model": "mixture", "ratio": ratio, "nodes": FOLLOWERS, "t_scale": 1.0, "gauss_sigma": 1.0,
         "dof_low": 3, "dof_high": 8, **fields}
    return get_spec("swarmloc/HybridNoise30-v0", duration=duration, faults={"hybrid_noise": h})


def gps_rollout(spec, seeds):
    """Every step's GPS noise z − p, systematic error and error labels: ``(T, B, N, 3)``, …, ``(T, B, N)``."""
    world = World(spec, len(seeds))
    world.reset(seeds)
    gps = world.layout.kind == GPS
    col = np.argmax(gps, axis=1)
    rows = np.arange(spec.n_uav)
    noise, systematic, label, valid = [], [], [], []
    for _ in range(spec.n_steps):
        buf = world.sense()
        noise.append(buf.z[:, rows, col] - buf.pos)
        systematic.append(buf.systematic[:, rows, col].copy())
        label.append(buf.error_label[:, rows, col].copy())
        valid.append(buf.valid[:, rows, col].copy())
        own = own_error_labels_reference(world.layout.kind, world.layout.sigma, buf.systematic, buf.valid,
                                      world.inputs.label_threshold)
        np.testing.assert_array_equal(buf.error_label, own)  # the world's own-error labels == the reference
    return world, *map(np.array, (noise, systematic, label, valid))


def mixture_noise_reference(seed: int, step: int, idx: int, h: HybridNoise) -> tuple[np.ndarray, bool]:
    """One fix's mixture noise from the counter-based draws, written out plainly.

    With probability p (uniform at 2·idx of the mixing stream) the fix is σ_t·n / sqrt(χ²_ν / ν),
    ν = ν_lo + ⌊u·(ν_hi − ν_lo + 1)⌋ (uniform at 2·idx + 1), χ² the sum of ν squared normals at
    2 000 000 + 64·idx + c of the GPS stream; else σ_g·n. n: normals at 3·idx + d of the GPS stream.
    """
    n = np.array([normal(seed, step, Stream.GPS, 3 * idx + d) for d in range(3)])
    if not uniform(seed, step, Stream.HYBRID_MIX, 2 * idx) < h.ratio:
        return h.gauss_sigma * n, False
    nu = h.dof_low + int(uniform(seed, step, Stream.HYBRID_MIX, 2 * idx + 1) * (h.dof_high - h.dof_low + 1))
    chi2 = sum(normal(seed, step, Stream.GPS, 2_000_000 + 64 * idx + c) ** 2 for c in range(nu))
    return h.t_scale * n / math.sqrt(chi2 / nu), True


def test_weighted_sum_v0_is_unchanged():
    """HybridNoise30-v0 (the weighted sum) gives the numbers it gave before the mixture model existed."""
    spec = get_spec("swarmloc/HybridNoise30-v0", duration=20.0)
    assert spec.faults.hybrid_noise.model == "weighted_sum"
    world = World(spec, 2)
    world.reset([1_000_000, 7])
    digest = hashlib.sha256()
    for _ in range(spec.n_steps):
        buf = world.sense()
        for a in (buf.z, buf.systematic, buf.error_label, buf.label, buf.injected, buf.valid):
            digest.update(np.ascontiguousarray(a).tobytes())
    gps = world.layout.kind == GPS
    assert buf.z[0][gps][1].tolist() == [20.437273293464568, -5.033686049247929, 9.276604157237653]
    assert buf.systematic[0][gps][1].tolist() == [0.030212743393497242, -0.20967807071558336, -0.17784097152144349]
    assert digest.hexdigest() == "60c38c60ee305c253878ad7113076b7a2f177e155c804e24f564361a6b7b7503"


def test_mixture_statistics():
    """A long episode: the fraction of Student-t fixes is p (binomial tolerance), the Gaussian fixes have
    std σ_g, the Student-t ones the t's spread, and the leader (no hybrid noise) keeps its nominal σ."""
    p, sigma_g, sigma_t, lo, hi = 0.3, 0.8, 1.5, 6, 10  # ν ≥ 6: the t's variance has a finite spread
    spec = mixture_spec(p, duration=300.0, gauss_sigma=sigma_g, t_scale=sigma_t, dof_low=lo, dof_high=hi)
    world, noise, systematic, label, valid = gps_rollout(spec, [2_000_000])
    assert valid.all()
    heavy = (systematic[:, 0, 1:] != 0).any(axis=-1)  # (T, 8) Student-t fixes of the followers
    n_fix = heavy.size
    assert abs(heavy.mean() - p) < 4.0 * math.sqrt(p * (1 - p) / n_fix), heavy.mean()
    follower = noise[:, 0, 1:]
    gauss = follower[~heavy]
    # std of a sample std ≈ σ / sqrt(2n)
    assert abs(gauss.std() - sigma_g) < 4.0 * sigma_g / math.sqrt(2 * gauss.size), gauss.std()
    assert abs(gauss.mean()) < 4.0 * sigma_g / math.sqrt(gauss.size)
    t_var = sigma_t**2 * np.mean([nu / (nu - 2) for nu in range(lo, hi + 1)])
    assert follower[heavy].var() == pytest.approx(t_var, rel=0.08)  # ≈ 3 standard errors (kurtosis ≥ 6)
    # a Student-t fix is systematic as a whole; a Gaussian one has none
    np.testing.assert_allclose(systematic[:, 0, 1:][heavy], follower[heavy], rtol=0, atol=1e-12)  # z − p rounds
    assert not systematic[:, 0, 1:][~heavy].any()
    assert not systematic[:, 0, 0].any()
    leader = noise[:, 0, 0]
    assert abs(leader.std() - 0.1) < 4.0 * 0.1 / math.sqrt(2 * leader.size)
    # error labels: only Student-t fixes, those outside the 3σ-equivalent radius (3.76 σ, σ = 1 m)
    assert not label[:, 0, 1:][~heavy].any()
    radius = world.inputs.label_threshold[world.layout.kind == GPS][1:]
    big = np.linalg.norm(systematic[:, 0, 1:], axis=-1) / 1.0 > radius
    np.testing.assert_array_equal(label[:, 0, 1:], heavy & big)
    assert label.any()


@pytest.mark.parametrize("ratio", [0.0, 1.0])
def test_mixture_edge_ratios(ratio):
    _, noise, systematic, _, _ = gps_rollout(mixture_spec(ratio, duration=5.0), [2_000_001])
    heavy = (systematic[:, 0, 1:] != 0).any(axis=-1)
    assert heavy.all() if ratio == 1.0 else not heavy.any()


def test_kernel_equals_the_reference():
    """Every follower fix of every step is the readable transcription's draw, bit for bit up to libm."""
    spec = mixture_spec(0.5, duration=3.0)
    h = spec.faults.hybrid_noise
    seeds = [2_000_002, 5]
    world, noise, systematic, _, _ = gps_rollout(spec, seeds)
    col = np.argmax(world.layout.kind == GPS, axis=1)
    n_l = world.layout.n_channels
    count = 0
    for k in range(spec.n_steps):
        for b, seed in enumerate(seeds):
            for i in FOLLOWERS:
                want, heavy = mixture_noise_reference(seed, k + 1, i * n_l + col[i], h)
                np.testing.assert_allclose(noise[k, b, i], want, rtol=1e-10, atol=1e-12)
                np.testing.assert_array_equal(systematic[k, b, i] != 0, np.full(3, heavy))
                count += heavy
    assert 0 < count < spec.n_steps * len(seeds) * len(FOLLOWERS)


def test_batched_equals_single():
    """The mixture's draws are keyed by (seed, step, stream, index): a batch — in parallel blocks from
    SERIAL_BELOW episodes on — gives each episode the numbers it gets alone."""
    spec = mixture_spec(0.3, duration=2.0)
    seeds = list(range(2_000_000, 2_000_000 + SERIAL_BELOW + 3))
    batch = World(spec, len(seeds))
    batch.reset(seeds)
    singles = [World(spec, 1) for _ in seeds]
    for world, seed in zip(singles, seeds):
        world.reset([seed])
    for _ in range(spec.n_steps):
        buf = batch.sense()
        for b, world in enumerate(singles):
            one = world.sense()
            for name in ("z", "systematic", "error_label", "label", "injected", "valid"):
                assert np.array_equal(getattr(buf, name)[b], getattr(one, name)[0]), (name, b)


def test_spec_fields():
    assert HybridNoise(ratio=0.3).model == "weighted_sum"  # every v0 task
    with pytest.raises(pydantic.ValidationError, match="model"):
        HybridNoise(ratio=0.3, model="sum")
    with pytest.raises(pydantic.ValidationError, match="dof_high"):
        HybridNoise(ratio=0.3, dof_high=64)  # the RNG keeps 64 normals per Student-t draw
