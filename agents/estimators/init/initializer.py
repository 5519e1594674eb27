"""MDS-MAP swarm initializer usable by any estimator: x₀ from the first second (dtvirm §3.3).

``MdsMapInitializer`` collects, step by step, the peer ranges and every UAV's displacement
(integrated visual-odometry velocity, or IMU double integration from the prior velocity
where the task has no VO) during a ``window`` (default 1 s); when it is full, ``solve``
returns the swarm's state at the current step, in dtvirm's frame: node 0's position at
the first step is the origin, axes ENU.

Method. (1) MDS-MAP (``mdsmap_init``, Algorithm 2): range epochs at ``epochs`` steps
spread over the window, node 0's known moves between them (its own integrated VO, the
"VIO + compass" displacement of §3.3), altitudes taken level (the swarm flies at one
nominal altitude; our world has no barometer). Both mirror images are computed (node 0's
move is usually straight, which leaves the reflection across it undetermined). (2) Each
image, also rotated about node 0 by k·360°/``yaw_starts`` (a short move leaves MDS-MAP's
yaw uncertain and the cost has local minima), is refined by Levenberg–Marquardt on
*every* range of the window with the model
‖pᵢ + Δᵢ(k) − pⱼ − Δⱼ(k)‖ = dᵢⱼ(k), where Δ(k) are the integrated displacements: the
other UAVs move too (MDS-MAP assumes them still), and their world-frame motion fixes the
yaw and the mirror. A weak prior keeps the altitudes level (σ ``altitude_sigma``). The
start with the smallest final cost wins. (3) The state at the current step is pᵢ + Δᵢ(K)
with the latest VO velocity.

Batch shapes: B episodes, N UAVs, K steps in the window.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmloc.envs.tasks.channels import PEER

from swarmloc.agents.protocols import Measurements, TaskFacts
from swarmloc.agents.estimators.init.mdsmap import mdsmap_init


@dataclass(frozen=True)
class InitConfig:
    """Settings of the MDS-MAP initializer."""

    window: float = 1.0
    """Seconds of ranging collected before solving (dtvirm: the first short move)."""
    epochs: int = 5
    """Range epochs handed to MDS-MAP (the first step plus ``epochs − 1`` after node 0's moves)."""
    refine_iters: int = 20
    """Levenberg–Marquardt iterations of the refinement (0: MDS-MAP only, mirror by ``side=+1``)."""
    altitude_sigma: float = 1.0
    """Prior std of each UAV's altitude about node 0's [m] (level-flight prior)."""
    yaw_starts: int = 8
    """Refinement starts per mirror image: the MDS-MAP layout rotated about node 0 by k·360°/yaw_starts."""

    def __post_init__(self) -> None:
        if not self.window > 0:
            raise ValueError(f"window must be > 0 s, got {self.window}")
        if self.epochs < 2:
            raise ValueError(f"epochs must be >= 2 (one before and one after a move), got {self.epochs}")
        if self.refine_iters < 0:
            raise ValueError(f"refine_iters must be >= 0, got {self.refine_iters}")
        if not self.altitude_sigma > 0:
            raise ValueError(f"altitude_sigma must be > 0, got {self.altitude_sigma}")
        if self.yaw_starts < 1:
            raise ValueError(f"yaw_starts must be >= 1, got {self.yaw_starts}")


def refine_with_odometry(p0: np.ndarray, D: np.ndarray, disp: np.ndarray, sigma: float, altitude_sigma: float,
                         iters: int) -> tuple[np.ndarray, float]:
    """Levenberg–Marquardt on start positions given ranges of moving UAVs with known displacements.

    Minimizes Σₖ Σᵢⱼ (‖pᵢ + Δᵢ(k) − pⱼ − Δⱼ(k)‖ − dᵢⱼ(k))² / σ² + Σᵢ zᵢ² / σ_z² over
    p₁ … p_{N−1} (node 0 fixed at the origin).

    Args:
        p0: (N, 3) starting guess, ``p0[0] == 0``.
        D: (K, N, N) ranges, NaN where missing (both directions used).
        disp: (K, N, 3) displacement of each UAV since the first step.
        sigma: range noise std [m]; altitude_sigma: altitude prior std [m].
        iters: iterations.

    Returns:
        The refined (N, 3) positions and the final cost.
    """
    K, N = D.shape[:2]
    k, i, j = np.nonzero(np.isfinite(D) & ~np.eye(N, dtype=bool)[None])
    d = D[k, i, j]
    ki, kj = k * N + i, k * N + j  # rows of the flattened (K·N, 3) positions
    p = p0.copy()

    def offsets(pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        q = (pos[None] + disp).reshape(K * N, 3)
        u = q[ki] - q[kj]
        return u, np.maximum(np.sqrt(np.einsum("md,md->m", u, u)), 1e-9)

    def residuals(pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        u, dist = offsets(pos)
        return (dist - d) / sigma, u / dist[:, None]

    def cost(pos: np.ndarray) -> float:
        r = (offsets(pos)[1] - d) / sigma
        return float(r @ r + np.sum((pos[1:, 2] / altitude_sigma) ** 2))

    c = cost(p)
    mu = 1e-3
    n_u = 3 * (N - 1)
    # a range's Jacobian row is +gᵀ/σ on pᵢ and −gᵀ/σ on pⱼ (g the unit vector from j to i), so
    # JᵀJ is a sum of ±g gᵀ/σ² blocks at (i, i), (j, j), (i, j), (j, i) and Jᵀr of ±g r/σ at i and j:
    # accumulated per block instead of through the dense (ranges × 3N) Jacobian
    pair = i * N + j
    z_cols = 3 * np.arange(N - 1) + 2  # altitude prior rows zᵢ / σ_z act on these unknowns alone
    for _ in range(iters):
        r, g = residuals(p)
        gg = (g[:, :, None] * g[:, None, :]).reshape(-1, 9) / sigma**2
        # C[a, b] = Σ g gᵀ/σ² over the ranges measured by a to b
        C = np.stack([np.bincount(pair, gg[:, e], N * N) for e in range(9)], axis=-1).reshape(N, N, 3, 3)
        blocks = -(C + C.transpose(1, 0, 2, 3))  # (a, b) ← −C[a, b] − C[b, a] (each block symmetric)
        blocks[np.arange(N), np.arange(N)] = C.sum(axis=1) + C.sum(axis=0)
        A = blocks.transpose(0, 2, 1, 3).reshape(3 * N, 3 * N)[3:, 3:]
        gr = g * (r / sigma)[:, None]
        b = np.stack([np.bincount(i, gr[:, e], N) - np.bincount(j, gr[:, e], N) for e in range(3)], axis=-1)
        b = b[1:].reshape(n_u)
        A[z_cols, z_cols] += 1.0 / altitude_sigma**2
        b[z_cols] += p[1:, 2] / altitude_sigma**2
        while True:
            # (JᵀJ + μ diag(JᵀJ)) δ = −Jᵀ r
            delta = np.linalg.solve(A + mu * np.diag(np.diag(A) + 1e-9), -b)
            trial = p.copy()
            trial[1:] += delta.reshape(N - 1, 3)
            c_new = cost(trial)
            if c_new < c:
                p, c, mu = trial, c_new, max(mu / 3.0, 1e-9)
                break
            mu *= 4.0
            if mu > 1e9:
                return p, c
    return p, c


class MdsMapInitializer:
    """Collects the first ``window`` seconds and solves the swarm's state (see the module doc).

    Args:
        facts: the task's public facts (peer channels, dt, VO availability, prior velocity).
        config: settings.
    """

    def __init__(self, facts: TaskFacts, config: InitConfig | None = None) -> None:
        self.config = config or InitConfig()
        kind = np.asarray(facts.kind)
        if not (kind == PEER).any():
            raise ValueError(f"MDS-MAP needs peer ranges; task {facts.task_id} has none")
        if facts.n_uav < 3:
            raise ValueError(f"MDS-MAP needs N >= 3 UAVs, task {facts.task_id} has {facts.n_uav}")
        self.n_steps = max(int(round(self.config.window / facts.dt)), self.config.epochs)
        B, N = facts.batch_size, facts.n_uav
        self._peer = (kind == PEER) & np.asarray(facts.linked)
        self._target = np.asarray(facts.target)
        self._dt = facts.dt
        self._sigma = float(np.median(np.asarray(facts.sigma)[self._peer]))
        self.D = np.full((self.n_steps, B, N, N), np.nan)
        self.disp = np.zeros((self.n_steps, B, N, 3))
        self._vel = np.array(facts.x0[..., 3:], dtype=np.float64)  # VO or IMU-integrated velocity
        self._k = 0

    @property
    def ready(self) -> bool:
        """True once the window is full (``solve`` may be called)."""
        return self._k >= self.n_steps

    def observe(self, meas: Measurements) -> bool:
        """Record one step's ranges and displacements; returns ``ready``."""
        if self.ready:
            return True
        k = self._k
        ii, ll = np.nonzero(self._peer)
        r = meas.z[:, ii, ll, 0]
        self.D[k][:, ii, self._target[ii, ll]] = np.where(meas.valid[:, ii, ll], r, np.nan)
        if meas.velocity is not None:
            v_new = np.asarray(meas.velocity, dtype=np.float64)
        else:  # no VO: integrate the accelerometer from the prior velocity
            v_new = self._vel + self._dt * np.asarray(meas.imu)
        if k > 0:
            # Δ(k) = Δ(k−1) + ½ (v(k−1) + v(k)) dt (trapezoid)
            self.disp[k] = self.disp[k - 1] + 0.5 * self._dt * (self._vel + v_new)
        self._vel = v_new
        self._k += 1
        return self.ready

    def solve(self) -> np.ndarray:
        """(B, N, 6) state at the last observed step, node 0's first position the origin."""
        if not self.ready:
            raise RuntimeError(f"the initializer has {self._k} of {self.n_steps} steps; observe more first")
        cfg = self.config
        K, B, N = self.n_steps, self.D.shape[1], self.D.shape[2]
        ep = np.unique(np.linspace(0, K - 1, cfg.epochs).round().astype(int))
        D_pre = self.D[ep[0]]
        D_post = np.moveaxis(self.D[ep[1:]], 0, 1)  # (B, E−1, N, N)
        track = self.disp[ep, :, 0]  # (E, B, 3) node 0's displacement at each epoch
        dX = np.moveaxis(np.diff(track, axis=0), 0, 1)
        dX[..., 2] = 0.0  # level track: MDS-MAP works in the horizontal plane
        z = np.zeros((B, N))
        out = np.zeros((B, N, 6))
        for b in range(B):
            best, best_cost = None, np.inf
            for side in (1, -1):
                try:
                    p = mdsmap_init(D_pre[b], D_post[b], dX[b], z[b], side=side)
                except ValueError:  # node 0 did not move horizontally, or the range graph broke
                    p = np.zeros((N, 3))
                    p[1:, 0] = np.arange(1, N)
                if not cfg.refine_iters:
                    if side == 1:
                        best, best_cost = p, 0.0
                    continue
                for a in 2.0 * np.pi * np.arange(cfg.yaw_starts) / cfg.yaw_starts:
                    # the layout rotated about node 0 (the origin) by a: a yaw error MDS-MAP may have made
                    c_a, s_a = np.cos(a), np.sin(a)
                    start = p @ np.array([[c_a, s_a, 0.0], [-s_a, c_a, 0.0], [0.0, 0.0, 1.0]])
                    q, c = refine_with_odometry(start, self.D[:, b], self.disp[:, b], self._sigma,
                                                cfg.altitude_sigma, cfg.refine_iters)
                    if c < best_cost:
                        best, best_cost = q, c
            out[b, :, :3] = best + self.disp[-1, b]
        out[..., 3:] = self._vel
        return out
