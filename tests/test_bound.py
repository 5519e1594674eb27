"""The information bound: closed forms, the CEKF in the linear case, fast == reference, labels, caching."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from swarmloc.bench.evaluation import bounds as BB
from swarmloc.bench.evaluation.recorder import EpisodeRecorder
from swarmloc.bench.evaluation.suites import Suite
from swarmloc.envs import cekf
from swarmloc.envs.bound import BoundInputs, BoundRecorder, pcrlb, record_inputs
from swarmloc.envs.bound_reference import pcrlb_reference
from swarmloc.envs.cekf_reference import run_reference
from swarmloc.envs.channels import ANCHOR, GPS
from swarmloc.envs.tasks import SIX_ANCHORS, get_spec
from swarmloc.envs.trust_env import TrustEnvBatch
from swarmloc.envs.world import World


def synthetic(kinds, targets, r0, pos, *, dt=0.1, imu_sigma=0.1, p0=(0.25, 0.04), anchors=SIX_ANCHORS, use=None):
    """One UAV (N = 1) with the given channels, at ``pos`` ``(T, 3)``, every channel used."""
    n_t = len(pos)
    kind = np.array([kinds], dtype=np.int64)
    return BoundInputs(
        dt=dt, imu_sigma=imu_sigma, p0_diag=np.array([p0[0]] * 3 + [p0[1]] * 3), kind=kind,
        target=np.array([targets], dtype=np.int64), r0=np.array([r0], dtype=float),
        anchors=np.asarray(anchors, dtype=float).reshape(-1, 3), landmarks=np.zeros((0, 3)),
        pos=np.asarray(pos, dtype=float).reshape(n_t, 1, 1, 3),
        use=np.ones((n_t, 1, 1, kind.shape[1]), dtype=bool) if use is None else use)


def anchor_information(p, anchors, sigma):
    """HᵀR⁻¹H of ranges from p to the anchors: Σ u uᵀ / σ²."""
    u = (p - np.asarray(anchors)) / np.linalg.norm(p - np.asarray(anchors), axis=1, keepdims=True)
    return u.T @ u / sigma**2


def test_static_uav_single_snapshot_is_inverse_fisher_information():
    # one step with a vanishing prior: the bound is tr (HᵀR⁻¹H)⁻¹ of the anchor ranges
    p, sigma = np.array([12.0, 7.0, 2.0]), 0.15
    inputs = synthetic([ANCHOR] * 6, range(6), [sigma**2] * 6, [p], p0=(1e8, 1e8))
    expected = np.trace(np.linalg.inv(anchor_information(p, SIX_ANCHORS, sigma)))
    assert pcrlb(inputs).pos_var[0, 0, 0] == pytest.approx(expected, rel=1e-6)
    assert pcrlb_reference(inputs).pos_var[0, 0, 0] == pytest.approx(expected, rel=1e-6)


def test_static_uav_accumulates_information():
    # a UAV known to be still (no process noise, velocity known): J_K = P₀⁻¹ + K HᵀR⁻¹H
    p, sigma, n_t, p0 = np.array([3.0, 20.0, 1.0]), 0.15, 50, 0.25
    inputs = synthetic([ANCHOR] * 6, range(6), [sigma**2] * 6, [p] * n_t, imu_sigma=0.0, p0=(p0, 1e-14))
    lam = anchor_information(p, SIX_ANCHORS, sigma)
    out = pcrlb(inputs).pos_var[:, 0, 0]
    for k in (0, 9, n_t - 1):
        assert out[k] == pytest.approx(np.trace(np.linalg.inv(np.eye(3) / p0 + (k + 1) * lam)), rel=1e-7)


def test_constant_velocity_riccati_steady_state():
    # position fixes, constant-acceleration model: the bound converges to the DARE solution per axis
    dt, q, sigma = 0.1, 0.3, 0.5
    inputs = synthetic([GPS], [-1], [sigma**2], np.zeros((1500, 3)), dt=dt, imu_sigma=q)
    F = np.array([[1.0, dt], [0.0, 1.0]])
    G = np.array([[dt * dt / 2], [dt]])
    H = np.array([[1.0, 0.0]])
    # a-priori covariance: P⁻ = F P⁻ Fᵀ − F P⁻ Hᵀ (H P⁻ Hᵀ + R)⁻¹ H P⁻ Fᵀ + Q
    P_prior = scipy.linalg.solve_discrete_are(F.T, H.T, q**2 * G @ G.T, np.array([[sigma**2]]))
    # a-posteriori position variance: P⁻ − P⁻Hᵀ (H P⁻ Hᵀ + R)⁻¹ H P⁻
    p_post = P_prior[0, 0] - P_prior[0, 0] ** 2 / (P_prior[0, 0] + sigma**2)
    assert pcrlb(inputs).pos_var[-1, 0, 0] == pytest.approx(3 * p_post, rel=1e-9)


def test_linear_single_uav_bound_equals_cekf_covariance():
    # GPS only: the CEKF is a Kalman filter, which attains the bound, so its P is J⁻¹
    spec = get_spec("swarmloc/Ideal-v0", n_uav=1, duration=20.0, anchors=(),
                    sensors={"gps_sigma": (0.4,), "peers": {"kind": "none"}})
    inputs, _ = record_inputs(spec, [5])
    bound = pcrlb(inputs).pos_var[-1, 0, 0]
    world = World(spec, 1)
    x = world.reset([5]).copy()
    imu, z, valid = [], [], []
    for _ in range(spec.n_steps):
        buf = world.sense()
        imu.append(buf.imu.copy())
        z.append(buf.z.copy())
        valid.append(buf.valid.copy())
    imu, z, valid = np.array(imu), np.array(z), np.array(valid)
    P0 = cekf.initial_covariance(1, 1, spec.filter.init_pos_sigma, spec.filter.init_vel_sigma)
    lay = world.layout
    # the reference CEKF (the fused kernel is held equal to it in test_cekf.py)
    _, _, P = run_reference(x, P0, imu, z, valid, np.ones(valid.shape), lay.kind, lay.target, lay.r0,
                            world.anchors, world.landmarks, spec.dt, spec.sensors.imu_sigma, spec.filter.alpha_th,
                            spec.filter.alpha_min)
    assert np.trace(P[0, 0, :3, :3]) == pytest.approx(bound, rel=1e-9)


@pytest.mark.parametrize("task_id", ["swarmloc/Ideal-v0", "swarmloc/Scale4-v0", "swarmloc/CascadedFaultRandom-v0",
                                     "swarmloc/VisionLoss-v0", "swarmloc/HybridNoise30-v0", "swarmloc/GradualFault-v0"])
def test_fast_matches_reference(task_id):
    base = get_spec(task_id)
    # a window with faults where the task has them: CascadedFaultRandom's start in [15, 25] s
    start = {"swarmloc/CascadedFaultRandom-v0": 24.0, "swarmloc/GradualFault-v0": 95.0}.get(task_id, 0.0)
    spec = get_spec(task_id, duration=start + 30 * base.dt)
    inputs, _ = record_inputs(spec, [1_000_000, 1_000_001])
    keep = slice(round(start / base.dt), None)
    inputs = inputs._replace(pos=inputs.pos[keep], use=inputs.use[keep])
    # random channel dropout exercises every exclusion path on top of the world's own
    rng = np.random.default_rng(3)
    inputs = inputs._replace(use=inputs.use & (rng.uniform(size=inputs.use.shape) > 0.2))
    fast, ref = pcrlb(inputs), pcrlb_reference(inputs)
    assert (fast.failed_at == -1).all() and (ref.failed_at == -1).all()
    np.testing.assert_allclose(fast.pos_var, ref.pos_var, rtol=1e-9, atol=0)


def test_failure_is_reported_not_returned():
    # a negative variance makes the information indefinite: no number, the step is named
    inputs = synthetic([ANCHOR] * 6, range(6), [0.02] * 5 + [-1e-4], [np.array([3.0, 4.0, 1.0])] * 5)
    for out in (pcrlb(inputs), pcrlb_reference(inputs)):
        assert out.failed_at.tolist() == [0]
        assert np.isnan(out.pos_var).all()


def test_labelled_measurements_raise_the_bound():
    # NLOSStep: anchor 0 is biased by 3 m from 20 to 30 s; leaving it out can only raise the bound
    spec = get_spec("swarmloc/NLOSStep-v0", duration=24.0)
    labelled, _ = record_inputs(spec, [1_000_000])
    unlabelled, _ = record_inputs(spec, [1_000_000], label_sigmas=np.inf)
    assert labelled.use.sum() < unlabelled.use.sum()
    with_labels, without = pcrlb(labelled).pos_var, pcrlb(unlabelled).pos_var
    assert (with_labels >= without * (1 - 1e-12)).all()
    fault = spec.dt * np.arange(1, spec.n_steps + 1) >= 20.0
    assert (with_labels[fault] > without[fault]).all()


def test_undefined_tasks_are_null_with_a_reason():
    free, = BB.episode_bounds("swarmloc/AnchorFree-v0", [1_000_000], persistent=False)
    assert free.rmse is None and free.healthy_rmse is None and "unobservable" in free.reason
    util, = BB.episode_bounds("swarmloc/UTILFlight-v0", [1_000_000], persistent=False)
    assert util.rmse is None and "recorded" in util.reason


HEALTHY_PER_EPISODE = {"nodes_from_schedule": "healthy"}


@pytest.mark.parametrize("task_id, scoring", [
    ("swarmloc/CascadedFault-v0", {}), ("swarmloc/CascadedFaultRandom-v0", {}),
    ("swarmloc/CascadedFaultRandom-v0", HEALTHY_PER_EPISODE), ("swarmloc/AnchorFree-v0", {}),
    ("swarmloc/HybridNoise10-v0", {})])
def test_scored_steps_and_uavs_match_the_recorder(task_id, scoring):
    spec = get_spec(task_id, scoring=scoring)
    seeds = np.array([1_000_000, 1_000_001, 1_000_002])
    world = World(spec, len(seeds))
    world.reset(seeds)
    rec = EpisodeRecorder(spec, seeds, world.schedule, world.layout.n_channels, False, False, False)
    for b in range(len(seeds)):
        steps, nodes = BB.scored_selection(spec, world.schedule, b)
        assert (steps == rec.scored_steps).all() and (nodes == rec.nodes[b]).all()
        if scoring:  # each episode scores exactly the UAVs its schedule leaves without an IMU fault
            assert (nodes == ~world.schedule.faulty_nodes[b]).all() and nodes.sum() == 2
    if scoring:
        assert len({tuple(row) for row in rec.nodes}) > 1, "these seeds should draw different faulty UAVs"


def test_bound_with_per_episode_healthy_scoring_is_over_the_episodes_healthy_uavs():
    spec = get_spec("swarmloc/CascadedFaultRandom-v0", duration=26.0, scoring=HEALTHY_PER_EPISODE)
    seeds = [1_000_000, 1_000_001]
    inputs, world = record_inputs(spec, seeds)
    pos_var = pcrlb(inputs).pos_var
    bounds = BB.bounds_from_inputs(spec, seeds, inputs, world.schedule)
    for b, bound in enumerate(bounds):
        healthy = ~world.schedule.faulty_nodes[b]
        assert bound.rmse == pytest.approx(np.sqrt(pos_var[:, b][:, healthy].mean()), rel=1e-12)
    # the same episodes scored over every UAV (v0's selection) have another bound
    every = BB.compute_bounds(get_spec("swarmloc/CascadedFaultRandom-v0", duration=26.0), seeds)
    assert all(a.rmse != b.rmse for a, b in zip(bounds, every))


def test_bounds_are_cached_per_process_and_on_disk(tmp_path, monkeypatch):
    monkeypatch.setenv(BB.CACHE_ENV, str(tmp_path))
    BB.clear_memory_cache()
    spec = get_spec("swarmloc/CascadedFault-v0", duration=25.0)
    first = BB.episode_bounds(spec, [7, 8])
    assert first[0].rmse > 0 and first[0].healthy_rmse > 0 and first[0].reason is None
    assert len(list((tmp_path / "bounds").rglob("*.json"))) == 1

    def no_compute(*args, **kwargs):
        raise AssertionError("the cached bound was computed again")

    monkeypatch.setattr(BB, "compute_bounds", no_compute)
    assert BB.episode_bounds(spec, [8, 7]) == first[::-1]  # per process
    BB.clear_memory_cache()
    assert BB.episode_bounds(spec, [7, 8]) == first  # from the file
    suite = Suite("two", "0", (("swarmloc/AnchorFree-v0", 7),))
    monkeypatch.undo()
    assert BB.suite_bounds(suite, persistent=False)[("swarmloc/AnchorFree-v0", 7)].rmse is None


def test_bounds_from_a_rollouts_world_equal_the_standalone_ones():
    # a runner that steps a world already (the uniform rollout) can record the bound's inputs
    # from it: the world holds the pending step after the reset and after each update
    spec = get_spec("swarmloc/CascadedFaultRandom-v0", duration=26.0)
    seeds = [1_000_000, 1_000_003]
    env = TrustEnvBatch(spec, len(seeds))
    env.reset(np.array(seeds))
    world = env.core.world
    rec = BoundRecorder(spec, env.layout, world.anchors, world.landmarks, len(seeds))
    for k in range(spec.n_steps):
        rec.record(world.buffers.pos, world.buffers.valid, world.buffers.injected)
        env.step(np.ones((len(seeds), spec.n_uav, env.layout.n_channels)))
    shared = BB.bounds_from_inputs(spec, seeds, rec.inputs(), world.schedule)
    assert shared == BB.compute_bounds(spec, seeds)
    assert all(b.healthy_rmse is not None for b in shared)
