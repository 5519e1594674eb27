"""The TDOA channel kind: spec and layout, world, CEKF kernel == reference == FilterPy, features, bound.

Everything here is simulated (``swarmloc/TDOA-v1`` and overrides of it); the real TDOA
flights are tested in ``test_util_tdoa.py``.
"""

from __future__ import annotations

import numpy as np
import pydantic
import pytest

from swarmloc.envs.filter.bound import pcrlb, record_inputs
from swarmloc.envs.filter.bound_reference import pcrlb_reference
from swarmloc.envs.filter.cekf_reference import measurement_rows
from swarmloc.envs.tasks.channels import ANCHOR, KIND_DIM, TDOA, build_layout, tdoa_code, tdoa_pair
from swarmloc.envs.world.core import LinkTrustCore
from swarmloc.envs.world.cost import PREDICT_FLOPS, TDOA_ROW_FLOPS
from swarmloc.envs.world.observation import KIND0, kind_one_hot
from swarmloc.envs.tasks.specs import TaskSpec, all_pairs, ring_pairs
from swarmloc.envs.tasks.catalogue import get_spec
from swarmloc.envs.world.sim import World

from envs_helpers import assert_kernel_matches_reference, assert_reference_matches_filterpy, sense

TASK = "swarmloc/TDOA-v1"


def quiet(**overrides) -> TaskSpec:
    """TDOA-v1 without faults or losses (one UAV unless overridden)."""
    return get_spec(TASK, **{"n_uav": 1, "faults": {"packet_loss": 0.0, "nlos_gauss_markov": None}, **overrides})


def range_difference(p: np.ndarray, anchors: np.ndarray, i: int, j: int) -> float:
    return float(np.linalg.norm(p - anchors[j]) - np.linalg.norm(p - anchors[i]))


# --------------------------------------------------------------------------- spec and layout


def test_pairs_helpers_and_layout_codes():
    assert ring_pairs(4) == ((0, 1), (1, 2), (2, 3), (3, 0))
    assert all_pairs(4) == ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))
    spec = get_spec(TASK)
    assert spec.n_channels == 8 == spec.n_anchor_channels and spec.sensors.tdoa.pairs == ring_pairs(8)
    lay = build_layout(spec)
    assert (lay.kind == TDOA).all() and not (lay.kind == ANCHOR).any()
    assert [tdoa_pair(int(c), 8) for c in lay.target[0]] == list(ring_pairs(8))
    assert tdoa_code(3, 4, 8) == 28 and tdoa_pair(28, 8) == (3, 4)
    assert np.allclose(lay.sigma, 0.15) and KIND_DIM[TDOA] == 1


@pytest.mark.parametrize("sensors, faults, message", [
    ({"tdoa": {"pairs": ((0, 8),)}}, {}, "beyond the 8 of the task"),
    ({"tdoa": {"pairs": ((0, 1), (1, 0))}}, {}, "appears twice"),
    ({"tdoa": {"pairs": ((2, 2),)}}, {}, "two different anchors"),
    ({}, {"nlos_steps": ({"target": "anchor", "index": 0, "start": 1.0, "end": 2.0, "bias": 1.0},)},
     "not modelled"),
])
def test_bad_tdoa_specs_are_named(sensors, faults, message):
    with pytest.raises(pydantic.ValidationError, match=message):
        get_spec(TASK, sensors=sensors, faults=faults)


def test_observation_puts_tdoa_in_the_anchor_column():
    lay = build_layout(get_spec(TASK))
    one_hot = kind_one_hot(lay.kind)
    assert one_hot.shape == (4, 8, 5) and (one_hot[..., 0] == 1).all() and one_hot.sum() == 32
    core = LinkTrustCore(get_spec(TASK, duration=1.0), 1)
    core.reset([0])
    from swarmloc.envs.adapters.trust_env import TrustEnvBatch

    env = TrustEnvBatch(get_spec(TASK, duration=1.0), 1)
    env.reset([0])
    obs = env.observation()
    assert obs.shape == (1, 4, 8, 11) and (obs[..., KIND0] == 1).all()


# --------------------------------------------------------------------------- world


def test_world_senses_the_range_difference_of_each_pair():
    spec = quiet(sensors={"tdoa": {"pairs": ring_pairs(8), "sigma": 1e-9}})
    world, _, _, z, valid, pos = sense(spec, 30)
    assert valid.all()
    for k in (0, 12, 29):
        for c, (i, j) in enumerate(ring_pairs(8)):
            assert z[k, 0, 0, c, 0] == pytest.approx(range_difference(pos[k, 0, 0], world.anchors, i, j), abs=1e-8)
            assert (z[k, 0, 0, c, 1:] == 0).all()


def test_world_nlos_on_tdoa_is_a_positive_bias_and_labelled():
    spec = get_spec(TASK, duration=20.0, faults={"packet_loss": 0.0,
                                                 "nlos_gauss_markov": {"onset_rate": 1.0, "mean_bias": 2.0}})
    world = World(spec, 1)
    world.reset([5])
    biased = 0
    for _ in range(spec.n_steps):
        buf = world.sense()
        e = buf.injected[0]
        assert (e >= 0).all() and np.array_equal(buf.systematic[0, ..., 0], e)
        assert np.array_equal(buf.label[0], buf.valid[0] & (e > 3.0 * 0.15))
        biased += int((e > 0).sum())
    assert biased > 0


