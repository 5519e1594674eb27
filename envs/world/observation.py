"""Per-channel observation of the link-trust track (docs/world.md, "What a Track A policy observes").

Each channel gets F = 11 features, each in [0, 1]: innovation magnitude r, predicted
distance d̂, previous applied trust, IMU jerk ‖u(k) − u(k−1)‖, normalised innovation
squared, a one-hot of the channel kind (anchor, peer, landmark, gps, peer_rel) and the
valid mask. A TDOA channel (range difference of an anchor pair) sets the anchor column
of the one-hot (``channels.OBS_KIND_COLUMN``), its d̂ is the predicted range difference
|‖p⁻ − a_j‖ − ‖p⁻ − a_i‖|, and r and the NIS are those of the scalar row, as for a range. Unbounded magnitudes are squashed with x / (x + s), a monotone map of
[0, ∞) onto [0, 1) whose scale s (below) sits at 0.5; ``unsquash`` inverts it.

The NIS is yᵀ S⁻¹ y with S = H P⁻ Hᵀ + R0 (P⁻ the UAV's prior covariance). v1 tasks: the
peer NIS includes the neighbour's broadcast covariance, S = u P_i⁻ uᵀ + u P_j⁻ uᵀ + R0 for a
peer range and P_i⁻ + P_j⁻ + R0 I for a relative position (``TaskSpec.peer_nis_neighbour_cov``,
``cekf.channel_features``); v0 tasks keep the v0 NIS bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from swarmloc.envs.tasks.channels import N_KINDS, OBS_KIND_COLUMN
from swarmloc.envs.world.core import CoreStep
from swarmloc.envs.world.sim_kernel import BLOCK, SERIAL_BELOW, block_bounds

FEATURE_NAMES = (
    "innovation", "predicted_distance", "previous_trust", "imu_jerk", "nis",
    "kind_anchor", "kind_peer", "kind_landmark", "kind_gps", "kind_peer_rel", "valid",
)
N_FEATURES = len(FEATURE_NAMES)
#: squash scales: innovation [m], predicted distance [m], jerk [m/s²], NIS [-]
SCALE_INNOVATION, SCALE_DISTANCE, SCALE_JERK, SCALE_NIS = 1.0, 10.0, 1.0, 5.0
INNOVATION, DISTANCE, PREV_TRUST, JERK, NIS, KIND0, VALID = 0, 1, 2, 3, 4, 5, 10


def squash(x: np.ndarray, scale: float) -> np.ndarray:
    """Map [0, ∞) onto [0, 1): x / (x + scale)."""
    return x / (x + scale)


def unsquash(y: np.ndarray, scale: float) -> np.ndarray:
    """Inverse of ``squash`` for y in [0, 1)."""
    return scale * y / np.maximum(1.0 - y, 1e-12)


def kind_one_hot(kind: np.ndarray) -> np.ndarray:
    """``(N, L)`` kind ids → ``(N, L, N_KINDS)`` float32 one-hot (TDOA in the anchor column)."""
    return np.eye(N_KINDS, dtype=np.float32)[OBS_KIND_COLUMN[kind]]


def build_observation(step: CoreStep, one_hot: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Observation ``(B, N, L, F)`` float32 in [0, 1] from a core step.

    Args:
        step: the core's latest ``CoreStep``.
        one_hot: ``(N, L, N_KINDS)`` from ``kind_one_hot(layout.kind)``.
        out: optional preallocated output.
    """
    n_b, n, n_l = step.resid.shape
    if out is None:
        out = np.empty((n_b, n, n_l, N_FEATURES), dtype=np.float32)
    _fill_kernel(n_b)(step.resid, step.pred, step.applied, step.jerk, step.nis, step.valid, one_hot, out,
                      _NO_STATE, _NO_X, _NO_P)
    return out


def build_observation_and_state(step: CoreStep, one_hot: np.ndarray, x: np.ndarray, P: np.ndarray,
                                state_size: int) -> tuple[np.ndarray, np.ndarray]:
    """The observation (``build_observation``) and the global state (``build_state``) in one pass: each
    feature is written to both, so the state does not read the observation back."""
    n_b, n, n_l = step.resid.shape
    out = np.empty((n_b, n, n_l, N_FEATURES), dtype=np.float32)
    state = np.empty((n_b, state_size), dtype=np.float32)
    _fill_kernel(n_b)(step.resid, step.pred, step.applied, step.jerk, step.nis, step.valid, one_hot, out, state, x, P)
    return out, state


