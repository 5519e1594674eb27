"""Adaptive fault-tolerant federated filter (federated §4): cycle closed forms and the estimator."""

from __future__ import annotations

import numpy as np
import pytest

from swarmloc.agents.estimators.federated import (
    FederatedConfig,
    FederatedEstimator,
    federated,
    federated_cycle,
    federated_fdi,
    imu_prediction,
)
from swarmloc.agents.estimators.fusion import chi2_threshold
from swarmloc.agents.protocols import Measurements, TaskFacts, episode_keys
from swarmloc.envs.tasks.catalogue import get_spec
from swarmloc.envs.world.sim import World

from track_b_helpers import play_blind

T_D = chi2_threshold(0.01, 3)


def _prior(rng: np.random.Generator, batch: int = 5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    x = rng.normal(0, 3, (batch, 6))
    A = rng.normal(size=(batch, 6, 6))
    P = A @ np.swapaxes(A, -1, -2) + 0.5 * np.eye(6)
    x_pred, P_pred, Q = imu_prediction(x, P, rng.normal(0, 0.1, (batch, 3)), 1.0, 0.05**2)
    return x_pred, P_pred, Q


def test_two_identical_sub_filters_fuse_to_their_own_state():
    rng = np.random.default_rng(0)
    x_pred, P_pred, Q = _prior(rng)
    z1 = x_pred[:, :3] + rng.normal(0, 1, (5, 3))
    z = np.stack([z1, z1], axis=1)
    R = np.broadcast_to(np.eye(3) * 4.0, (5, 2, 3, 3))
    # one sub-filter alone: prior P⁻/β with β = ½, then its Kalman update
    P_i = 2.0 * P_pred
    K = P_i[:, :, :3] @ np.linalg.inv(P_i[:, :3, :3] + R[:, 0])
    x_sub = x_pred + (K @ (z1 - x_pred[:, :3])[..., None])[..., 0]
    for scheme in ("fdi", "adaptive"):
        cfg = FederatedConfig(scheme=scheme, isolate=False)
        x_g, P_g, info = federated_cycle(x_pred, P_pred, Q, z, R, np.ones((5, 2), bool), np.full((5, 2), 0.5),
                                         cfg, T_D)
        assert np.allclose(info.beta, 0.5)  # identical residuals → equal shares, R unchanged
        assert np.allclose(x_g, x_sub, atol=1e-9)  # the fusion returns their common state


def test_fault_free_equal_allocation_equals_the_centralized_kalman_filter():
    rng = np.random.default_rng(1)
    x_pred, P_pred, Q = _prior(rng)
    z = x_pred[:, None, :3] + rng.normal(0, 1, (5, 2, 3))
    R = np.stack([np.eye(3) * 100.0, np.eye(3) * 0.3])[None].repeat(5, axis=0)
    cfg = FederatedConfig(scheme="fdi", isolate=False)
    x_g, P_g, _ = federated_cycle(x_pred, P_pred, Q, z, R, np.ones((5, 2), bool), np.full((5, 2), 0.5), cfg, T_D)
    # centralized: both fixes stacked, H = [[I, 0], [I, 0]], R = blkdiag(R₁, R₂)
    H = np.vstack([np.hstack([np.eye(3), np.zeros((3, 3))])] * 2)
    Rb = np.zeros((5, 6, 6))
    Rb[:, :3, :3], Rb[:, 3:, 3:] = R[:, 0], R[:, 1]
    S = H @ P_pred @ H.T + Rb
    K = P_pred @ H.T @ np.linalg.inv(S)
    x_c = x_pred + (K @ (z.reshape(5, 6) - x_pred @ H.T)[..., None])[..., 0]
    P_c = (np.eye(6) - K @ H) @ P_pred
    assert np.allclose(x_g, x_c, atol=1e-9)
    assert np.allclose(P_g, P_c, atol=1e-9)


def test_a_faulty_sub_filter_is_isolated_and_loses_its_share():
    rng = np.random.default_rng(2)
    x_pred, P_pred, Q = _prior(rng)
    z = x_pred[:, None, :3] + rng.normal(0, 0.1, (5, 2, 3))
    z[:, 0] += 60.0  # a gross GPS error
    R = np.broadcast_to(np.eye(3), (5, 2, 3, 3))
    has = np.ones((5, 2), bool)
    x_g, _, info = federated_cycle(x_pred, P_pred, Q, z, R, has, np.full((5, 2), 0.5), FederatedConfig(), T_D)
    assert info.fault[:, 0].all() and not info.fault[:, 1].any()
    assert not info.used[:, 0].any() and info.used[:, 1].all()
    assert (info.beta[:, 0] < 0.1).all()  # adaptive share of the faulty sub-filter collapses
    assert np.allclose(info.beta.sum(axis=-1), 1.0)
    # the global estimate is the healthy sub-filter alone
    x_alone, _, _ = federated_cycle(x_pred, P_pred, Q, z, R, np.array([[False, True]] * 5),
                                    np.full((5, 2), 0.5), FederatedConfig(scheme="fdi"), T_D)
    assert np.linalg.norm(x_g[:, :3] - x_pred[:, :3], axis=-1).max() < 5.0
    assert np.isfinite(x_alone).all()


def _episode(make, seeds: list[int], poison_truth: bool = False, duration: float = 40.0, **overrides):
    spec = get_spec("GradualFault-v0", duration=duration, **overrides)
    played = play_blind(make(), spec, seeds, poison_truth)
    assert played.weights is not None and ((played.weights >= 0) & (played.weights <= 1)).all()
    return played.positions, played.truth


@pytest.mark.parametrize("make", [federated, federated_fdi])
def test_estimator_is_deterministic_batched_and_blind_to_truth(make):
    pos, truth = _episode(make, [3, 8])
    assert np.isfinite(pos).all()
    assert np.array_equal(pos, _episode(make, [3, 8], poison_truth=True)[0])
    assert np.array_equal(pos[:, 1:], _episode(make, [8])[0])
    # cooperation: followers end far closer to the truth than their 10 m GPS
    err = np.linalg.norm(pos - truth, axis=-1)[10:, :, 1:]
    assert np.sqrt((err**2).mean()) < 3.0


def test_followers_track_the_leaders_estimate_not_the_truth():
    """Shift the leader's GPS by a constant: its estimate moves, and the followers move with it."""
    pos, _ = _episode(lambda: federated(leader_cov_in_R=True), [5], duration=60.0)
    spec = get_spec("GradualFault-v0", duration=60.0)
    world = World(spec, 1)
    x0 = world.reset([5]).copy()
    facts = TaskFacts.from_spec(spec, world.layout, x0, episode_keys([5]))
    est = federated(leader_cov_in_R=True)
    est.reset(facts, facts.x0)
    shift = np.array([5.0, -4.0, 0.0])
    out = None
    for k in range(1, spec.n_steps + 1):
        buf = world.sense()
        z = buf.z.copy()
        z[:, 0, -1] += shift  # the leader's GPS slot is last
        out = est.step(Measurements.capture(buf.imu, z, buf.valid, k * spec.dt, k))
    moved = out.positions[0] - pos[-1, 0]
    assert np.allclose(moved[0], shift, atol=1.0)
    assert np.allclose(moved[1:], shift, atol=1.5)


def test_bad_inputs_are_rejected():
    with pytest.raises(ValueError, match="scheme"):
        FederatedConfig(scheme="ekf")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="p_false_alarm"):
        FederatedConfig(p_false_alarm=0.0)
    spec = get_spec("Ideal-v0")
    world = World(spec, 1)
    facts = TaskFacts.from_spec(spec, world.layout, world.reset([0]), episode_keys([0]))
    with pytest.raises(ValueError, match="GPS"):
        FederatedEstimator().reset(facts, facts.x0)


@pytest.mark.parametrize("version", [0, 1])
def test_reproduce_federated_runs_each_version(tmp_path, version):
    import json

    from swarmloc.bench.reproduce.federated import reproduce_federated

    path = reproduce_federated(tmp_path, seeds=2, version=version)
    text = path.read_text()
    assert f"GradualFault-v{version}" in text and "### Reading" in text
    raw = json.loads(path.with_suffix(".json").read_text())
    assert raw["version"] == version and len(raw["orderings"]) == 4
    if version == 1:  # the v1 reading quotes each ordering's measured difference
        assert f"{raw['orderings'][0]['mean_diff']:+.3f} m" in text
    with pytest.raises(ValueError, match="version must be one of"):
        reproduce_federated(tmp_path, seeds=2, version=2)
