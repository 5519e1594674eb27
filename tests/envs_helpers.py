"""Helpers shared by the tests of the environments and the CEKF."""

from __future__ import annotations

import numpy as np
import pydantic
import pytest

from swarmloc.envs.tasks.specs import Scoring
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


def record(task_id: str, n_steps: int, seeds=(3,), **overrides):
    """Sense ``n_steps`` steps of a task; return the spec, world and stacked sequences."""
    spec = get_spec(task_id, **overrides)
    world = make_world(spec, len(seeds))
    x0 = world.reset(list(seeds)).copy()
    imu, z, valid = [], [], []
    for _ in range(n_steps):
        buf = world.sense()
        imu.append(buf.imu.copy())
        z.append(buf.z.copy())
        valid.append(buf.valid.copy())
    return spec, world, x0, np.array(imu), np.array(z), np.array(valid)
