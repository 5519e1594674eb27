"""Classical link-trust baselines, the oracle, smoothing and dead reckoning."""

from __future__ import annotations

import numpy as np
import pytest
from trust_helpers import trust_input as _input
from trust_helpers import trust_layout as _layout

from swarmloc.agents.trust.classical import (
    Chi2GateTrust,
    Chi2SoftTrust,
    FederatedCoefTrust,
    HuberTrust,
    NonCooperativeTrust,
    OracleTrust,
    RandomTrust,
)
from swarmloc.agents.protocols import PrivilegedInfo, episode_keys
from swarmloc.agents.registry import load_method
from swarmloc.agents.trust.smoothing import MarkovSmoothing, smooth_step
from swarmloc.bench.evaluation.runner import evaluate_task, rollout
from swarmloc.envs.tasks.channels import ANCHOR, GPS, LANDMARK, PEER, PEER_REL, TDOA, ChannelLayout
from swarmloc.envs.tasks.catalogue import get_spec

SEEDS = list(range(1_000_000, 1_000_008))


# --------------------------------------------------------------------------- rules


def test_huber_weight():
    pol = HuberTrust(1.345)
    pol.reset(1, _layout([ANCHOR, ANCHOR, ANCHOR]), episode_keys([0]))
    # u = √NIS = 1, 1.345, 2.69 → 1, 1, 0.5
    alpha = pol.act(_input(np.array([[[1.0, 1.345**2, 2.69**2]]])))
    np.testing.assert_allclose(alpha, [[[1.0, 1.0, 0.5]]])


def test_chi2_gate_thresholds_per_dof():
    pol = Chi2GateTrust(0.95)
    pol.reset(1, _layout([ANCHOR, ANCHOR, GPS, GPS]), episode_keys([0]))
    # χ²₀.₉₅(1) = 3.841, χ²₀.₉₅(3) = 7.815
    alpha = pol.act(_input(np.array([[[3.8, 3.9, 7.8, 7.9]]])))
    np.testing.assert_allclose(alpha, [[[1.0, 0.01, 1.0, 0.01]]])


def test_chi2_soft_is_continuous_at_the_gate_and_decays():
    pol = Chi2SoftTrust(0.95, 1.0)
    pol.reset(1, _layout([ANCHOR, ANCHOR, ANCHOR]), episode_keys([0]))
    thr = 3.841458820694124
    alpha = pol.act(_input(np.array([[[thr - 1e-9, thr + 2.0, thr + 20.0]]])))
    # exp(−2 / 2) and exp(−20 / 2)
    np.testing.assert_allclose(alpha, [[[1.0, np.exp(-1.0), np.exp(-10.0)]]], rtol=1e-9)


def test_federated_coefficient():
    pol = FederatedCoefTrust(0.85)
    pol.reset(1, _layout([ANCHOR] * 4), episode_keys([0]))
    # three consistent channels (ΔV ≤ d → β = 1), one with ΔV = 8.5 → β = 0.1
    alpha = pol.act(_input(np.array([[[0.5, 0.2, 0.8, 8.5]]])))
    # β_t = 0.1 / 3.1, n β_t = 0.4/3.1, α = 1 / (2 − n β_t)
    expected = 1.0 / (2.0 - 0.4 / 3.1)
    np.testing.assert_allclose(alpha, [[[1.0, 1.0, 1.0, expected]]])
    assert 0.5 < expected < 1.0
    # a lone present channel keeps full trust whatever its residual
    alpha = pol.act(_input(np.array([[[50.0, 0.0, 0.0, 0.0]]]), np.array([[[True, False, False, False]]])))
    assert alpha[0, 0, 0] == 1.0


def test_non_cooperative_skips_exactly_the_peer_channels():
    pol = NonCooperativeTrust()
    pol.reset(2, _layout([ANCHOR, PEER, LANDMARK, GPS, PEER_REL, TDOA]), episode_keys([0, 1]))
    alpha = pol.act(_input(np.full((2, 1, 6), 50.0)))
    np.testing.assert_array_equal(alpha, [[[1.0, 0.0, 1.0, 1.0, 0.0, 1.0]]] * 2)


def test_non_cooperative_estimates_ignore_the_peer_measurements():
    """Invariant: with the peer channels skipped, noisier peer ranges change no estimate (bit for bit)."""
    base = get_spec("swarmloc/Ideal-v1", duration=3.0)
    rmse = {}
    for sigma in (0.15, 5.0):
        peers = {**base.sensors.peers.model_dump(), "sigma": sigma}
        spec = get_spec("swarmloc/Ideal-v1", duration=3.0, sensors={**base.sensors.model_dump(), "peers": peers})
        for name in ("non-cooperative", "uniform"):
            rmse[name, sigma] = [m["rmse"] for m in rollout(load_method(name), spec, SEEDS[:2])[0]]
    assert rmse["non-cooperative", 0.15] == rmse["non-cooperative", 5.0]
    assert rmse["uniform", 0.15] != rmse["uniform", 5.0]  # the peers do reach the standard CEKF


def test_random_trust_is_keyed_per_episode():
    pol = RandomTrust()
    shape = (3, 2, 4)
    layout = ChannelLayout(kind=np.zeros(shape[1:], int), target=np.zeros(shape[1:], int),
                           linked=np.ones(shape[1:], bool), sigma=np.ones(shape[1:]))
    keys = episode_keys([7, 8, 9])
    pol.reset(3, layout, keys)
    batched = pol.act(_input(np.zeros(shape), step=5))
    assert ((batched > 0) & (batched < 1)).all()
    pol.reset(1, layout, keys[1:2])
    alone = pol.act(_input(np.zeros((1, *shape[1:])), step=5))
    np.testing.assert_array_equal(alone[0], batched[1])
    assert not np.array_equal(batched[0], batched[1])


