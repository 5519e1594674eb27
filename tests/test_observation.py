"""The Track A observation and the critics' global state: the one-pass kernels (on the calling thread and
threaded) against their definitions in NumPy, bit for bit."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from swarmloc.envs.tasks.channels import N_KINDS
from swarmloc.envs.world import observation as O
from swarmloc.envs.world.sim_kernel import SERIAL_BELOW


def _reference(step, one_hot):
    """docs/world.md, "What a Track A policy observes": each feature squashed x / (x + s) in float64, stored as
    float32; absent measurements carry no innovation, distance or NIS."""
    n_b, n, n_l = step.resid.shape
    out = np.empty((n_b, n, n_l, O.N_FEATURES), dtype=np.float32)
    out[..., O.INNOVATION] = O.squash(step.resid, O.SCALE_INNOVATION)
    out[..., O.DISTANCE] = O.squash(step.pred, O.SCALE_DISTANCE)
    out[..., O.PREV_TRUST] = step.applied
    out[..., O.JERK] = O.squash(step.jerk, O.SCALE_JERK)[..., None]
    out[..., O.NIS] = O.squash(step.nis, O.SCALE_NIS)
    out[..., O.KIND0:O.KIND0 + N_KINDS] = one_hot
    out[..., O.VALID] = step.valid
    out[..., [O.INNOVATION, O.DISTANCE, O.NIS]] *= step.valid[..., None]
    return out


def _step(rng, shape):
    return SimpleNamespace(resid=rng.exponential(2.0, shape), pred=rng.uniform(0.0, 40.0, shape),
                           applied=rng.uniform(0.0, 1.0, shape), jerk=rng.exponential(1.0, shape[:2]),
                           nis=rng.exponential(5.0, shape), valid=rng.uniform(size=shape) < 0.7)


@pytest.mark.parametrize("n_b", [7, SERIAL_BELOW + 9])  # on the calling thread, and threaded over blocks
def test_the_kernel_is_the_definition_bit_for_bit(n_b):
    rng = np.random.default_rng(0)
    shape = (n_b, 5, 9)
    step = _step(rng, shape)
    one_hot = O.kind_one_hot(rng.integers(0, 6, size=shape[1:]))
    got = O.build_observation(step, one_hot)
    want = _reference(step, one_hot)
    assert got.dtype == np.float32 and np.array_equal(got.view(np.uint32), want.view(np.uint32))
    assert ((got >= 0.0) & (got <= 1.0)).all()
    out = np.full_like(got, np.nan)
    assert O.build_observation(step, one_hot, out=out) is out and np.array_equal(out, want)


def _state_reference(obs, x, P):
    """``TrustEnvBatch.state``'s layout in NumPy: the observation flattened, prior positions, velocities, √tr(P_pp)."""
    n_b, n = x.shape[:2]
    return np.concatenate([obs.reshape(n_b, -1), x[:, :, :3].reshape(n_b, -1), x[:, :, 3:].reshape(n_b, -1),
                           np.sqrt(P[:, :, 0, 0] + P[:, :, 1, 1] + P[:, :, 2, 2])], axis=1).astype(np.float32)


@pytest.mark.parametrize("n_b", [3, SERIAL_BELOW + 5])
def test_the_state_kernel_is_its_layout_bit_for_bit(n_b):
    rng = np.random.default_rng(1)
    obs = rng.uniform(size=(n_b, 4, 6, O.N_FEATURES)).astype(np.float32)
    x = rng.normal(size=(n_b, 4, 6)) * 10.0
    A = rng.normal(size=(n_b, 4, 6, 6))
    P = A @ np.swapaxes(A, -1, -2)
    out = np.full((n_b, obs[0].size + 7 * 4), np.nan, dtype=np.float32)
    assert O.build_state(obs, x, P, out) is out
    assert np.array_equal(out.view(np.uint32), _state_reference(obs, x, P).view(np.uint32))


@pytest.mark.parametrize("n_b", [4, SERIAL_BELOW + 2])
def test_observation_and_state_in_one_pass_are_the_two_kernels(n_b):
    rng = np.random.default_rng(2)
    shape = (n_b, 3, 7)
    step = _step(rng, shape)
    one_hot = O.kind_one_hot(rng.integers(0, 6, size=shape[1:]))
    x = rng.normal(size=(n_b, 3, 6))
    A = rng.normal(size=(n_b, 3, 6, 6))
    P = A @ np.swapaxes(A, -1, -2)
    obs, state = O.build_observation_and_state(step, one_hot, x, P, 3 * 7 * O.N_FEATURES + 7 * 3)
    assert np.array_equal(obs.view(np.uint32), _reference(step, one_hot).view(np.uint32))
    assert np.array_equal(state.view(np.uint32), _state_reference(obs, x, P).view(np.uint32))
