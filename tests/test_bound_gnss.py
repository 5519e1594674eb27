"""The information bound with GNSS errors correlated in time: a literal augmented Kalman filter (the linear case,
where the bound is the filter's covariance), the white limit, and the dispatch from ``bound.pcrlb``."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from swarmloc.envs.filter.bound import pcrlb
from swarmloc.envs.filter.bound_gnss import WHITE_SHARE, pcrlb_correlated_gnss
from swarmloc.envs.filter.cekf_reference import transition
from swarmloc.envs.tasks.channels import GPS

sys.path.insert(0, str(Path(__file__).parent))
from test_bound import synthetic


def augmented_kalman(n_t, dt, imu_sigma, p0, var, tau):
    """tr P_pp of one UAV, state [p, v, ε], fixes z = p + ε (+ the bound's tiny white part), ε Gauss–Markov."""
    F6, G = transition(dt)
    phi = math.exp(-dt / tau)
    F = np.eye(9)
    F[:6, :6] = F6
    F[6:, 6:] *= phi
    Q = np.zeros((9, 9))
    Q[:6, :6] = imu_sigma**2 * G @ G.T
    Q[6:, 6:] = var * (1 - phi * phi) * np.eye(3)
    H = np.hstack([np.eye(3), np.zeros((3, 3)), np.eye(3)])
    R = WHITE_SHARE * var * np.eye(3)
    P = np.diag([p0[0]] * 3 + [p0[1]] * 3 + [var] * 3)
    out = []
    for _ in range(n_t):
        P = F @ P @ F.T + Q
        K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
        P = (np.eye(9) - K @ H) @ P @ (np.eye(9) - K @ H).T + K @ R @ K.T
        out.append(np.trace(P[:3, :3]))
    return np.array(out)


@pytest.mark.parametrize("tau", [5.0, 60.0])
def test_a_uav_with_only_a_correlated_fix_is_the_augmented_kalman_filter(tau):
    n_t, dt, var = 80, 1.0, 1.0
    inputs = synthetic([GPS], [-1], [var], np.zeros((n_t, 3)), dt=dt, imu_sigma=0.05, p0=(25.0, 0.25))
    got = pcrlb(inputs._replace(gps_tau=tau)).pos_var[:, 0, 0]
    np.testing.assert_allclose(got, augmented_kalman(n_t, dt, 0.05, (25.0, 0.25), var, tau), rtol=1e-6)


def test_correlation_costs_information_and_a_short_one_is_white():
    n_t, dt, var = 120, 1.0, 1.0
    inputs = synthetic([GPS], [-1], [var], np.zeros((n_t, 3)), dt=dt, imu_sigma=0.05, p0=(25.0, 0.25))
    white = pcrlb(inputs).pos_var[-1, 0, 0]
    bounds = [pcrlb_correlated_gnss(inputs._replace(gps_tau=tau)).pos_var[-1, 0, 0] for tau in (1e-3, 10.0, 60.0)]
    # τ → 0: the fixes are white again (the bound's tiny white part aside)
    assert bounds[0] == pytest.approx(white, rel=1e-4)
    # a longer correlation carries less information: the bound rises with τ, towards the fix's own variance 3σ²
    assert bounds[0] < bounds[1] < bounds[2] < 3 * var


def test_it_needs_a_correlation_time():
    inputs = synthetic([GPS], [-1], [1.0], np.zeros((3, 3)))
    with pytest.raises(ValueError, match="gps_tau=0.0"):
        pcrlb_correlated_gnss(inputs)