def build_state(obs: np.ndarray, x: np.ndarray, P: np.ndarray, out: np.ndarray) -> np.ndarray:
    """The centralized critics' global state ``(B, S)`` float32 (``TrustEnvBatch.state`` states the layout):
    ``obs`` ``(B, N, L, F)`` flattened, the prior positions and velocities of ``x`` ``(B, N, 6)``, then
    √tr(P_pp) of ``P`` ``(B, N, 6, 6)``, written into ``out``."""
    (_state if obs.shape[0] < SERIAL_BELOW else _state_threaded)(obs, x, P, out)
    return out


#: stand-ins for the state arguments of ``_fill`` when no state is written
_NO_STATE, _NO_X, _NO_P = np.empty((0, 0), dtype=np.float32), np.empty((0, 0, 6)), np.empty((0, 0, 6, 6))


def _fill_kernel(n_b: int):
    return _fill if n_b < SERIAL_BELOW else _fill_threaded


@njit(cache=True, inline="always")
def _fill_rows(resid, pred, applied, jerk, nis, valid, one_hot, out, state, x, P, lo, hi):
    """``build_observation`` for episodes lo..hi−1 in one pass (float64 arithmetic, rounded to float32 once,
    as NumPy's assignments round; absent measurements carry no innovation, distance or NIS); with a ``state``
    of B rows, each feature goes to its place in the state too, then ``_state_tail``."""
    n, n_l = resid.shape[1], resid.shape[2]
    with_state = state.shape[0] > 0
    for b in range(lo, hi):
        for i in range(n):
            jk = jerk[b, i] / (jerk[b, i] + SCALE_JERK)
            for l in range(n_l):
                v = 1.0 if valid[b, i, l] else 0.0
                o = out[b, i, l]
                o[INNOVATION] = resid[b, i, l] / (resid[b, i, l] + SCALE_INNOVATION) * v
                o[DISTANCE] = pred[b, i, l] / (pred[b, i, l] + SCALE_DISTANCE) * v
                o[PREV_TRUST] = applied[b, i, l]
                o[JERK] = jk
                o[NIS] = nis[b, i, l] / (nis[b, i, l] + SCALE_NIS) * v
                for k in range(N_KINDS):
                    o[KIND0 + k] = one_hot[i, l, k]
                o[VALID] = v
                if with_state:
                    at = (i * n_l + l) * N_FEATURES
                    for f in range(N_FEATURES):
                        state[b, at + f] = o[f]
        if with_state:
            _state_tail(x, P, state, b, n * n_l * N_FEATURES)


@njit(cache=True)
def _fill(resid, pred, applied, jerk, nis, valid, one_hot, out, state, x, P):
    """``_fill_rows`` over the batch, on the calling thread."""
    _fill_rows(resid, pred, applied, jerk, nis, valid, one_hot, out, state, x, P, 0, resid.shape[0])


@njit(cache=True, parallel=True)
def _fill_threaded(resid, pred, applied, jerk, nis, valid, one_hot, out, state, x, P):
    """``_fill_rows`` with threads over blocks of ``BLOCK`` episodes."""
    n_b = resid.shape[0]
    for block in prange((n_b + BLOCK - 1) // BLOCK):
        lo, hi = block_bounds(block, n_b)
        _fill_rows(resid, pred, applied, jerk, nis, valid, one_hot, out, state, x, P, lo, hi)


@njit(cache=True, inline="always")
def _state_tail(x, P, state, b, at):
    """The state's part after the observation, from column ``at``: prior positions (N·3), velocities (N·3),
    √tr(P_pp) (N)."""
    n = x.shape[1]
    for i in range(n):
        for d in range(3):
            state[b, at + 3 * i + d] = x[b, i, d]
            state[b, at + 3 * n + 3 * i + d] = x[b, i, 3 + d]
        state[b, at + 6 * n + i] = math.sqrt(P[b, i, 0, 0] + P[b, i, 1, 1] + P[b, i, 2, 2])


@njit(cache=True, inline="always")
def _state_rows(obs, x, P, out, lo, hi):
    """``build_state`` for episodes lo..hi−1: the observation copied, then ``_state_tail``."""
    n, n_l, n_f = obs.shape[1], obs.shape[2], obs.shape[3]
    for b in range(lo, hi):
        k = 0
        for i in range(n):
            for l in range(n_l):
                for f in range(n_f):
                    out[b, k] = obs[b, i, l, f]
                    k += 1
        _state_tail(x, P, out, b, k)


@njit(cache=True)
def _state(obs, x, P, out):
    """``_state_rows`` over the batch, on the calling thread."""
    _state_rows(obs, x, P, out, 0, obs.shape[0])


@njit(cache=True, parallel=True)
def _state_threaded(obs, x, P, out):
    """``_state_rows`` with threads over blocks of ``BLOCK`` episodes."""
    n_b = obs.shape[0]
    for block in prange((n_b + BLOCK - 1) // BLOCK):
        lo, hi = block_bounds(block, n_b)
        _state_rows(obs, x, P, out, lo, hi)
