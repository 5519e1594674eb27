"""AnchorFree-v0: VO buffer, UWB loss and NLOS windows, scoring alignment, MDS-MAP initializer."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

from swarmloc.agents.estimators.init.initializer import InitConfig, MdsMapInitializer, refine_with_odometry
from swarmloc.agents.protocols import Measurements, TaskFacts, episode_keys
from swarmloc.agents.registry import load_method
from swarmloc.bench.evaluation.alignment import align_estimates, yaw_translation_fit
from swarmloc.bench.evaluation.runner import _Recorder, rollout
from swarmloc.envs.tasks.channels import PEER
from swarmloc.envs.tasks.catalogue import CATALOGUE, get_spec
from swarmloc.envs.world.sim import World

TASK = "swarmloc/AnchorFree-v0"


def test_task_is_anchor_free_with_vo_and_alignment():
    spec = get_spec(TASK)
    assert TASK in CATALOGUE
    assert spec.n_uav == 6 and not spec.anchors and not spec.landmarks and not spec.sensors.gps_sigma
    assert spec.sensors.peers.sigma == 0.3 and spec.sensors.velocity_sigma is not None
    assert spec.scoring.align_first_seconds > 0 and spec.faults.nlos_uniform.low == 3.0


def test_vo_is_truth_plus_constant_bias_plus_noise_and_batch_invariant():
    spec = get_spec(TASK, duration=20.0)
    world = World(spec, 2)
    world.reset([3, 11])
    single = World(spec, 1)
    single.reset([11])
    resid = []
    for _ in range(spec.n_steps):
        buf = world.sense()
        one = single.sense()
        assert np.array_equal(buf.velocity[1], one.velocity[0])
        resid.append(buf.velocity - buf.vel - world.velocity_bias)
    resid = np.array(resid)
    assert abs(resid.std() - spec.sensors.velocity_sigma) < 0.01
    assert abs(resid.mean()) < 0.01
    assert np.abs(world.velocity_bias).max() > 0 and np.abs(world.velocity_bias).max() < 0.2
    assert World(get_spec("Ideal-v0"), 1).buffers.velocity is None  # no VO, no buffer


def test_uwb_outage_and_nlos_windows_land_where_stated():
    spec = get_spec(TASK)
    world = World(spec, 2)
    world.reset([5, 6])
    peer = world.layout.kind == PEER
    abnormal = total = 0
    for k in range(1, spec.n_steps + 1):
        buf = world.sense()
        t = k * spec.dt
        lost = 12.0 <= t + 1e-9 and t < 18.0 - 1e-9
        assert buf.valid[:, peer].any() != lost, t
        d = np.linalg.norm(buf.pos[:, :, None] - buf.pos[:, world.layout.target.clip(0)], axis=-1)
        err = np.abs(buf.z[..., 0] - d)[:, peer]
        ok = buf.valid[:, peer]
        in_nlos = (25.0 <= t < 35.0) or (42.0 <= t < 52.0)
        if not in_nlos:
            assert (err[ok] < 1.5).all(), t
        abnormal += int((err[ok] > 1.0).sum())
        total += int(ok.sum())
        assert not (buf.label & ~buf.valid).any()
    assert 0.15 < abnormal / total < 0.25  # dtvirm Table 6: 20 % abnormal


def test_yaw_translation_fit_recovers_a_rigid_motion():
    rng = np.random.default_rng(0)
    a = rng.normal(0, 5, (4, 30, 3))
    psi = np.array([0.3, -2.0, 1.0, 0.0])
    R = np.zeros((4, 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = np.cos(psi), -np.sin(psi), np.sin(psi), np.cos(psi), 1
    t = rng.normal(0, 10, (4, 3))
    b = np.einsum("bij,bmj->bmi", R, a) + t[:, None]
    R_fit, t_fit = yaw_translation_fit(a, b)
    assert np.allclose(R_fit, R) and np.allclose(t_fit, t)
    with pytest.raises(ValueError, match="positive weight"):
        yaw_translation_fit(a, b, np.zeros((4, 30)))


def test_runner_scores_after_the_first_second_alignment():
    spec = get_spec(TASK, duration=6.0)
    n_t, B, N = spec.n_steps, 2, spec.n_uav
    times = spec.dt * np.arange(1, n_t + 1)
    rng = np.random.default_rng(1)
    truth = np.cumsum(rng.normal(0, 0.3, (n_t, B, N, 3)), axis=0)
    psi = 0.7
    R = np.array([[np.cos(psi), -np.sin(psi), 0], [np.sin(psi), np.cos(psi), 0], [0, 0, 1]])
    est = truth @ R.T + np.array([4.0, -3.0, 1.0])  # a frame of its own, otherwise exact
    late = times >= 4.0
    est[late] += np.array([0.5, 0.0, 0.0])  # drift after the alignment window counts
    assert np.allclose(align_estimates(spec, times, est, truth)[~late], truth[~late])
    rec = _Recorder(spec, np.array([0, 1]), None, 5, False, False, False)
    for k in range(n_t):
        rec.record(k, est[k], truth[k], np.zeros((B, N, 5), bool), np.zeros((B, N, 5), bool), None, None, None)
    m = rec.episode_metrics(0)
    scored = (times >= spec.scoring.start).sum()
    assert m["rmse"] == pytest.approx(0.5 * np.sqrt(late.sum() / scored), rel=1e-9)


def test_mdsmap_initializer_recovers_the_layout_up_to_the_unobservable_motion():
    seeds = list(range(2_000_000, 2_000_006))
    spec = get_spec(TASK, duration=3.0)
    world = World(spec, len(seeds))
    x0 = world.reset(seeds).copy()
    facts = TaskFacts.from_spec(spec, world.layout, x0, episode_keys(seeds))
    init = MdsMapInitializer(facts, InitConfig(window=2.0))
    first = None
    k = 0
    while not init.ready:
        k += 1
        buf = world.sense()
        first = buf.pos[:, :1].copy() if first is None else first
        init.observe(Measurements.capture(buf.imu, buf.z, buf.valid, k * spec.dt, k, buf.velocity))
    x = init.solve()
    truth = buf.pos - first  # dtvirm's frame: node 0's first position is the origin
    R, t = yaw_translation_fit(x[..., :3], truth)
    shape_err = np.linalg.norm(np.einsum("bij,bnj->bni", R, x[..., :3]) + t[:, None] - truth, axis=-1)
    yaw = np.degrees(np.abs(np.arctan2(R[:, 1, 0], R[:, 0, 0])))
    assert np.median(shape_err.mean(axis=1)) < 0.8
    assert np.median(yaw) < 5.0
    assert np.median(np.linalg.norm(x[..., :3] - truth, axis=-1)) < 1.5  # no alignment at all


def test_odometry_refinement_fixes_a_perturbed_layout():
    rng = np.random.default_rng(4)
    K, N = 10, 5
    p = rng.uniform(-10, 10, (N, 3))
    p[:, 2] = 0.0
    p[0] = 0.0
    disp = np.cumsum(rng.normal(0, 0.3, (K, N, 3)), axis=0)
    disp[0] = 0.0
    q = p[None] + disp
    D = np.linalg.norm(q[:, :, None] - q[:, None], axis=-1)
    guess = p + rng.normal(0, 1.0, p.shape) * np.r_[0, 1, 1, 1, 1][:, None]
    guess[:, 2] = 0.0
    fit, cost = refine_with_odometry(guess, D, disp, 0.1, 1.0, 50)
    assert np.abs(fit - p).max() < 1e-4 and cost < 1e-6


def test_spec_rejects_inconsistent_vo_and_alignment():
    with pytest.raises(ValidationError, match="velocity_sigma"):
        get_spec(TASK, sensors={"velocity_sigma": None})
    with pytest.raises(ValidationError, match="align_first_seconds"):
        get_spec(TASK, scoring={"align_first_seconds": 100.0})
    with pytest.raises(ValidationError, match="start < end"):
        get_spec(TASK, faults={"uwb_outage": {"windows": ((5.0, 2.0),)}})


def test_ci_ekf_runs_through_the_runner_with_vo():
    metrics, _ = rollout(load_method("ci-ekf"), get_spec(TASK, duration=8.0), [1_000_000])
    assert metrics[0]["rmse"] < 2.0 and metrics[0]["anomaly_detection_rate"] is None


def test_odometry_refinement_reaches_scipy_least_squares_optimum_with_noise_and_gaps():
    """The block-accumulated normal equations solve the same problem as a generic solver."""
    from scipy.optimize import least_squares

    rng = np.random.default_rng(7)
    K, N, sigma, sigma_z = 12, 9, 0.1, 1.0
    p = rng.uniform(-10, 10, (N, 3))
    p[0] = 0.0
    disp = np.cumsum(rng.normal(0, 0.3, (K, N, 3)), axis=0)
    disp[0] = 0.0
    q = p[None] + disp
    D = np.linalg.norm(q[:, :, None] - q[:, None], axis=-1) + rng.normal(0, sigma, (K, N, N))
    D[rng.random(D.shape) < 0.3] = np.nan  # dropped ranges
    guess = p + rng.normal(0, 0.5, p.shape)
    guess[0] = 0.0
    fit, cost = refine_with_odometry(guess, D, disp, sigma, sigma_z, 100)

    k, i, j = np.nonzero(np.isfinite(D) & ~np.eye(N, dtype=bool)[None])

    def residuals(x):
        pos = np.vstack([np.zeros(3), x.reshape(N - 1, 3)])
        qq = pos[None] + disp
        ranges = np.linalg.norm(qq[k, i] - qq[k, j], axis=-1)
        return np.r_[(ranges - D[k, i, j]) / sigma, pos[1:, 2] / sigma_z]

    ref = least_squares(residuals, guess[1:].ravel(), xtol=1e-14, ftol=1e-14, gtol=1e-14)
    np.testing.assert_allclose(fit[1:].ravel(), ref.x, atol=1e-6)
    assert cost == pytest.approx(2 * ref.cost, rel=1e-9)
