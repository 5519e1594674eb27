"""Helpers shared by the tests of the environments and the CEKF."""

from __future__ import annotations

import numpy as np
import pydantic
import pytest

from swarmloc.envs.filter import cekf
from swarmloc.envs.filter.cekf_reference import predict_reference, run_reference, update_reference
from swarmloc.envs.world.core import LinkTrustCore
from swarmloc.envs.tasks.specs import Scoring, TaskSpec
from swarmloc.envs.tasks.catalogue import get_spec
from swarmloc.envs.world.worlds import data_missing, make_world


def short(task_id: str, steps: int) -> dict:
    """Overrides that make ``task_id`` last ``steps`` updates (scoring reset if it no longer fits)."""
    overrides = {"duration": steps * get_spec(task_id).dt}
    try:
        get_spec(task_id, **overrides)
    except pydantic.ValidationError:
        overrides["scoring"] = Scoring().model_dump()
        get_spec(task_id, **overrides)
    return overrides


def skip_without_data(task_id: str) -> None:
    """Skip a test of a recorded task whose data set is not here."""
    why = data_missing(get_spec(task_id))
    if why:
        pytest.skip(f"{task_id}: {why.splitlines()[0]}")


def assert_same(a, b) -> None:
    """Exact equality of nested tuples / dicts / arrays / scalars."""
    if isinstance(a, dict):
        assert a.keys() == b.keys()
        for key in a:
            assert_same(a[key], b[key])
    elif isinstance(a, (tuple, list)):
        assert len(a) == len(b)
        for x, y in zip(a, b):
            assert_same(x, y)
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and np.array_equal(a, b)
    else:
        assert a == b


def sense(spec: TaskSpec, n_steps: int, seeds=(3,)):
    """Sense ``n_steps`` steps of ``spec``'s world; return the world, x0 and the stacked imu, z, valid and true positions."""
    world = make_world(spec, len(seeds))
    x0 = world.reset(list(seeds)).copy()
    imu, z, valid, pos = [], [], [], []
    for _ in range(n_steps):
        buf = world.sense()
        imu.append(buf.imu.copy())
        z.append(buf.z.copy())
        valid.append(buf.valid.copy())
        pos.append(buf.pos.copy())
    return world, x0, np.array(imu), np.array(z), np.array(valid), np.array(pos)


def record(task_id: str, n_steps: int, seeds=(3,), **overrides):
    """Sense ``n_steps`` steps of a task; return the spec, world and stacked sequences."""
    spec = get_spec(task_id, **overrides)
    world, x0, imu, z, valid, _ = sense(spec, n_steps, seeds)
    return spec, world, x0, imu, z, valid


def assert_kernel_matches_reference(spec: TaskSpec, world, x0, imu, z, valid, alpha, peer_update: str = "point"):
    """The fused CEKF kernel (``cekf_run``) and the readable numpy reference (``run_reference``) filter the
    recorded sequences with trust ``alpha`` to the same estimates and covariances (within 1e-9).

    Returns:
        ``(P0, args, P_ref)``: the initial covariance, the arguments both took after ``(x, P)``, and the
        reference's final covariance, for further checks on the same data.
    """
    lay = world.layout
    P0 = cekf.initial_covariance(len(x0), spec.n_uav, spec.filter.init_pos_sigma, spec.filter.init_vel_sigma)
    args = (imu, z, valid, alpha, lay.kind, lay.target, lay.r0, world.anchors, world.landmarks, spec.dt,
            spec.sensors.imu_sigma, spec.filter.alpha_th, spec.filter.alpha_min)
    est_ref, _, P_ref = run_reference(x0, P0, *args, peer_update=peer_update)
    x, P = x0.copy(), P0.copy()
    est = np.zeros_like(est_ref)
    cekf.cekf_run(x, P, *args, est, cekf.PEER_UPDATE_CODES[peer_update])
    assert np.abs(est - est_ref).max() <= 1e-9, np.abs(est - est_ref).max()
    assert np.abs(P - P_ref).max() <= 1e-9
    return P0, args, P_ref


def batch_and_singles(spec: TaskSpec, seeds) -> tuple[LinkTrustCore, list[LinkTrustCore]]:
    """One core of ``len(seeds)`` episodes and one core per episode alone, each reset to its seeds."""
    batch = LinkTrustCore(spec, len(seeds))
    batch.reset(seeds)
    singles = [LinkTrustCore(spec, 1) for _ in seeds]
    for core, seed in zip(singles, seeds):
        core.reset([seed])
    return batch, singles


def assert_reference_matches_filterpy(spec: TaskSpec, world, x0, imu, z, valid, hx, jac) -> None:
    """The numpy reference (predict, then update at full trust) and FilterPy's ``ExtendedKalmanFilter`` with the
    measurement function ``hx`` and its Jacobian ``jac`` agree within 1e-9 at every step of the first UAV of the
    first episode, whose channels must all be valid. Skips without FilterPy."""
    filterpy = pytest.importorskip("filterpy.kalman")
    lay, dt, q = world.layout, spec.dt, spec.sensors.imu_sigma
    n_z = lay.kind.shape[1]
    P0 = np.diag([spec.filter.init_pos_sigma**2] * 3 + [spec.filter.init_vel_sigma**2] * 3)
    ekf = filterpy.ExtendedKalmanFilter(dim_x=6, dim_z=n_z, dim_u=3)
    ekf.x, ekf.P = x0[0, 0].copy(), P0.copy()
    ekf.F = np.block([[np.eye(3), dt * np.eye(3)], [np.zeros((3, 3)), np.eye(3)]])
    G = np.vstack([0.5 * dt * dt * np.eye(3), dt * np.eye(3)])
    ekf.B, ekf.Q, ekf.R = G, q**2 * G @ G.T, np.diag(lay.r0[0])
    x_ref, P_ref, ones = x0[0, 0].copy(), P0.copy(), np.ones(n_z)
    for k in range(len(imu)):
        assert valid[k, 0, 0].all()
        ekf.predict(u=imu[k, 0, 0])
        ekf.update(z[k, 0, 0, :, 0], jac, hx)
        x_ref, P_ref = predict_reference(x_ref, P_ref, imu[k, 0, 0], dt, q)
        x_ref, P_ref, active = update_reference(x_ref, P_ref, z[k, 0, 0], valid[k, 0, 0], ones, lay.kind[0],
                                                lay.target[0], lay.r0[0], world.anchors, world.landmarks,
                                                np.zeros((1, 3)), spec.filter.alpha_th, spec.filter.alpha_min)
        assert active.all()
        assert np.abs(x_ref - ekf.x).max() <= 1e-9 and np.abs(P_ref - ekf.P).max() <= 1e-9
