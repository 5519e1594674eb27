"""The UTIL NLOS fit: its statistics on known processes, its process against the world kernel, and the
frozen ``UTIL_NLOS_*`` values against the real logs (skipped where the UTIL data is absent)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarmloc.envs.recorded.nlos_statistics import (autocorrelation, channel_offsets, excess, residual_statistics,
                                                    run_lengths)
from swarmloc.envs.tasks.catalogue import get_spec
from swarmloc.envs.tasks.rng import Stream, normal_array, uniform_array
from swarmloc.envs.world.nlos_reference import GM_FIELDS, gm_nlos_bias, simulate_gm_nlos
from swarmloc.envs.world.sim import World
from swarmloc.envs.world.worlds import data_missing


def _ar1(n_t: int, n_c: int, phi: float, rng: np.random.Generator) -> np.ndarray:
    """Stationary unit-variance AR(1) series, one per column."""
    x = np.empty((n_t, n_c))
    x[0] = rng.standard_normal(n_c)
    for k in range(1, n_t):
        x[k] = phi * x[k - 1] + math.sqrt(1.0 - phi * phi) * rng.standard_normal(n_c)
    return x


def test_run_lengths_offsets_and_excess_are_exact():
    assert run_lengths(np.array([1, 1, 0, 1, 0, 0, 1, 1, 1], dtype=bool)).tolist() == [2, 1, 3]
    assert run_lengths(np.zeros(4, dtype=bool)).size == 0
    residual = np.array([[1.0, 5.0], [2.0, 0.0], [3.0, 7.0], [9.0, 6.0]])
    valid = np.array([[1, 1], [1, 0], [1, 1], [0, 1]], dtype=bool)
    assert channel_offsets(residual, valid).tolist() == [2.0, 6.0]
    assert excess(residual, valid).tolist() == [[-1.0, -1.0], [0.0, 0.0], [1.0, 1.0], [0.0, 0.0]]
    with pytest.raises(ValueError, match="must both be"):
        excess(residual, valid[:3])


def test_statistics_of_an_on_off_chain_match_its_closed_form():
    # a two-state Markov chain per channel: off → on with probability p, on → off with q per step; a bias
    # of 10 σ while on. Biased share p / (p + q), mean run 1/q steps, every magnitude 10 σ (noise σ = 0.01)
    p, q, dt, n_t, n_c = 0.02, 0.1, 0.01, 20_000, 20
    rng = np.random.default_rng(1)
    on = np.zeros((n_t, n_c), dtype=bool)
    state = rng.random(n_c) < p / (p + q)
    for k in range(n_t):
        u = rng.random(n_c)
        state = np.where(state, u >= q, u < p)
        on[k] = state
    residual = 10.0 * on + 0.01 * rng.standard_normal((n_t, n_c)) + np.arange(n_c) * 0.0
    valid = np.ones_like(on)
    # centring on the channel median (0: the chain is off most of the time) leaves the bias as it is
    stats = residual_statistics([(residual, valid)], sigma_los=1.0, dt=dt, k=3.0)
    assert stats.share_biased == pytest.approx(p / (p + q), rel=0.05)
    assert stats.mean_run_s == pytest.approx(dt / q, rel=0.05)
    assert stats.magnitude == pytest.approx((10.0, 10.0, 10.0), abs=0.03)


def test_statistics_of_an_ar1_process_match_its_closed_form():
    # unit AR(1), φ = exp(−dt/τ): ACF at lag ℓ steps φ^ℓ; share beyond 3σ is 2Φ(−3); sampled every 10th
    # step (held between samples) the ACF at lags of whole sample intervals is unchanged
    dt, tau = 0.01, 0.5
    phi = math.exp(-dt / tau)
    x = _ar1(40_000, 16, phi, np.random.default_rng(2))
    valid = np.ones(x.shape, dtype=bool)
    stats = residual_statistics([(x, valid)], sigma_los=1.0, dt=dt, k=3.0)
    assert stats.share_biased == pytest.approx(math.erfc(3.0 / math.sqrt(2.0)), rel=0.15)
    assert stats.acf == pytest.approx([math.exp(-lag / tau) for lag in (0.2, 1.0, 3.0)], abs=0.03)
    sparse = np.zeros_like(valid)
    sparse[::10] = True
    assert autocorrelation(x, sparse, 20) == pytest.approx(phi ** 20, abs=0.03)
    with pytest.raises(ValueError, match="sigma_los"):
        residual_statistics([(x, valid)], sigma_los=0.0, dt=dt)


@pytest.mark.parametrize("onset", ["ramp", "jump"])
def test_reference_process_equals_the_world_kernel(onset):
    # the readable process, fed the kernel's counter-based draws, gives the world's bias on every channel
    spec = get_spec("swarmloc/NLOS-v1", duration=3.0,
                    faults={"nlos_gauss_markov": {"onset_rate": 1.5, "mean_duration": 1.0, "onset": onset}})
    seed, n_t = 11, spec.n_steps
    world = World(spec, 1)
    world.reset([seed])
    bias = np.array([world.sense().systematic[0, :, :, 0].copy() for _ in range(n_t)])
    mask = world.schedule.gm_mask[0]
    keys = world.schedule.gm_key[mask]
    onset_u = np.array([uniform_array(seed, k, Stream.NLOS_ONSET, 2 * keys) for k in range(1, n_t + 1)])
    duration_u = np.array([uniform_array(seed, k, Stream.NLOS_ONSET, 2 * keys + 1) for k in range(1, n_t + 1)])
    normals = np.array([normal_array(seed, k, Stream.NLOS_PROCESS, keys) for k in range(1, n_t + 1)])
    g = spec.faults.nlos_gauss_markov
    expected = gm_nlos_bias({k: getattr(g, k) for k in GM_FIELDS}, onset == "ramp", spec.dt, onset_u, duration_u,
                            normals)
    assert (expected > 0).mean() > 0.2
    np.testing.assert_allclose(bias[:, mask], expected, rtol=0, atol=1e-12)
    assert not bias[:, ~mask].any()


def test_simulated_process_rejects_empty_shapes():
    with pytest.raises(ValueError, match="n_steps=0"):
        simulate_gm_nlos({k: 1.0 for k in GM_FIELDS}, True, 0.01, 0, 3, np.random.default_rng(0))


def test_frozen_util_nlos_matches_the_real_residual_statistics():
    """The frozen ``UTIL_NLOS_*`` process, observed as the logs are, has the logs' statistics.

    Tolerances (the fit leaves: share 1.31, magnitudes 1.34, run 1.46, ACF 0.05 at most):
    biased share within a factor 1.35, magnitude quantiles within 1.4, mean biased run within
    1.5, excess autocorrelation at 0.2 / 1 / 3 s within 0.1.
    """
    for task in ("swarmloc/UTILFlight-v0", "swarmloc/UTILC0426Tdoa2Wood-v1"):
        why = data_missing(get_spec(task))
        if why:
            pytest.skip(f"the UTIL data is not here ({why.splitlines()[0]}); the fit's test needs it")
    from swarmloc.bench.reproduce.nlos_fit import DATASETS, FROZEN, load_dataset, real_statistics, simulated_statistics

    for dataset in DATASETS:
        series = load_dataset(dataset)
        real, sim = real_statistics(series), simulated_statistics(FROZEN[dataset.name], series)
        ratio = lambda a, b: max(a / b, b / a)  # noqa: E731
        assert ratio(sim.share_biased, real.share_biased) < 1.35, (dataset.name, sim, real)
        assert all(ratio(a, b) < 1.4 for a, b in zip(sim.magnitude, real.magnitude)), (dataset.name, sim, real)
        assert ratio(sim.mean_run_s, real.mean_run_s) < 1.5, (dataset.name, sim, real)
        assert np.allclose(sim.acf, real.acf, atol=0.1), (dataset.name, sim, real)
