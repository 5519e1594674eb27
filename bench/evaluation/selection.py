"""Which UAVs and steps an episode's metrics score: one home for the recorder and the bound.

``EpisodeRecorder`` (the metrics) and ``bounds`` (the information bound) both select from
here, so ``rmse`` and ``bound_rmse`` are always over the same UAVs and steps:

* scored steps: update k (0-based) is at time (k + 1)·dt and is scored from
  ``scoring.start`` on;
* scored UAVs: ``spec.scored_nodes``, and with ``scoring.nodes_from_schedule="healthy"``
  only those the episode's fault schedule leaves without an IMU fault (a per-episode set);
* healthy UAVs and steps of ``healthy_rmse``;
* each UAV's IMU-fault end, from which ``recovery_s`` is measured.

``schedule`` is the world's ``swarmloc.envs.world.faults.FaultSchedule`` of the batch (None for a
world without one, e.g. a recorded flight) and b the episode's index in it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from swarmloc.bench.scoring import metrics as M
from swarmloc.envs.tasks.specs import TaskSpec


def step_times(spec: TaskSpec) -> np.ndarray:
    """``(T,)`` time of every filter update, (k + 1)·dt [s]."""
    return spec.dt * np.arange(1, spec.n_steps + 1)


def scored_steps(spec: TaskSpec) -> np.ndarray:
    """``(T,)`` bool: the steps of the scored interval, t ≥ ``scoring.start``."""
    return step_times(spec) >= spec.scoring.start - 1e-9


def scored_nodes(spec: TaskSpec, schedule: Any, b: int) -> np.ndarray:
    """``(N,)`` bool: the UAVs episode b scores.

    Raises:
        ValueError: the task scores healthy nodes per episode and no schedule is given.
    """
    nodes = np.zeros(spec.n_uav, dtype=bool)
    nodes[list(spec.scored_nodes)] = True
    if spec.scoring.nodes_from_schedule == "healthy":
        if schedule is None:
            raise ValueError(f"{spec.task_id} scores each episode's healthy nodes "
                             "(scoring.nodes_from_schedule='healthy'): its fault schedule is needed")
        nodes &= ~schedule.faulty_nodes[b]
    return nodes


def scored_node_masks(spec: TaskSpec, schedule: Any, n_episodes: int) -> np.ndarray:
    """``(B, N)`` bool: :func:`scored_nodes` of every episode of the batch."""
    return np.stack([scored_nodes(spec, schedule, b) for b in range(n_episodes)])


def healthy_selection(spec: TaskSpec, schedule: Any, b: int) -> tuple[np.ndarray, np.ndarray] | None:
    """UAVs ``(N,)`` and steps ``(T,)`` the ``healthy_rmse`` metric scores in episode b, or None.

    The spec's healthy nodes over its fault window (or over the episode's IMU-fault span),
    or, for a randomised cascade, the nodes without an IMU fault over the fault span.
    """
    times, steps_ok = step_times(spec), scored_steps(spec)
    s = spec.scoring
    if s.healthy_nodes:
        healthy = np.zeros(spec.n_uav, dtype=bool)
        healthy[list(s.healthy_nodes)] = True
        if s.fault_window is not None:
            return healthy, M.window_steps(times, s.fault_window) & steps_ok
        span = schedule.imu_fault_span()[b] if schedule is not None else np.full(2, np.nan)
        window = None if np.isnan(span).any() else (float(span[0]), float(span[1]))
        return healthy, (M.window_steps(times, window) if window else steps_ok) & steps_ok
    if spec.faults.imu_cascade_random is not None and schedule is not None:
        span = schedule.imu_fault_span()[b]
        return ~schedule.faulty_nodes[b], M.window_steps(times, (float(span[0]), float(span[1]))) & steps_ok
    return None


def imu_fault_ends(schedule: Any, b: int, n_uav: int) -> np.ndarray:
    """``(N,)`` end of each UAV's last IMU-fault window in episode b [s]; NaN for a UAV without one."""
    ends = np.full(n_uav, np.nan)
    if schedule is None:
        return ends
    for (_, end), nodes in zip(schedule.imu_time[b], schedule.imu_nodes[b]):
        ends[nodes] = np.fmax(ends[nodes], end)
    return ends
