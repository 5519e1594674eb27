"""Playing Track B estimators on simulated episodes, shared by the estimator tests."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

from swarmloc.agents.protocols import EstimatorOutput, Measurements, TaskFacts, episode_keys
from swarmloc.envs.tasks.specs import TaskSpec
from swarmloc.envs.world.sim import World


class Played(NamedTuple):
    """What an estimator answered over a batch of episodes, beside the truth."""

    positions: np.ndarray
    """``(T, B, N, 3)`` estimated positions."""
    weights: np.ndarray | None
    """``(T, B, N, L)`` channel weights applied, None when the estimator reports none."""
    truth: np.ndarray
    """``(T, B, N, 3)`` true positions."""


def play_blind(est: Any, spec: TaskSpec, seeds: list[int], poison_truth: bool = False,
               check: Callable[[Any, EstimatorOutput], None] | None = None) -> Played:
    """Play episodes ``seeds`` of ``spec`` through the estimator ``est`` from the world's measurements alone.

    Args:
        est: a Track B estimator (``reset(facts, x0)``, ``step(meas)``).
        spec: the task.
        seeds: one episode seed per batch element.
        poison_truth: the world's truth buffers hold NaN while ``est`` steps, so an estimator that
            reached them would answer NaN (they are restored for the world's next step).
        check: called with ``(est, output)`` after every step.
    """
    world = World(spec, len(seeds))
    x0 = world.reset(seeds).copy()
    facts = TaskFacts.from_spec(spec, world.layout, x0, episode_keys(seeds))
    est.reset(facts, facts.x0)
    pos, weights, truth = [], [], []
    for k in range(1, spec.n_steps + 1):
        buf = world.sense()
        meas = Measurements.capture(buf.imu, buf.z, buf.valid, k * spec.dt, k, buf.velocity)
        truth.append(buf.pos.copy())
        saved = buf.pos.copy(), buf.vel.copy()
        if poison_truth:
            buf.pos[:] = np.nan
            buf.vel[:] = np.nan
        out = est.step(meas)
        buf.pos[:], buf.vel[:] = saved
        if check is not None:
            check(est, out)
        pos.append(out.positions.copy())
        weights.append(None if out.weights is None else out.weights.copy())
    stacked = None if any(w is None for w in weights) else np.array(weights)
    return Played(np.array(pos), stacked, np.array(truth))