def test_oracle_needs_labels_and_rejects_labelled_channels():
    injected, error = np.array([[[True, False]]]), np.array([[[False, True]]])
    pol = OracleTrust()
    pol.reset(1, _layout([ANCHOR, ANCHOR]), episode_keys([0]))
    with pytest.raises(RuntimeError, match="observe_privileged"):
        pol.act(_input(np.zeros((1, 1, 2))))
    pol.observe_privileged(PrivilegedInfo(labels=injected, error_labels=error))
    np.testing.assert_allclose(pol.act(_input(np.zeros((1, 1, 2)))), [[[1.0, 0.01]]])  # the error labels only
    with pytest.raises(ValueError, match="labels must have shape"):
        pol.observe_privileged(PrivilegedInfo(labels=np.zeros((2, 1, 2), bool), error_labels=np.zeros((2, 1, 2), bool)))
    with pytest.raises(ValueError, match="error_labels"):
        OracleTrust().observe_privileged(PrivilegedInfo(labels=injected))


def test_oracle_at_other_thresholds_reads_the_systematic_error():
    """An oracle at its own k thresholds ``systematic_sigmas`` per channel dimension (ranges: k)."""
    pol = OracleTrust(label_sigmas=2.0, vector_radius=4.0)
    pol.reset(1, _layout([ANCHOR, GPS, ANCHOR]), episode_keys([0]))
    pol.observe_privileged(PrivilegedInfo(labels=np.zeros((1, 1, 3), bool), error_labels=np.zeros((1, 1, 3), bool),
                                          systematic_sigmas=np.array([[[2.5, 3.0, 1.5]]])))
    np.testing.assert_allclose(pol.act(_input(np.zeros((1, 1, 3)))), [[[0.01, 1.0, 1.0]]])
    with pytest.raises(ValueError, match="systematic_sigmas"):
        pol.observe_privileged(PrivilegedInfo(labels=np.zeros((1, 1, 3), bool)))
    with pytest.raises(ValueError, match="must be > 0"):
        OracleTrust(label_sigmas=0.0)


def test_parameters_validated():
    with pytest.raises(ValueError, match="k must be > 0"):
        HuberTrust(0.0)
    with pytest.raises(ValueError, match=r"confidence must be in \(0, 1\)"):
        Chi2GateTrust(1.5)
    with pytest.raises(ValueError, match="beta_max"):
        MarkovSmoothing(HuberTrust(), beta_max=1.0)


# --------------------------------------------------------------------------- smoothing


def test_smooth_step_hand_computed():
    prev, raw = np.array([1.0, 1.0, 0.5]), np.array([0.0, 0.0, 0.0])
    r_prev, r = np.array([0.0, 0.0, 0.0]), np.array([0.0, 10.0, 0.0])
    valid = np.array([True, True, False])
    out = smooth_step(prev, raw, r_prev, r, valid, 0.85, 2.0)
    # Δr = 0: β = 0.85 → 0.85·1 + 0.15·0; Δr = 10: β = 0.85 e⁻²⁰ ≈ 0; absent: unchanged
    np.testing.assert_allclose(out, [0.85, 0.85 * np.exp(-20.0), 0.5])


def test_smoothing_wrapper_reduces_jitter():
    spec = get_spec("swarmloc/NLOS-v0", duration=15.0)
    raw, _ = rollout(load_method("huber"), spec, SEEDS[:2])
    smooth, _ = rollout(load_method("huber+smooth"), spec, SEEDS[:2])
    for a, b in zip(raw, smooth):
        assert b["jitter"] < a["jitter"]
    assert load_method("oracle+smooth").privileged


# --------------------------------------------------------------------------- on the tasks


@pytest.fixture(scope="module")
def cascaded() -> dict:
    return evaluate_task(["uniform", "oracle", "chi2-gate"], "swarmloc/CascadedFault-v0",
                         SEEDS).episodes


def test_oracle_beats_uniform_on_every_seed_nlos():
    out = evaluate_task(["uniform", "oracle"], "swarmloc/NLOS-v0", SEEDS).episodes
    for u, o in zip(out["uniform"], out["oracle"]):
        assert o["rmse"] < u["rmse"]
        # the score's reference: uniform's own RMSE on the same episode (gain 0 for uniform)
        assert o["uniform_rmse"] == u["uniform_rmse"] == u["rmse"]


def test_oracle_beats_uniform_on_every_seed_cascaded(cascaded):
    for u, o in zip(cascaded["uniform"], cascaded["oracle"]):
        assert o["rmse"] < u["rmse"]
        assert o["healthy_rmse"] < u["healthy_rmse"]


def test_chi2_gate_beats_uniform_on_healthy_nodes(cascaded):
    gate = [e["healthy_rmse"] for e in cascaded["chi2-gate"]]
    uniform = [e["healthy_rmse"] for e in cascaded["uniform"]]
    assert np.mean(gate) < np.mean(uniform)
    assert all(g < u for g, u in zip(gate, uniform))


def test_dead_reckoning_far_worse_than_cekf_on_ideal():
    out = evaluate_task(["uniform", "dead-reckoning"], "swarmloc/Ideal-v0", SEEDS).episodes
    for u, d in zip(out["uniform"], out["dead-reckoning"]):
        assert d["rmse"] >= 5.0 * u["rmse"]
        assert d["jitter"] is None  # reports no trust
        assert d["delay_ms"] is not None  # reports FLOPs
