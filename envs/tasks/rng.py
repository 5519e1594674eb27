"""Counter-based random numbers keyed by (seed, step, stream, index).

Every random draw in the world is a pure function of its key, so a batched world with
seeds ``[s0..sB-1]`` reproduces exactly the B single worlds with those seeds, in any
process and in any evaluation order (no generator state to advance). The hash is the
SplitMix64 finaliser applied in a chain over the key fields; uniforms take the top 53
bits, normals use Box–Muller on two uniforms drawn at sub-indices ``2k`` and ``2k+1``.

Streams are small integers naming what a draw is for (see ``Stream``); the index names
the element (e.g. ``uav * L + channel``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from enum import IntEnum

import numpy as np
from numba import njit

_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S11 = np.uint64(11)
_TWO_M53 = 1.0 / 9007199254740992.0  # 2^-53


class Stream(IntEnum):
    """What a random draw is for; part of its key so streams never share numbers."""

    INIT = 1
    TRAJECTORY = 2
    IMU = 3
    ANCHOR = 4
    PEER = 5
    LANDMARK = 6
    GPS = 7
    PACKET_LOSS = 8
    NLOS_ONSET = 9
    NLOS_PROCESS = 10
    NLOS_UNIFORM = 11
    HYBRID_MIX = 12
    SCHEDULE = 13
    POLICY = 14
    ESTIMATOR = 15
    VELOCITY = 16


@njit(cache=True, inline="always")
def _mix(z: np.uint64) -> np.uint64:
    # SplitMix64 finaliser: a bijective avalanche on 64 bits.
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@njit(cache=True, inline="always")
def stream_key(seed: int, step: int, stream: int) -> np.uint64:
    """The hash of a draw's key up to its index: three of the four SplitMix64 rounds.

    A kernel that draws many elements of one stream in one step computes this once and
    finishes each draw with ``uniform_at`` / ``normal_at`` (one round each); the numbers
    are the same as ``uniform`` / ``normal`` on the full key.
    """
    h = _mix(np.uint64(seed) + _GOLDEN)
    h = _mix(h ^ (np.uint64(step + 1) * _GOLDEN))
    return _mix(h ^ (np.uint64(stream) * _M1))


@njit(cache=True, inline="always")
def hash_key(seed: int, step: int, stream: int, index: int) -> np.uint64:
    """64-bit hash of a draw's key (seed, step, stream, index)."""
    return _mix(stream_key(seed, step, stream) ^ (np.uint64(index) * _M2 + _GOLDEN))


@njit(cache=True, inline="always")
def uniform_at(key: np.uint64, index: int) -> float:
    """Uniform draw in (0, 1) of element ``index`` of the stream ``key = stream_key(...)``."""
    h = _mix(key ^ (np.uint64(index) * _M2 + _GOLDEN))
    return (float(h >> _S11) + 0.5) * _TWO_M53


@njit(cache=True, inline="always")
def normal_at(key: np.uint64, index: int) -> float:
    """Standard normal draw (Box–Muller on sub-indices 2·index and 2·index+1) of stream ``key``."""
    u1 = uniform_at(key, 2 * index)
    u2 = uniform_at(key, 2 * index + 1)
    return math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)


@njit(cache=True, inline="always")
def student_t_at(key: np.uint64, index: int, dof: int) -> float:
    """Student-t draw with integer ``dof`` of stream ``key``: z / sqrt(χ²_dof / dof), χ² a sum of squares."""
    z = normal_at(key, index * 64)
    chi2 = 0.0
    for k in range(dof):
        g = normal_at(key, index * 64 + 1 + k)
        chi2 += g * g
    return z / math.sqrt(chi2 / dof)


@njit(cache=True, inline="always")
def uniform(seed: int, step: int, stream: int, index: int) -> float:
    """Uniform draw in the open interval (0, 1)."""
    return uniform_at(stream_key(seed, step, stream), index)


@njit(cache=True, inline="always")
def normal(seed: int, step: int, stream: int, index: int) -> float:
    """Standard normal draw (Box–Muller on sub-indices 2·index and 2·index+1)."""
    return normal_at(stream_key(seed, step, stream), index)


@njit(cache=True, error_model="numpy")
def student_t(seed: int, step: int, stream: int, index: int, dof: int) -> float:
    """Student-t draw with integer ``dof``: z / sqrt(χ²_dof / dof), χ² as a sum of squares."""
    return student_t_at(stream_key(seed, step, stream), index, dof)


def _draw_array(draw: Callable[[int, int, int, int], float], seed: int, step: int, stream: int,
                indices: np.ndarray) -> np.ndarray:
    """``draw(seed, step, stream, index)`` for every entry of an integer index array, in its shape."""
    out = np.empty(indices.shape, dtype=np.float64)
    flat = indices.ravel()
    res = out.ravel()
    for k in range(flat.size):
        res[k] = draw(seed, step, stream, int(flat[k]))
    return out


def uniform_array(seed: int, step: int, stream: int, indices: np.ndarray) -> np.ndarray:
    """Vectorised ``uniform`` over an integer index array (Python-side helper)."""
    return _draw_array(uniform, seed, step, stream, indices)


def normal_array(seed: int, step: int, stream: int, indices: np.ndarray) -> np.ndarray:
    """Vectorised ``normal`` over an integer index array (Python-side helper)."""
    return _draw_array(normal, seed, step, stream, indices)
