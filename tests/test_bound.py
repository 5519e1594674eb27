"""The information bound: closed forms, the CEKF in the linear case, peer ranges against a centralised KF and
the CEKF, the planar-ranging limit, fast == reference, labels, caching."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from swarmloc.bench.scoring import bounds as BB
from swarmloc.bench.evaluation.recorder import EpisodeRecorder
from swarmloc.bench.evaluation.suites import Suite
from swarmloc.envs.filter import cekf
from swarmloc.envs.filter.bound import BoundInputs, BoundRecorder, pcrlb, record_inputs
from swarmloc.envs.filter.bound_reference import pcrlb_reference
from swarmloc.envs.filter.cekf_reference import run_reference
from swarmloc.envs.tasks.channels import ANCHOR, GPS, LANDMARK, PEER
from swarmloc.envs.tasks.catalogue import SIX_ANCHORS, get_spec
from swarmloc.envs.adapters.trust_env import TrustEnvBatch
from swarmloc.envs.world.sim import World


def synthetic(kinds, targets, r0, pos, *, dt=0.1, imu_sigma=0.1, p0=(0.25, 0.04), anchors=SIX_ANCHORS, use=None):
    """One UAV (N = 1) with the given channels, at ``pos`` ``(T, 3)``, every channel used."""
    n_t = len(pos)
    kind = np.array([kinds], dtype=np.int64)
    return BoundInputs(
        dt=dt, imu_sigma=imu_sigma, bias_sigma=0.0, fault_var=np.zeros((n_t, 1, 1)),
        p0_diag=np.array([p0[0]] * 3 + [p0[1]] * 3), kind=kind,
        target=np.array([targets], dtype=np.int64), r0=np.array([r0], dtype=float),
        anchors=np.asarray(anchors, dtype=float).reshape(-1, 3), landmarks=np.zeros((0, 3)),
        pos=np.asarray(pos, dtype=float).reshape(n_t, 1, 1, 3),
        use=np.ones((n_t, 1, 1, kind.shape[1]), dtype=bool) if use is None else use)


def expected_outer(d, S):
    """E[u uᵀ], u = x/‖x‖, x ~ N(d, S), by the six-point cubature rule (points d ± √3 L e_c, L = chol S)."""
    L = np.linalg.cholesky(S)
    pts = [d + sg * np.sqrt(3.0) * L[:, c] for c in range(3) for sg in (1.0, -1.0)]
    return sum(np.outer(x, x) / (x @ x) for x in pts) / 6.0


def anchor_information(p, anchors, sigma, S=None):
    """HᵀR⁻¹H of ranges from p to the anchors: Σ u uᵀ / σ² at p, or its expectation over p ~ N(p, S)."""
    if S is None:
        u = (p - np.asarray(anchors)) / np.linalg.norm(p - np.asarray(anchors), axis=1, keepdims=True)
        return u.T @ u / sigma**2
    return sum(expected_outer(p - a, S) for a in np.asarray(anchors)) / sigma**2


def test_static_uav_single_snapshot_is_the_expected_fisher_information():
    # one step: J₁ = (C⁻)⁻¹ + E[HᵀR⁻¹H], the expectation over p ~ N(p, C⁻) with C⁻ = (p0 + dt²·v0) I
    p, sigma, dt, p0, v0 = np.array([12.0, 7.0, 2.0]), 0.15, 0.1, 4.0, 1.0
    inputs = synthetic([ANCHOR] * 6, range(6), [sigma**2] * 6, [p], dt=dt, imu_sigma=0.0, p0=(p0, v0))
    prior = (p0 + dt * dt * v0) * np.eye(3)
    expected = np.trace(np.linalg.inv(np.linalg.inv(prior) + anchor_information(p, SIX_ANCHORS, sigma, prior)))
    assert pcrlb(inputs).pos_var[0, 0, 0] == pytest.approx(expected, rel=1e-9)
    assert pcrlb_reference(inputs).pos_var[0, 0, 0] == pytest.approx(expected, rel=1e-9)
    # a prior this wide spreads the ranges' directions: the bound is not the inverse Fisher information at the truth
    at_truth = np.trace(np.linalg.inv(np.linalg.inv(prior) + anchor_information(p, SIX_ANCHORS, sigma)))
    assert abs(expected / at_truth - 1) > 1e-3


def test_static_uav_accumulates_information():
    # a UAV known to be still (no process noise, velocity known): C_k = (C_{k−1}⁻¹ + E_{C_{k−1}}[HᵀR⁻¹H])⁻¹,
    # which tends to the inverse of P₀⁻¹ + K HᵀR⁻¹H at the truth as the spread shrinks
    p, sigma, n_t, p0 = np.array([3.0, 20.0, 1.0]), 0.15, 50, 0.25
    inputs = synthetic([ANCHOR] * 6, range(6), [sigma**2] * 6, [p] * n_t, imu_sigma=0.0, p0=(p0, 1e-14))
    out, ref = pcrlb(inputs).pos_var[:, 0, 0], pcrlb_reference(inputs).pos_var[:, 0, 0]
    C = p0 * np.eye(3)
    for k in range(n_t):
        C = np.linalg.inv(np.linalg.inv(C) + anchor_information(p, SIX_ANCHORS, sigma, C))
        assert out[k] == pytest.approx(np.trace(C), rel=1e-7) and ref[k] == pytest.approx(np.trace(C), rel=1e-7)
    lam = anchor_information(p, SIX_ANCHORS, sigma)
    assert out[-1] == pytest.approx(np.trace(np.linalg.inv(np.eye(3) / p0 + n_t * lam)), rel=1e-2)


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
                                     "swarmloc/VisionLoss-v0", "swarmloc/HybridNoise30-v0", "swarmloc/GradualFault-v0",
                                     "swarmloc/Indoor-v1", "swarmloc/CascadedFault-v1", "swarmloc/TDOA-v1"])
def test_fast_matches_reference(task_id):
    base = get_spec(task_id)
    # a window with faults where the task has them: CascadedFaultRandom's start in [15, 25] s, the
    # onset of CascadedFault-v1's IMU fault (with Indoor-v1, the accelerometer bias states)
    start = {"swarmloc/CascadedFaultRandom-v0": 24.0, "swarmloc/GradualFault-v0": 95.0,
             "swarmloc/CascadedFault-v1": base.faults.imu_cascades[0].start - 1.0
             if base.faults.imu_cascades else 0.0}.get(task_id, 0.0)
    spec = get_spec(task_id, duration=start + 30 * base.dt)
    inputs, _ = record_inputs(spec, [1_000_000, 1_000_001])
    keep = slice(round(start / base.dt), None)
    inputs = inputs._replace(pos=inputs.pos[keep], use=inputs.use[keep], fault_var=inputs.fault_var[keep])
    if task_id == "swarmloc/CascadedFault-v1":
        assert (inputs.fault_var[0] == 0).all() and (inputs.fault_var[-1] > 0).any()
    if task_id == "swarmloc/Indoor-v1":
        assert inputs.bias_sigma > 0
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


# --------------------------------------------------------------------------- peer ranges: a centralised KF, the CEKF


def swarm_inputs(truth, kind, target, r0, use, landmarks, *, dt=0.1, imu_sigma=0.1, p0=(0.25, 0.04)):
    """N UAVs (one episode) at ``truth`` ``(T, N, 3)`` with per-UAV channels ``(N, L)`` used where ``use`` ``(N, L)``."""
    n_t, n = truth.shape[:2]
    return BoundInputs(
        dt=dt, imu_sigma=imu_sigma, bias_sigma=0.0, fault_var=np.zeros((n_t, 1, n)),
        p0_diag=np.array([p0[0]] * 3 + [p0[1]] * 3),
        kind=np.asarray(kind, dtype=np.int64), target=np.asarray(target, dtype=np.int64),
        r0=np.asarray(r0, dtype=float), anchors=np.zeros((0, 3)), landmarks=np.asarray(landmarks, dtype=float),
        pos=np.ascontiguousarray(truth, dtype=float).reshape(n_t, 1, n, 3),
        use=np.ascontiguousarray(np.broadcast_to(use, (n_t, 1) + np.shape(use))))


def joint_kalman_covariance(inputs, expected=True):
    """Posterior covariances ``(T, 6N, 6N)`` of a centralised filter over the joint state, plain dense numpy.

    UAV-major state [p_0, v_0, p_1, v_1, …]; a peer range is one row with uᵀ on the receiver's
    position and −uᵀ on the neighbour's, a landmark −I on the receiver's. ``expected=False``:
    the Kalman filter linearised at the TRUE positions (u between them), every update in
    Joseph form. ``expected=True``: the bound's information form, P⁺ = (P⁻⁻¹ + Σ E[HᵀR⁻¹H])⁻¹
    with a range's E[u uᵀ] over d = p_i − p_j ~ N(truth, P⁻) (``expected_outer``). Episode 0.
    """
    n = inputs.pos.shape[2]
    dt, q = inputs.dt, inputs.imu_sigma**2
    F1 = np.block([[np.eye(3), dt * np.eye(3)], [np.zeros((3, 3)), np.eye(3)]])
    G1 = np.vstack([dt * dt / 2 * np.eye(3), dt * np.eye(3)])
    F, Q = np.kron(np.eye(n), F1), np.kron(np.eye(n), q * G1 @ G1.T)
    P = np.diag(np.tile(inputs.p0_diag, n))
    out = []
    for k in range(inputs.pos.shape[0]):
        P = F @ P @ F.T + Q
        pos, rows, var, info = inputs.pos[k, 0], [], [], np.zeros((6 * n, 6 * n))
        for i, l in zip(*np.nonzero(inputs.use[k, 0])):
            j = inputs.target[i, l]
            if inputs.kind[i, l] == PEER:
                u = (pos[i] - pos[j]) / np.linalg.norm(pos[i] - pos[j])
                h = np.zeros((1, 6 * n))
                h[0, 6 * i:6 * i + 3], h[0, 6 * j:6 * j + 3] = u, -u
                sel = np.zeros((3, 6 * n))
                sel[:, 6 * i:6 * i + 3], sel[:, 6 * j:6 * j + 3] = np.eye(3), -np.eye(3)
                info += sel.T @ expected_outer(pos[i] - pos[j], sel @ P @ sel.T) @ sel / inputs.r0[i, l]
            else:
                assert inputs.kind[i, l] == LANDMARK
                h = np.zeros((3, 6 * n))
                h[:, 6 * i:6 * i + 3] = -np.eye(3)
                info += h.T @ h / inputs.r0[i, l]
            rows.append(h)
            var += [inputs.r0[i, l]] * len(h)
        if expected:
            P = np.linalg.inv(np.linalg.inv(P) + info)
            P = 0.5 * (P + P.T)
        elif rows:
            H, R = np.vstack(rows), np.diag(var)
            K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
            A = np.eye(6 * n) - K @ H
            P = A @ P @ A.T + K @ R @ K.T
        out.append(P)
    return np.array(out)


def cekf_monte_carlo(inputs, vel, n_episodes, seed):
    """Squared position errors ``(T, B, N, 3)`` of the CEKF (α = 1) on B synthetic episodes of ``inputs``' truth.

    The UAVs fly at constant velocity ``vel`` ``(N, 3)`` (the IMU reads only its noise); every
    channel in ``use`` is measured with its nominal σ; the initial estimate is the truth at
    t = 0 perturbed by P₀, as ``World`` draws it.
    """
    truth = inputs.pos[:, 0]
    n_t, n = truth.shape[:2]
    n_l = inputs.kind.shape[1]
    rng = np.random.default_rng(seed)
    sd0 = np.sqrt(inputs.p0_diag)
    x = np.concatenate([truth[0] - inputs.dt * vel, vel], axis=1) + sd0 * rng.standard_normal((n_episodes, n, 6))
    P = cekf.initial_covariance(n_episodes, n, sd0[0], sd0[3])
    imu = inputs.imu_sigma * rng.standard_normal((n_t, n_episodes, n, 3))
    z = np.zeros((n_t, n_episodes, n, n_l, 3))
    for i in range(n):
        for l in range(n_l):
            j, sd = inputs.target[i, l], np.sqrt(inputs.r0[i, l])
            if inputs.kind[i, l] == PEER:
                r = np.linalg.norm(truth[:, i] - truth[:, j], axis=1)
                z[:, :, i, l, 0] = r[:, None] + sd * rng.standard_normal((n_t, n_episodes))
            else:
                rel = inputs.landmarks[j] - truth[:, i]
                z[:, :, i, l] = rel[:, None] + sd * rng.standard_normal((n_t, n_episodes, 3))
    valid = np.ascontiguousarray(np.broadcast_to(inputs.use[:, 0][:, None], (n_t, n_episodes, n, n_l)))
    est = np.zeros((n_t, n_episodes, n, 3))
    cekf.cekf_run(x, P, imu, z, valid, np.ones(valid.shape), inputs.kind, inputs.target, inputs.r0,
                  np.zeros((0, 3)), inputs.landmarks, inputs.dt, inputs.imu_sigma, 0.0, 1e-3, est)
    return (est - truth[:, None]) ** 2


def test_peer_range_bound_is_a_centralised_filter_and_below_the_cekf():
    # UAV 0 flies past a landmark it sees every step; UAV 1 hovers and has only a range to UAV 0.
    # The bound must be the centralised information recursion (the peer's cross blocks, their
    # sign and R enter exactly once), close to the Kalman filter linearised at the truth where
    # the spread is small against the range, and no higher than the CEKF's Monte-Carlo MSE.
    n_t, dt = 40, 0.1
    vel = np.array([[0.5, 0.0, 0.0], [0.0, 0.0, 0.0]])
    t = dt * np.arange(1, n_t + 1)
    truth = np.stack([np.array([0.0, 0.0, 2.0]) + t[:, None] * vel[0], np.broadcast_to([3.0, 2.0, 2.5], (n_t, 3))], 1)
    kind, target = [[PEER, LANDMARK], [PEER, LANDMARK]], [[1, 0], [0, 0]]
    use = np.array([[False, True], [True, False]])
    inputs = swarm_inputs(truth, kind, target, [[0.2**2, 0.15**2]] * 2, use, [[1.0, -1.0, 3.0]], dt=dt)
    dense = joint_kalman_covariance(inputs)
    expected = np.stack([np.trace(dense[:, 6 * i:6 * i + 3, 6 * i:6 * i + 3], axis1=1, axis2=2) for i in range(2)], 1)
    np.testing.assert_allclose(pcrlb(inputs).pos_var[:, 0], expected, rtol=1e-9)
    np.testing.assert_allclose(pcrlb_reference(inputs).pos_var[:, 0], expected, rtol=1e-9)
    at_truth = joint_kalman_covariance(inputs, expected=False)
    at_truth = np.stack([np.trace(at_truth[:, 6 * i:6 * i + 3, 6 * i:6 * i + 3], axis1=1, axis2=2) for i in range(2)], 1)
    # UAV 0, tight from its landmark, is nearly the filter at the truth; UAV 1's spread (0.7 m against a
    # 3.6 m range) turns its one range's direction: the expectation informs it across the range too
    np.testing.assert_allclose(expected[:, 0], at_truth[:, 0], rtol=0.02)
    assert (expected[5:, 1] < at_truth[5:, 1]).all()
    # the range informs UAV 1 (without it the bound is its dead reckoning)
    no_range = pcrlb(inputs._replace(use=inputs.use & ~(inputs.kind == PEER))).pos_var[:, 0]
    assert (expected[10:, 1] < 0.9 * no_range[10:, 1]).all()
    mse = cekf_monte_carlo(inputs, vel, 400, seed=11).sum(-1).mean(axis=(0, 1))
    bound = expected.mean(axis=0)
    # UAV 0's CEKF is the Kalman filter of its landmark, which the bound barely undercuts (UAV 1's
    # range hardly informs it): equal within the Monte-Carlo error (5 %); UAV 1's, which takes
    # UAV 0's prior as a known point, is well above
    assert mse[0] >= 0.95 * bound[0] and mse[1] >= 1.1 * bound[1], (mse, bound)


def test_planar_ranging_framework_is_bounded_out_of_plane():
    # bound.py, "Expected information": UAVs 0–2 see a landmark each; UAV 3, in their plane
    # (z = 2), has ranges to them only. Out of the plane a range changes by δ²/2r, nothing to
    # first order: a Cramér–Rao bound at the truth leaves UAV 3's out-of-plane variance at its
    # dead reckoning, while the CEKF, linearised at its estimate, stays 100× below it from the
    # ranges' curvature (bound v1 was above the estimator there). The expectation over the
    # predicted spread gives the bound that information: it holds in the plane and out of it.
    n_t, dt, imu_sigma, p0 = 200, 0.1, 0.3, (0.25, 0.04)
    plane = np.array([[0.0, 0.0, 2.0], [4.0, 0.0, 2.0], [2.0, 3.5, 2.0], [2.0, 1.2, 2.0]])
    truth = np.broadcast_to(plane, (n_t, 4, 3))
    kind = [[PEER] * 3 + [LANDMARK] * 3] * 4
    target = [[j for j in range(4) if j != i] + [0, 1, 2] for i in range(4)]
    r0 = [[0.2**2] * 3 + [0.15**2] * 3] * 4
    use = np.zeros((4, 6), dtype=bool)
    use[[0, 1, 2], [3, 4, 5]] = True  # UAV i < 3 sees landmark i
    use[3, :3] = True  # UAV 3: ranges to UAVs 0, 1, 2
    inputs = swarm_inputs(truth, kind, target, r0, use, plane[:3] + 1.0, dt=dt, imu_sigma=imu_sigma, p0=p0)
    at_truth = joint_kalman_covariance(inputs, expected=False)
    # one axis of dead reckoning: C ← F C Fᵀ + σ² G Gᵀ from diag(p0)
    F, G, C, dead_reckoning = np.array([[1.0, dt], [0.0, 1.0]]), np.array([[dt * dt / 2], [dt]]), np.diag(p0), []
    for _ in range(n_t):
        C = F @ C @ F.T + imu_sigma**2 * G @ G.T
        dead_reckoning.append(C[0, 0])
    z3 = 6 * 3 + 2
    np.testing.assert_allclose(at_truth[:, z3, z3], dead_reckoning, rtol=1e-9)
    dense = joint_kalman_covariance(inputs)
    bound = pcrlb(inputs).pos_var[:, 0, 3]
    np.testing.assert_allclose(bound, np.trace(dense[:, 18:21, 18:21], axis1=1, axis2=2), rtol=1e-9)
    err2 = cekf_monte_carlo(inputs, np.zeros((4, 3)), 200, seed=5)[:, :, 3]
    assert err2[..., 2].mean() < 0.02 * np.mean(dead_reckoning)  # out of plane: 0.12 m² against 11.7 m²
    assert err2[..., 2].mean() > dense[:, z3, z3].mean()  # the bound holds out of the plane
    assert err2[..., :2].sum(-1).mean() > (dense[:, 18, 18] + dense[:, 19, 19]).mean()  # and in it


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
    shared = BB.bounds_from_inputs(spec, seeds, rec.inputs(world.schedule), world.schedule)
    assert shared == BB.compute_bounds(spec, seeds)
    assert all(b.healthy_rmse is not None for b in shared)
