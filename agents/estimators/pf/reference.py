"""Straightforward per-UAV numpy version of the particle filter in ``core.py``.

The same maths and the same random numbers as the numba kernel, written the obvious way:
a Python loop over episodes and UAVs, numpy over particles, ``np.cumsum`` +
``np.searchsorted`` for systematic resampling. It is the oracle the kernel is tested
against and the baseline of the speed ratio in ``bench/speed/estimators.py``.

The counter-based generator of ``envs.rng`` is re-expressed here with numpy ``uint64``
arithmetic (SplitMix64 finaliser chained over the key), so whole particle sets draw their
numbers in one vectorised call; a test holds it equal to ``envs.rng.uniform``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from swarmloc.envs.tasks.channels import ANCHOR, GPS, LANDMARK, PEER
from swarmloc.envs.tasks.rng import Stream

from swarmloc.agents.estimators.pf.core import N_SLOTS, PARTICLE_STRIDE, SLOT_INIT, SLOT_PERTURB, SLOT_PROCESS, SLOT_RESAMPLE
from swarmloc.agents.estimators.pf.pfnn import PFNNWeights

_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)


def _mix(z: np.ndarray) -> np.ndarray:
    """SplitMix64 finaliser on a uint64 array (wrapping arithmetic)."""
    z = (z ^ (z >> np.uint64(30))) * _M1
    z = (z ^ (z >> np.uint64(27))) * _M2
    return z ^ (z >> np.uint64(31))


def uniform_np(key: int, step: int, indices: np.ndarray) -> np.ndarray:
    """``envs.rng.uniform(key, step, Stream.ESTIMATOR, index)`` for an index array."""
    one = np.ones(1, dtype=np.uint64)
    h = _mix(one * np.uint64(key) + _GOLDEN)
    h = _mix(h ^ (one * np.uint64(step + 1) * _GOLDEN))
    h = _mix(h ^ (one * np.uint64(int(Stream.ESTIMATOR)) * _M1))
    h = _mix(h ^ (np.asarray(indices, dtype=np.uint64) * _M2 + _GOLDEN))
    return ((h >> np.uint64(11)).astype(np.float64) + 0.5) * (1.0 / 9007199254740992.0)


def normal_pairs_np(key: int, step: int, base: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Box–Muller pairs from uniforms at ``base`` and ``base + 1`` (as ``core._normal_pair``)."""
    u1 = uniform_np(key, step, base)
    u2 = uniform_np(key, step, base + 1)
    r = np.sqrt(-2.0 * np.log(u1))
    return r * np.cos(2.0 * math.pi * u2), r * np.sin(2.0 * math.pi * u2)


def _base(uav: int, m: int, slot: int) -> np.ndarray:
    return (uav * PARTICLE_STRIDE + np.arange(m, dtype=np.int64)) * N_SLOTS + slot


def systematic_resample_reference(weights: np.ndarray, n_out: int, offset: float) -> np.ndarray:
    """Ancestor indices: the smallest i with ``cumsum(w)_i ≥ (j + U)/n_out`` (clipped to M − 1)."""
    c = np.cumsum(weights)
    u = (np.arange(n_out) + offset) / n_out
    return np.minimum(np.searchsorted(c, u, side="left"), weights.shape[0] - 1)


@dataclass
class ReferenceUAV:
    """One UAV's particle set: particles ``(M, 6)``, log weights ``(M,)``, estimate ``(6,)``."""

    x: np.ndarray
    logw: np.ndarray
    est: np.ndarray