# --------------------------------------------------------------------------- filter


def test_measurement_row_is_the_range_difference_and_its_jacobian():
    anchors = np.array([[0.0, 0.0, 0.0], [4.0, 0.0, 3.0], [0.0, 5.0, 0.5]])
    x = np.array([1.0, 2.0, 1.5, 0.3, -0.2, 0.0])
    z = np.array([0.7, 0.0, 0.0])
    y, H = measurement_rows(x, z, TDOA, tdoa_code(2, 1, 3), anchors, np.zeros((0, 3)), np.zeros((1, 3)))
    h = range_difference(x[:3], anchors, 2, 1)
    assert y[0] == pytest.approx(0.7 - h)
    eps = 1e-6
    numeric = [(range_difference(x[:3] + eps * np.eye(3)[d], anchors, 2, 1)
                - range_difference(x[:3] - eps * np.eye(3)[d], anchors, 2, 1)) / (2 * eps) for d in range(3)]
    np.testing.assert_allclose(H[0, :3], numeric, atol=1e-8)
    assert (H[0, 3:] == 0).all()


def test_kernel_matches_reference_with_faults_and_random_trust():
    spec = get_spec(TASK, duration=4.0)
    world, x0, imu, z, valid, _ = sense(spec, spec.n_steps, seeds=(3, 11))
    alpha = np.random.default_rng(11).uniform(0.0, 1.0, size=valid.shape)
    assert_kernel_matches_reference(spec, world, x0, imu, z, valid, alpha)


def test_reference_matches_filterpy_on_a_tdoa_only_case():
    spec = quiet()
    world, x0, imu, z, valid, _ = sense(spec, 300)
    anchors = world.anchors
    pairs = np.array([tdoa_pair(int(c), len(anchors)) for c in world.layout.target[0]])

    def hx(x):
        # h = ‖p − a_j‖ − ‖p − a_i‖ per pair (i, j)
        return np.linalg.norm(x[:3] - anchors[pairs[:, 1]], axis=1) - np.linalg.norm(x[:3] - anchors[pairs[:, 0]], axis=1)

    def jac(x):
        H = np.zeros((len(pairs), 6))
        u = lambda a: (x[:3] - a) / np.linalg.norm(x[:3] - a, axis=1, keepdims=True)
        H[:, :3] = u(anchors[pairs[:, 1]]) - u(anchors[pairs[:, 0]])
        return H

    assert_reference_matches_filterpy(spec, world, x0, imu, z, valid, hx, jac)


def test_features_and_flops_of_a_tdoa_row():
    spec = quiet(duration=0.5)
    core = LinkTrustCore(spec, 1)
    core.reset([2])
    buf, x = core.world.buffers, core.x[0, 0]
    anchors = core.world.anchors
    for c, (i, j) in enumerate(ring_pairs(8)):
        h = range_difference(x[:3], anchors, i, j)
        assert core._out.pred[0, 0, c] == pytest.approx(abs(h), abs=1e-12)
        assert core._out.resid[0, 0, c] == pytest.approx(abs(buf.z[0, 0, c, 0] - h), abs=1e-12)
    step = core.step(np.ones((1, 1, 8)))
    assert step.active.all() and step.flops[0, 0] == PREDICT_FLOPS + 8 * TDOA_ROW_FLOPS


def test_bound_fast_matches_reference_on_tdoa():
    spec = get_spec(TASK, duration=0.3)
    inputs, _ = record_inputs(spec, [1_000_000, 1_000_001])
    fast, ref = pcrlb(inputs), pcrlb_reference(inputs)
    assert (fast.failed_at == -1).all() and (ref.failed_at == -1).all()
    np.testing.assert_allclose(fast.pos_var, ref.pos_var, rtol=1e-9, atol=0)
    assert np.isfinite(fast.pos_var).all() and (fast.pos_var > 0).all()


def test_fused_core_step_equals_the_batch_kernels_on_tdoa():
    """The core's one-kernel step on TDOA channels gives bit for bit the separate kernels' numbers."""
    from swarmloc.bench.speed.world import UnfusedCore

    spec = get_spec(TASK, duration=1.5, faults={"nlos_gauss_markov": {"onset_rate": 2.0}})
    seeds = np.array([3, 1_000_001])
    fused, unfused = LinkTrustCore(spec, 2), UnfusedCore(spec, 2)
    fused.reset(seeds)
    unfused.reset(seeds)
    rng = np.random.default_rng(0)
    for k in range(spec.n_steps - 1):
        trust = rng.uniform(0.0, 1.0, (2, spec.n_uav, spec.n_channels))
        a, b = fused.step(trust), unfused.step(trust)
        for name in ("resid", "pred", "nis", "valid", "estimate", "label", "active", "flops"):
            assert np.array_equal(getattr(a, name), b[name]), (name, k)
    assert np.array_equal(fused.x, unfused.x) and np.array_equal(fused.P, unfused.P)
