"""CI-EKF (dtvirm §3.6–3.7): cooperative range update, UWB adaptive adjustment, the estimator.

Covariance intersection itself is tested in ``test_fusion.py``.
"""

from __future__ import annotations

import numpy as np
import pytest

from swarmloc.agents.estimators.ci_ekf import CiEkfConfig, CiEkfEstimator, ci_ekf, ci_ekf_no_aa, range_update, velocity_update
from swarmloc.agents.protocols import TaskFacts, UnsupportedTask, episode_keys
from swarmloc.bench.evaluation.alignment import align_estimates
from swarmloc.envs.tasks.catalogue import get_spec
from swarmloc.envs.world.sim import World

from track_b_helpers import play_blind

N = 4


def _swarm(rng: np.random.Generator, B: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Estimates x, P of N UAVs, all-pairs target table (N, N−1) and the exact ranges."""
    x = np.zeros((B, N, 6))
    x[..., :3] = rng.uniform(-10, 10, (B, N, 3))
    P = np.broadcast_to(np.diag([0.2, 0.2, 0.2, 0.05, 0.05, 0.05]), (B, N, 6, 6)).copy()
    target = np.array([[j for j in range(N) if j != i] for i in range(N)])
    d = np.linalg.norm(x[:, :, None, :3] - x[:, target, :3], axis=-1)
    return x, P, target, d


def test_consistent_ranges_leave_the_estimates_and_weights_alone():
    x, P, target, d = _swarm(np.random.default_rng(0))
    valid = np.ones(d.shape, bool)
    x_new, P_new, info = range_update(x, P, d, valid, target, np.full(target.shape, 0.3), CiEkfConfig())
    assert np.allclose(x_new, x)
    assert np.allclose(info.weight, 1.0)
    assert (np.linalg.eigvalsh(P[..., :3, :3] - P_new[..., :3, :3]) > -1e-12).all()  # information only grows


def test_an_nlos_range_is_down_weighted_only_with_the_adjustment():
    x, P, target, d = _swarm(np.random.default_rng(1))
    d = d.copy()
    d[:, 0, 1] += 4.0  # NLOS on one link of UAV 0
    valid = np.ones(d.shape, bool)
    sigma = np.full(target.shape, 0.3)
    x_aa, _, info = range_update(x, P, d, valid, target, sigma, CiEkfConfig())
    x_no, _, info_no = range_update(x, P, d, valid, target, sigma, CiEkfConfig(adaptive_adjustment=False))
    assert (info.weight[:, 0, 1] < 1e-6).all()
    mask = np.ones(d.shape, bool)
    mask[:, 0, 1] = False
    assert np.allclose(info.weight[mask], 1.0)
    assert np.allclose(info_no.weight, 1.0)
    move_aa = np.linalg.norm(x_aa[:, 0, :3] - x[:, 0, :3], axis=-1)
    move_no = np.linalg.norm(x_no[:, 0, :3] - x[:, 0, :3], axis=-1)
    assert (move_aa < 1e-3).all() and (move_no > 0.1).all()


def test_neighbour_noise_uses_the_ci_covariance():
    x, P, target, d = _swarm(np.random.default_rng(2))
    P = P.copy()
    P[:, 1, :3, :3] *= 25.0  # UAV 1 is far less certain than the others
    valid = np.ones(d.shape, bool)
    sigma = np.full(target.shape, 0.3)
    _, _, ci = range_update(x, P, d, valid, target, sigma, CiEkfConfig(ci=True))
    _, _, plain = range_update(x, P, d, valid, target, sigma, CiEkfConfig(ci=False))
    # R = σ² + h P hᵀ with P = P_j (plain) ⪰ P_CI: the CI bound never exceeds the larger input
    assert (ci.R <= plain.R + 1e-12).all()
    assert np.allclose(plain.R[:, 0, 0], 0.09 + 25 * 0.2)  # slot 0 of UAV 0 is UAV 1
    assert (ci.R[:, 0, 0] < plain.R[:, 0, 0]).all()


def test_velocity_update_matches_the_closed_form():
    x = np.zeros((1, 6))
    P = np.diag([1.0, 1.0, 1.0, 0.5, 0.5, 0.5])[None]
    x_new, P_new = velocity_update(x, P, np.array([[1.0, -2.0, 0.0]]), 0.5)
    assert np.allclose(x_new[0, 3:], [0.5, -1.0, 0.0])  # K = P_vv / (P_vv + r) = ½
    assert np.allclose(np.diag(P_new[0])[3:], 0.25) and np.allclose(x_new[0, :3], 0.0)


def _episode(make, seeds, poison_truth=False, **overrides):
    spec = get_spec("AnchorFree-v0", **overrides)
    played = play_blind(make(), spec, seeds, poison_truth)
    return spec, played.positions, played.truth, played.weights


def test_estimator_is_deterministic_batched_and_blind_to_truth():
    _, pos, _, _ = _episode(ci_ekf, [1, 6], duration=4.0)
    assert np.isfinite(pos).all()
    assert np.array_equal(pos, _episode(ci_ekf, [1, 6], poison_truth=True, duration=4.0)[1])
    assert np.array_equal(pos[:, 1:], _episode(ci_ekf, [6], duration=4.0)[1])


def test_adaptive_adjustment_beats_the_ablation_under_nlos():
    nlos = {"nlos_uniform": {"windows": ((4.0, 9.0),)}, "uwb_outage": None}
    rmse = {}
    for name, make in (("ci-ekf", ci_ekf), ("no-aa", ci_ekf_no_aa)):
        spec, pos, truth, _ = _episode(make, [2_000_000, 2_000_001], duration=10.0, faults=nlos)
        t = np.arange(1, spec.n_steps + 1) * spec.dt
        e = np.linalg.norm(align_estimates(spec, t, pos, truth) - truth, axis=-1)[t >= spec.scoring.start]
        rmse[name] = np.sqrt((e**2).mean())
    assert rmse["ci-ekf"] < 0.7 * rmse["no-aa"], rmse


def test_bad_config_and_tasks_are_rejected():
    with pytest.raises(ValueError, match="aa_confidence"):
        CiEkfConfig(aa_confidence=1.0)
    with pytest.raises(ValueError, match="init"):
        CiEkfConfig(init="gps")  # type: ignore[arg-type]
    for task, why in (("GradualFault-v0", "fuses peer ranges; task swarmloc/GradualFault-v0 has none"),
                      ("Scale8-v1", r"anchor-free: .* task swarmloc/Scale8-v1 has absolute references \(anchor\)"),
                      ("Indoor-v1", r"absolute references \(landmark\)")):
        spec = get_spec(task)
        world = World(spec, 1)
        facts = TaskFacts.from_spec(spec, world.layout, world.reset([0]), episode_keys([0]), anchors=world.anchors)
        with pytest.raises(UnsupportedTask, match=why):
            CiEkfEstimator().reset(facts, facts.x0)
