"""The Track A observation: the one-pass kernel against its definition in NumPy, bit for bit."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from swarmloc.envs.tasks.channels import N_KINDS
from swarmloc.envs.world import observation as O


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


def test_the_kernel_is_the_definition_bit_for_bit():
    rng = np.random.default_rng(0)
    shape = (7, 5, 9)
    step = SimpleNamespace(resid=rng.exponential(2.0, shape), pred=rng.uniform(0.0, 40.0, shape),
                           applied=rng.uniform(0.0, 1.0, shape), jerk=rng.exponential(1.0, shape[:2]),
                           nis=rng.exponential(5.0, shape), valid=rng.uniform(size=shape) < 0.7)
    one_hot = O.kind_one_hot(rng.integers(0, 6, size=shape[1:]))
    got = O.build_observation(step, one_hot)
    want = _reference(step, one_hot)
    assert got.dtype == np.float32 and np.array_equal(got.view(np.uint32), want.view(np.uint32))
    assert ((got >= 0.0) & (got <= 1.0)).all()
    out = np.full_like(got, np.nan)
    assert O.build_observation(step, one_hot, out=out) is out and np.array_equal(out, want)
