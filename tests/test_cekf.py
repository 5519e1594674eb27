"""CEKF backbone: fused kernel vs numpy reference vs FilterPy, and covariance health."""

from __future__ import annotations

import numpy as np
import pytest

from swarmloc.envs.filter.cekf_reference import predict_reference, update_reference
from swarmloc.envs.world.core import LinkTrustCore
from swarmloc.envs.tasks.catalogue import CATALOGUE, get_spec
from swarmloc.envs.world.worlds import data_missing

from envs_helpers import assert_kernel_matches_reference, record


@pytest.mark.parametrize("task_id", sorted(CATALOGUE))
def test_kernel_matches_reference_400_steps(task_id):
    spec = get_spec(task_id)
    if (reason := data_missing(spec)) is not None:
        pytest.skip(f"recorded task without its data: {reason.splitlines()[0]}")
    n_steps = min(400, spec.n_steps)
    spec, world, x0, imu, z, valid = record(task_id, n_steps)
    rng = np.random.default_rng(11)
    alpha = rng.uniform(0.0, 1.0, size=valid.shape)  # random trust exercises skipping and inflation
    assert_kernel_matches_reference(spec, world, x0, imu, z, valid, alpha)


def test_reference_matches_filterpy_fault_free():
    filterpy = pytest.importorskip("filterpy.kalman")
    spec, world, x0, imu, z, valid = record("swarmloc/Ideal-v0", 400, n_uav=1)
    lay = world.layout
    dt, q = spec.dt, spec.sensors.imu_sigma
    P0 = np.diag([spec.filter.init_pos_sigma**2] * 3 + [spec.filter.init_vel_sigma**2] * 3)
    anchors = world.anchors
    ekf = filterpy.ExtendedKalmanFilter(dim_x=6, dim_z=len(anchors), dim_u=3)
    ekf.x = x0[0, 0].copy()
    ekf.P = P0.copy()
    ekf.F = np.block([[np.eye(3), dt * np.eye(3)], [np.zeros((3, 3)), np.eye(3)]])
    G = np.vstack([0.5 * dt * dt * np.eye(3), dt * np.eye(3)])
    ekf.B = G
    ekf.Q = q**2 * G @ G.T
    ekf.R = np.diag(lay.r0[0])

    def hx(x):
        return np.linalg.norm(x[:3] - anchors, axis=1)

    def jac(x):
        H = np.zeros((len(anchors), 6))
        H[:, :3] = (x[:3] - anchors) / hx(x)[:, None]
        return H

    x_ref, P_ref = x0[0, 0].copy(), P0.copy()
    ones = np.ones(len(anchors))
    for k in range(len(imu)):
        assert valid[k, 0, 0].all()
        ekf.predict(u=imu[k, 0, 0])
        ekf.update(z[k, 0, 0, :, 0], jac, hx)
        x_ref, P_ref = predict_reference(x_ref, P_ref, imu[k, 0, 0], dt, q)
        x_ref, P_ref, _ = update_reference(x_ref, P_ref, z[k, 0, 0], valid[k, 0, 0], ones, lay.kind[0],
                                           lay.target[0], lay.r0[0], anchors, world.landmarks,
                                           np.zeros((1, 3)), spec.filter.alpha_th, spec.filter.alpha_min)
        assert np.abs(x_ref - ekf.x).max() <= 1e-9
        assert np.abs(P_ref - ekf.P).max() <= 1e-9


def test_covariance_symmetric_positive_definite_10000_random_steps():
    spec = get_spec("swarmloc/Scale6-v0", duration=1000.0)
    core = LinkTrustCore(spec, 2)
    core.reset([1, 2])
    rng = np.random.default_rng(0)
    shape = (2, spec.n_uav, spec.n_channels)
    for k in range(spec.n_steps):
        core.step(rng.uniform(0.0, 1.0, size=shape))
        P = core.P
        assert np.array_equal(P, np.swapaxes(P, -1, -2)), f"P not symmetric at step {k}"
        assert np.linalg.eigvalsh(P).min() > 0.0, f"P not positive definite at step {k}"
    assert spec.n_steps == 10_000


def test_skipped_channels_cost_no_flops_and_trust_inflates_r():
    spec = get_spec("swarmloc/Ideal-v0")
    core = LinkTrustCore(spec, 1)
    core.reset([0])
    shape = (1, spec.n_uav, spec.n_channels)
    step = core.step(np.zeros(shape))  # every channel skipped (α ≤ α_th): prediction only
    assert not step.active.any()
    assert (step.flops == cekf_predict_flops()).all()


def cekf_predict_flops() -> int:
    from swarmloc.envs.world.cost import PREDICT_FLOPS

    return PREDICT_FLOPS
