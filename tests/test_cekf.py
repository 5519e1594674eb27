"""CEKF backbone: fused kernel vs numpy reference vs FilterPy, and covariance health."""

from __future__ import annotations

import numpy as np
import pytest

from swarmloc.envs.world.core import LinkTrustCore
from swarmloc.envs.tasks.catalogue import CATALOGUE, get_spec
from swarmloc.envs.world.worlds import data_missing

from envs_helpers import assert_kernel_matches_reference, assert_reference_matches_filterpy, record


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
    spec, world, x0, imu, z, valid = record("swarmloc/Ideal-v0", 400, n_uav=1)
    anchors = world.anchors

    def hx(x):
        return np.linalg.norm(x[:3] - anchors, axis=1)

    def jac(x):
        H = np.zeros((len(anchors), 6))
        H[:, :3] = (x[:3] - anchors) / hx(x)[:, None]
        return H

    assert_reference_matches_filterpy(spec, world, x0, imu, z, valid, hx, jac)


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