class ReferenceParticleFilter:
    """Per-UAV numpy particle filter; same arguments and results as ``ParticleFilter``.

    Args:
        keys: ``(B,)`` per-episode random keys; x0: ``(B, N, 6)`` initial priors.
        kind, target, sigma: ``(N, L)`` channel layout; anchors ``(A, 3)``; landmarks ``(M, 3)``.
        dt: [s]; pos_sigma, vel_sigma: initial prior std; accel_sigma: process noise σ_a.
        config: a ``filters.PFConfig``; network: optional ``PFNNWeights`` (frozen).
    """

    def __init__(self, keys: np.ndarray, x0: np.ndarray, kind: np.ndarray, target: np.ndarray,
                 sigma: np.ndarray, anchors: np.ndarray, landmarks: np.ndarray, dt: float, pos_sigma: float,
                 vel_sigma: float, accel_sigma: float, config, network: PFNNWeights | None = None):
        self.keys = [int(k) for k in keys]
        self.kind, self.target, self.sigma = kind, target, sigma
        self.anchors, self.landmarks = np.asarray(anchors).reshape(-1, 3), np.asarray(landmarks).reshape(-1, 3)
        self.dt, self.accel_sigma, self.c, self.network = dt, accel_sigma, config, network
        n_b, n = x0.shape[:2]
        m = config.n_init
        std = np.array([pos_sigma] * 3 + [vel_sigma] * 3)
        self.uavs: list[list[ReferenceUAV]] = []
        for b in range(n_b):
            row = []
            for i in range(n):
                base = _base(i, m, SLOT_INIT)
                g = np.empty((m, 6))
                for pair in range(3):
                    g[:, 2 * pair], g[:, 2 * pair + 1] = normal_pairs_np(self.keys[b], 0, base + 2 * pair)
                row.append(ReferenceUAV(x=x0[b, i] + std * g, logw=np.full(m, -math.log(m)), est=x0[b, i].copy()))
            self.uavs.append(row)
        self.used = np.zeros((n_b, n), dtype=np.int64)
        self.ess = np.zeros((n_b, n))

    def positions(self) -> np.ndarray:
        """``(B, N, 3)`` current estimates."""
        return np.array([[u.est[:3] for u in row] for row in self.uavs])

    def step(self, step: int, imu: np.ndarray, z: np.ndarray, valid: np.ndarray) -> np.ndarray:
        """One filter step for every episode; returns ``(B, N, 3)`` estimates."""
        for b, row in enumerate(self.uavs):
            key = self.keys[b]
            prior_pos = np.empty((len(row), 3))
            for i, u in enumerate(row):
                self._predict(key, step, i, u, imu[b, i])
                prior_pos[i] = np.exp(u.logw) @ u.x[:, :3]
            for i, u in enumerate(row):
                self.used[b, i] = u.x.shape[0]
                self.ess[b, i] = self._update(key, step, i, u, z[b, i], valid[b, i], prior_pos)
        return self.positions()

    def _predict(self, key: int, step: int, i: int, u: ReferenceUAV, imu: np.ndarray) -> None:
        base = _base(i, u.x.shape[0], SLOT_PROCESS)
        g0, g1 = normal_pairs_np(key, step, base)
        g2, _ = normal_pairs_np(key, step, base + 2)
        # a = u + w;  p ← p + v dt + ½ a dt²;  v ← v + a dt
        a = imu + self.accel_sigma * np.stack([g0, g1, g2], axis=1)
        u.x[:, :3] = u.x[:, :3] + u.x[:, 3:] * self.dt + 0.5 * self.dt * self.dt * a
        u.x[:, 3:] = u.x[:, 3:] + a * self.dt

    def _update(self, key: int, step: int, i: int, u: ReferenceUAV, z: np.ndarray, valid: np.ndarray,
                prior_pos: np.ndarray) -> float:
        c = self.c
        m = u.x.shape[0]
        p = u.x[:, :3]
        ll = np.zeros(m)
        for l in np.flatnonzero(valid):
            kind, t, var = self.kind[i, l], self.target[i, l], self.sigma[i, l] ** 2
            if kind in (PEER, ANCHOR):
                q = prior_pos[t] if kind == PEER else self.anchors[t]
                r = z[l, 0] - np.linalg.norm(p - q, axis=1)
                ll -= 0.5 * r * r / var
            else:
                if kind == LANDMARK:
                    h = self.landmarks[t] - p
                elif kind == GPS:
                    h = p
                else:
                    h = prior_pos[t] - p
                ll -= 0.5 * np.sum((z[l] - h) ** 2, axis=1) / var
        if self.network is not None:
            y = self.network.forward(u.x - u.est)
            ll += np.log(c.correction_base + c.correction_gain * (y - 0.5))
        lw = u.logw + ll
        top = lw.max()
        lw = lw - (top + math.log(np.sum(np.exp(lw - top))))
        w = np.exp(lw)
        ess = 1.0 / np.sum(w * w)
        u.est = w @ u.x
        if ess < c.grow_below * m:
            m_new = min(m + c.grow_step, c.n_max)
        elif ess > c.shrink_above * m:
            m_new = max(m - c.shrink_step, c.n_min)
        else:
            m_new = m
        if ess < c.resample_below * m:
            offset = float(uniform_np(key, step, np.array([i * PARTICLE_STRIDE * N_SLOTS + SLOT_RESAMPLE]))[0])
            x = u.x[systematic_resample_reference(w, m_new, offset)]
            base = _base(i, m_new, SLOT_PERTURB)
            g = np.empty((m_new, 6))
            for pair in range(3):
                g[:, 2 * pair], g[:, 2 * pair + 1] = normal_pairs_np(key, step, base + 2 * pair)
            std = np.array([c.perturb_pos] * 3 + [c.perturb_vel] * 3)
            u.x = x + std * g
            u.logw = np.full(m_new, -math.log(m_new))
        elif m_new < m:
            keep = np.argsort(-lw, kind="mergesort")[:m_new]
            u.x = u.x[keep]
            u.logw = lw[keep] - math.log(np.sum(np.exp(lw[keep])))
        else:
            u.logw = lw
        return float(ess)
