"""Analytic truth trajectories: position, velocity and acceleration at any time t.

Each UAV's trajectory is a kind id plus a parameter row (``N_PARAMS`` floats) built once
per episode by ``trajectory_params``; ``truth_at`` evaluates it inside the world kernel.
Random waypoints draw their waypoints from the counter-based RNG on demand, so nothing
per-episode has to be stored beyond the seed.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from swarmloc.envs.tasks.rng import Stream, uniform
from swarmloc.envs.tasks.specs import (
    AccelCircle,
    FigureEightChain,
    LeaderFollowerLine,
    PhasedCircles,
    RandomWaypoints,
    TaskSpec,
)

ACCEL_CIRCLE, PHASED_CIRCLES, FIGURE_EIGHT, LEADER_LINE, RANDOM_WAYPOINTS = 0, 1, 2, 3, 4
N_PARAMS = 8
_KIND_IDS = {
    "accel_circle": ACCEL_CIRCLE,
    "phased_circles": PHASED_CIRCLES,
    "figure_eight_chain": FIGURE_EIGHT,
    "leader_follower_line": LEADER_LINE,
    "random_waypoints": RANDOM_WAYPOINTS,
}
_WAYPOINT_STRIDE = 1 << 20  # index space per UAV for waypoint draws


def trajectory_kind(spec: TaskSpec) -> int:
    """Integer id of the spec's trajectory kind (used by the kernel)."""
    return _KIND_IDS[spec.trajectory.kind]


def trajectory_params(spec: TaskSpec) -> np.ndarray:
    """Per-UAV parameter rows ``(N, N_PARAMS)`` for ``truth_at``."""
    tr = spec.trajectory
    n = spec.n_uav
    prm = np.zeros((n, N_PARAMS))
    for i in range(n):
        if isinstance(tr, AccelCircle):
            prm[i, :6] = (0.0, i * tr.spacing, tr.altitude, tr.accel_time, tr.radius, tr.omega)
        elif isinstance(tr, PhasedCircles):
            prm[i, :8] = (
                tr.center[0], tr.center[1], tr.center[2], tr.radius + i * tr.radius_step,
                tr.omega, i * tr.phase_step, tr.z_amplitude, tr.z_omega,
            )
        elif isinstance(tr, FigureEightChain):
            prm[i, :5] = (tr.radius, tr.omega, tr.altitude, i * tr.lag, i * tr.offset)
        elif isinstance(tr, LeaderFollowerLine):
            # formation: row 0 leads, the others sit behind it on alternating sides
            side = 0.0 if i == 0 else (1.0 if i % 2 else -1.0) * ((i + 1) // 2)
            prm[i, :5] = (-(i > 0) * tr.spacing, side * tr.spacing, tr.altitude, tr.speed, tr.turn_rate)
        elif isinstance(tr, RandomWaypoints):
            prm[i, :7] = (tr.segment_time, *tr.low, *tr.high)
    return prm


@njit(cache=True, inline="always")
def _waypoint(seed: int, uav: int, k: int, prm: np.ndarray, d: int) -> float:
    u = uniform(seed, 0, Stream.TRAJECTORY, uav * _WAYPOINT_STRIDE + 3 * k + d)
    return prm[1 + d] + (prm[4 + d] - prm[1 + d]) * u


@njit(cache=True, inline="always")
def truth_at(kind: int, prm: np.ndarray, t: float, seed: int, uav: int,
             p: np.ndarray, v: np.ndarray, a: np.ndarray) -> None:
    """Write the truth position, velocity and acceleration of one UAV at time ``t``.

    Args:
        kind: trajectory kind id.
        prm: the UAV's parameter row ``(N_PARAMS,)``.
        t: time [s].
        seed: episode seed (random waypoints only).
        uav: UAV index (random waypoints only).
        p, v, a: output 3-vectors.
    """
    if kind == ACCEL_CIRCLE:
        x0, y0, z0, ta, r, w = prm[0], prm[1], prm[2], prm[3], prm[4], prm[5]
        speed = r * w
        acc = speed / ta
        if t < ta:
            p[0], p[1], p[2] = x0 + 0.5 * acc * t * t, y0, z0
            v[0], v[1], v[2] = acc * t, 0.0, 0.0
            a[0], a[1], a[2] = acc, 0.0, 0.0
        else:
            th = w * (t - ta)
            s = x0 + 0.5 * speed * ta
            p[0], p[1], p[2] = s + r * math.sin(th), y0 + r - r * math.cos(th), z0
            v[0], v[1], v[2] = speed * math.cos(th), speed * math.sin(th), 0.0
            a[0], a[1], a[2] = -speed * w * math.sin(th), speed * w * math.cos(th), 0.0
    elif kind == PHASED_CIRCLES:
        cx, cy, cz, r, w, ph, za, zw = prm[0], prm[1], prm[2], prm[3], prm[4], prm[5], prm[6], prm[7]
        th = w * t + ph
        ps = zw * t + ph
        p[0], p[1], p[2] = cx + r * math.cos(th), cy + r * math.sin(th), cz + za * math.sin(ps)
        v[0], v[1], v[2] = -r * w * math.sin(th), r * w * math.cos(th), za * zw * math.cos(ps)
        a[0], a[1], a[2] = -r * w * w * math.cos(th), -r * w * w * math.sin(th), -za * zw * zw * math.sin(ps)
    elif kind == FIGURE_EIGHT:
        r, w, z0, lag, off = prm[0], prm[1], prm[2], prm[3], prm[4]
        th = w * (t - lag)
        # Gerono lemniscate: x = r sin θ, y = (r/2) sin 2θ
        p[0], p[1], p[2] = r * math.sin(th), 0.5 * r * math.sin(2.0 * th) + off, z0
        v[0], v[1], v[2] = r * w * math.cos(th), r * w * math.cos(2.0 * th), 0.0
        a[0], a[1], a[2] = -r * w * w * math.sin(th), -2.0 * r * w * w * math.sin(2.0 * th), 0.0
    elif kind == LEADER_LINE:
        x0, y0, z0, speed, turn = prm[0], prm[1], prm[2], prm[3], prm[4]
        psi = turn * t
        if abs(turn) < 1e-12:
            p[0], p[1], p[2] = x0 + speed * t, y0, z0
            v[0], v[1], v[2] = speed, 0.0, 0.0
            a[0], a[1], a[2] = 0.0, 0.0, 0.0
        else:
            rad = speed / turn
            p[0], p[1], p[2] = x0 + rad * math.sin(psi), y0 + rad * (1.0 - math.cos(psi)), z0
            v[0], v[1], v[2] = speed * math.cos(psi), speed * math.sin(psi), 0.0
            a[0], a[1], a[2] = -speed * turn * math.sin(psi), speed * turn * math.cos(psi), 0.0
    else:  # RANDOM_WAYPOINTS
        seg = prm[0]
        k = int(math.floor(t / seg))
        tau = t / seg - k
        # cosine blend s(τ) = (1 − cos πτ)/2: zero velocity at each waypoint
        s = 0.5 * (1.0 - math.cos(math.pi * tau))
        ds = 0.5 * math.pi * math.sin(math.pi * tau) / seg
        dds = 0.5 * math.pi * math.pi * math.cos(math.pi * tau) / (seg * seg)
        for d in range(3):
            w0 = _waypoint(seed, uav, k, prm, d)
            w1 = _waypoint(seed, uav, k + 1, prm, d)
            p[d] = w0 + (w1 - w0) * s
            v[d] = (w1 - w0) * ds
            a[d] = (w1 - w0) * dds
