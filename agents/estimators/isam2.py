"""``isam2-robust``: a fixed-lag factor-graph smoother over the swarm with robust measurement factors (gtsam).

Where the CEKF and the joint EKF (``centralized-oracle``) linearise every measurement once, at the
prior, and forget it, this estimator keeps the last ``lag`` seconds of the swarm's trajectory as a
factor graph and re-solves it each step (iSAM2: incremental Gauss–Newton on the Bayes tree,
relinearising the variables that moved; Kaess et al., "iSAM2", IJRR 2012). Older states are
marginalised out by gtsam's ``IncrementalFixedLagSmoother``, so the graph stays ``lag / dt`` steps
long. Each measurement factor carries an M-estimator on its whitened residual, so a gross error
(an NLOS range, a drifting fix) loses its pull instead of dragging the estimate (robust noise
models; Huber 1964; gtsam ``noiseModel.Robust``). Requires the ``factorgraph`` extra (gtsam).

**Variables**, per UAV i and step k: p_i^k and v_i^k, each a ``Point3`` [m], [m/s].

**Motion factor** between steps k−1 and k, from UAV i's accelerometer reading u (the CEKF's
constant-acceleration model, ``cekf_reference.transition``):

    e = [p^k − p^{k−1} − dt v^{k−1} − dt²/2 u,  v^k − v^{k−1} − dt u],   e ~ N(0, Q),
    Q = σ_imu² dt · [[dt³/3 I, dt²/2 I], [dt²/2 I, dt I]]

The CEKF's Q = σ_imu² G Gᵀ has rank 3 (a noise held constant over the step) and has no Gaussian
noise model; Q above is the continuous white-noise-acceleration form with the same velocity
variance σ_imu² dt² and covariance σ_imu² dt³/2, and dt⁴/3 instead of dt⁴/4 on the position: full
rank. The factor is linear; it is a ``CustomFactor`` with constant Jacobians [−I, −dt I, I, 0] and
[0, −I, 0, I] on (p^{k−1}, v^{k−1}, p^k, v^k). An accelerometer bias (``TaskFacts.imu_bias_sigma``)
and IMU faults are not modelled (as in the CEKF).

**Measurement factors** on the step's valid channels, each with the channel's nominal σ
(``TaskFacts.sigma``) under the robust kernel:

| kind | factor | residual |
|---|---|---|
| anchor | ``CustomFactor`` on p_i | z − ‖p_i − a‖ |
| TDOA (a, b) | ``CustomFactor`` on p_i | z − (‖p_i − a_b‖ − ‖p_i − a_a‖) |
| GPS | ``PriorFactorPoint3`` on p_i | z − p_i |
| landmark | ``PriorFactorPoint3`` on p_i at m − z | (m − z) − p_i |
| peer range | ``RangeFactor3`` (Point3–Point3) on (p_i, p_j) | z − ‖p_i − p_j‖ |
| peer relative position | ``BetweenFactorPoint3`` on (p_i, p_j) | z − (p_j − p_i) |

A peer factor is a true joint factor on both UAVs' positions (UAV i's channel to j and j's channel
to i are two measurements, each used once). Visual odometry, where the task has it, is a
``PriorFactorPoint3`` on v_i^k with ``TaskFacts.velocity_sigma`` (robust too). The initial prior
(``TaskFacts.x0`` with ``init_pos_sigma``, ``init_vel_sigma``) is Gaussian.

**Robust kernel** (:class:`ISAM2Config`): Huber with threshold k = 1.345 σ by default (95 %
efficiency under Gaussian noise), ρ(r) = r²/2 for |r| ≤ k, k|r| − k²/2 beyond, on the whitened
residual r (the norm of the whitened 3-vector for a vector channel); iSAM2 applies it as the
iteratively reweighted weight w = min(1, k/|r|) at each relinearisation. ``cauchy`` (k = 2.3849)
and ``gaussian`` (no kernel: the non-robust smoother, for the tests) are the alternatives.

**Solver**: ``gtsam.IncrementalFixedLagSmoother`` (ISAM2 inside; one iSAM2 update, i.e. one
Gauss–Newton step on the relinearised variables, per filter step; relinearisation threshold
0.01, checked every update), lag ``ISAM2Config.lag`` = 2 s. The output is the latest estimate of
each p_i^k and, for the NEES, its marginal covariance from the Bayes tree.

One smoother per episode: the episodes of a batch never share a number, so an episode gives the
same result alone or batched (``tests/test_isam2.py``). Not reported: FLOPs (a sparse
re-factorisation has no fixed count).
"""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np

from swarmloc.envs.tasks.channels import ANCHOR, GPS, LANDMARK, PEER, PEER_REL, TDOA, tdoa_pair

from swarmloc.agents.protocols import EstimatorOutput, Measurements, TaskFacts, UnsupportedTask

#: a range shorter than this has no direction: the channel is skipped (as the CEKF does)
_MIN_RANGE = 1e-9
#: the robust kernels and their default thresholds in σ (95 % efficiency under Gaussian noise)
KERNEL_THRESHOLD = {"huber": 1.345, "cauchy": 2.3849, "gaussian": float("inf")}


@dataclass(frozen=True)
class ISAM2Config:
    """Settings of the smoother.

    Attributes:
        lag: the fixed lag [s]: states older than this are marginalised out.
        kernel: robust kernel of every measurement factor, ``"huber"``, ``"cauchy"`` or ``"gaussian"`` (none).
        threshold: the kernel's threshold k in units of σ; None: ``KERNEL_THRESHOLD[kernel]``.
        relinearize_threshold: iSAM2 relinearises a variable whose update exceeds this (in its tangent space).
        covariance: report each UAV's marginal position covariance (costs a Bayes-tree marginal per UAV).
        max_uavs: the largest swarm it runs; a task with more UAVs is refused (``UnsupportedTask``), see
            ``MAX_UAVS``. None: any.
    """

    lag: float = 2.0
    kernel: str = "huber"
    threshold: float | None = None
    relinearize_threshold: float = 0.01
    covariance: bool = True
    max_uavs: int | None = None

    @property
    def k(self) -> float:
        """The kernel threshold in σ."""
        return KERNEL_THRESHOLD[self.kernel] if self.threshold is None else float(self.threshold)


def motion_covariance(dt: float, imu_sigma: float) -> np.ndarray:
    """``(6, 6)`` Q of the motion factor over [p, v]: σ² dt [[dt³/3 I, dt²/2 I], [dt²/2 I, dt I]] (module docstring)."""
    q = imu_sigma**2 * dt
    per_axis = q * np.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])
    return np.kron(per_axis, np.eye(3))


def _motion_factor(keys: list[int], imu: np.ndarray, dt: float, noise) -> gtsam.CustomFactor:
    """The motion factor on (p^{k−1}, v^{k−1}, p^k, v^k) for one accelerometer reading ``imu`` ``(3,)``."""
    eye = np.eye(3)
    zero = np.zeros((3, 3))
    jac = [np.vstack([-eye, zero]), np.vstack([-dt * eye, -eye]), np.vstack([eye, zero]), np.vstack([zero, eye])]
    dp, dv = 0.5 * dt * dt * imu, dt * imu

    def error(this: gtsam.CustomFactor, values: gtsam.Values, jacobians) -> np.ndarray:
        p0, v0 = values.atPoint3(keys[0]), values.atPoint3(keys[1])
        p1, v1 = values.atPoint3(keys[2]), values.atPoint3(keys[3])
        if jacobians is not None:
            for slot, value in enumerate(jac):
                jacobians[slot] = value
        # e = [p⁺ − p − dt v − dt²/2 u, v⁺ − v − dt u]
        return np.concatenate([p1 - p0 - dt * v0 - dp, v1 - v0 - dv])

    return gtsam.CustomFactor(noise, keys, error)


def _range_factor(key: int, z: float, a: np.ndarray, b: np.ndarray | None, noise) -> gtsam.CustomFactor:
    """A range to the fixed point ``a`` (``b`` None: h = ‖p − a‖) or a TDOA (h = ‖p − b‖ − ‖p − a‖)."""

    def error(this: gtsam.CustomFactor, values: gtsam.Values, jacobians) -> np.ndarray:
        p = values.atPoint3(key)
        d = p - a
        r = max(float(np.linalg.norm(d)), _MIN_RANGE)
        h, J = r, d / r
        if b is not None:
            d_b = p - b
            r_b = max(float(np.linalg.norm(d_b)), _MIN_RANGE)
            h, J = r_b - r, d_b / r_b - J
        if jacobians is not None:
            jacobians[0] = J.reshape(1, 3)
        # the error is h − z (gtsam's convention: its Jacobian is ∂h/∂p)
        return np.array([h - z])

    return gtsam.CustomFactor(noise, [key], error)


class ChannelModels:
    """Per channel the fixed point(s) and the robust noise model, built once per reset.

    Args:
        facts: the task's facts (kind, target, sigma, anchors, landmarks).
        config: the kernel.
    """

    def __init__(self, facts: TaskFacts, config: ISAM2Config) -> None:
        n, n_l = facts.kind.shape
        self.kind = np.asarray(facts.kind, dtype=np.int64)
        self.target = np.asarray(facts.target, dtype=np.int64)
        self.point: dict[tuple[int, int], np.ndarray] = {}
        self.point_b: dict[tuple[int, int], np.ndarray] = {}
        self.noise: dict[tuple[int, int], object] = {}
        anchors = np.asarray(facts.anchors, dtype=np.float64)
        for i in range(n):
            for l in range(n_l):
                k, t = int(self.kind[i, l]), int(self.target[i, l])
                if k == ANCHOR:
                    self.point[i, l] = anchors[t].copy()
                elif k == LANDMARK:
                    self.point[i, l] = np.asarray(facts.landmarks[t], dtype=np.float64).copy()
                elif k == TDOA:
                    a, b = tdoa_pair(t, len(anchors))
                    self.point[i, l], self.point_b[i, l] = anchors[a].copy(), anchors[b].copy()
                dim = 1 if k in (ANCHOR, PEER, TDOA) else 3
                self.noise[i, l] = robust_noise(dim, float(facts.sigma[i, l]), config)
        self.velocity = None if facts.velocity_sigma is None else robust_noise(3, facts.velocity_sigma, config)


def robust_noise(dim: int, sigma: float, config: ISAM2Config):
    """An isotropic noise model of std ``sigma`` under the configured kernel (none for ``gaussian``)."""
    base = gtsam.noiseModel.Isotropic.Sigma(dim, sigma)
    if config.kernel == "gaussian":
        return base
    if config.kernel == "huber":
        kernel = gtsam.noiseModel.mEstimator.Huber.Create(config.k)
    elif config.kernel == "cauchy":
        kernel = gtsam.noiseModel.mEstimator.Cauchy.Create(config.k)
    else:
        raise ValueError(f"kernel must be one of {sorted(KERNEL_THRESHOLD)}, got {config.kernel!r}")
    return gtsam.noiseModel.Robust.Create(kernel, base)


class EpisodeGraph:
    """The fixed-lag smoother of one episode: its keys, its latest estimate and its factors per step."""

    def __init__(self, x0: np.ndarray, facts: TaskFacts, config: ISAM2Config) -> None:
        params = gtsam.ISAM2Params()
        params.setRelinearizeThreshold(config.relinearize_threshold)
        params.relinearizeSkip = 1
        self.smoother = gtsam.IncrementalFixedLagSmoother(config.lag, params)
        self.n = facts.n_uav
        self.x = np.array(x0, dtype=np.float64)  # (N, 6) the latest estimate [p, v]
        graph, values, stamps = gtsam.NonlinearFactorGraph(), gtsam.Values(), {}
        prior_p = gtsam.noiseModel.Isotropic.Sigma(3, facts.init_pos_sigma)
        prior_v = gtsam.noiseModel.Isotropic.Sigma(3, facts.init_vel_sigma)
        for i in range(self.n):
            kp, kv = self.keys(0, i)
            graph.add(gtsam.PriorFactorPoint3(kp, self.x[i, :3], prior_p))
            graph.add(gtsam.PriorFactorPoint3(kv, self.x[i, 3:], prior_v))
            values.insertPoint3(kp, self.x[i, :3])
            values.insertPoint3(kv, self.x[i, 3:])
            stamps[kp] = stamps[kv] = 0.0
        self.smoother.update(graph, values, stamps)

    def keys(self, k: int, i: int) -> tuple[int, int]:
        """The keys of p_i^k and v_i^k."""
        return gtsam.symbol("p", k * self.n + i), gtsam.symbol("v", k * self.n + i)

    def step(self, k: int, t: float, imu: np.ndarray, z: np.ndarray, valid: np.ndarray, velocity: np.ndarray | None,
             models: ChannelModels, dt: float, motion_noise, covariance: bool) -> tuple[np.ndarray, np.ndarray | None]:
        """Add step ``k``'s states and factors (``imu`` ``(N, 3)``, ``z`` ``(N, L, 3)``, ``valid`` ``(N, L)``,
        ``velocity`` ``(N, 3)`` or None), update the smoother; returns positions ``(N, 3)`` and covariances."""
        graph, values, stamps = gtsam.NonlinearFactorGraph(), gtsam.Values(), {}
        for i in range(self.n):
            kp0, kv0 = self.keys(k - 1, i)
            kp, kv = self.keys(k, i)
            p, v = self.x[i, :3], self.x[i, 3:]
            # initial guess: the IMU prediction from the latest estimate
            values.insertPoint3(kp, p + dt * v + 0.5 * dt * dt * imu[i])
            values.insertPoint3(kv, v + dt * imu[i])
            stamps[kp] = stamps[kv] = t
            graph.add(_motion_factor([kp0, kv0, kp, kv], imu[i], dt, motion_noise))
            if velocity is not None and models.velocity is not None:
                graph.add(gtsam.PriorFactorPoint3(kv, velocity[i], models.velocity))
        for i, l in zip(*np.nonzero(valid)):
            graph.add(self._channel_factor(int(i), int(l), z[i, l], k, models))
        self.smoother.update(graph, values, stamps)
        pos = np.empty((self.n, 3))
        for i in range(self.n):
            kp, kv = self.keys(k, i)
            pos[i] = self.smoother.calculateEstimatePoint3(kp)
            self.x[i, :3], self.x[i, 3:] = pos[i], self.smoother.calculateEstimatePoint3(kv)
        cov = np.stack([self.smoother.marginalCovariance(self.keys(k, i)[0]) for i in range(self.n)]) \
            if covariance else None
        return pos, cov

    def _channel_factor(self, i: int, l: int, z: np.ndarray, k: int, models: ChannelModels):
        """The factor of UAV i's channel l (the module docstring's table)."""
        kind, noise = int(models.kind[i, l]), models.noise[i, l]
        kp = self.keys(k, i)[0]
        if kind == ANCHOR:
            return _range_factor(kp, float(z[0]), models.point[i, l], None, noise)
        if kind == TDOA:
            return _range_factor(kp, float(z[0]), models.point[i, l], models.point_b[i, l], noise)
        if kind == GPS:
            return gtsam.PriorFactorPoint3(kp, np.array(z, dtype=np.float64), noise)
        if kind == LANDMARK:
            return gtsam.PriorFactorPoint3(kp, models.point[i, l] - z, noise)
        kj = self.keys(k, int(models.target[i, l]))[0]
        if kind == PEER:
            return gtsam.RangeFactor3(kp, kj, float(z[0]), noise)
        if kind == PEER_REL:
            return gtsam.BetweenFactorPoint3(kp, kj, np.array(z, dtype=np.float64), noise)
        raise ValueError(f"channel kind {kind} of UAV {i}, slot {l} is not one of the kinds {ANCHOR}..{TDOA}")


class ISAM2Robust:
    """A fixed-lag iSAM2 smoother per episode over the swarm's positions and velocities, robust factors."""

    privileged = False
    deterministic = True

    def __init__(self, config: ISAM2Config | None = None) -> None:
        self.config = config or ISAM2Config()
        self._facts: TaskFacts | None = None

    def reset(self, facts: TaskFacts, x0: np.ndarray) -> None:
        """Start B episodes at the prior ``x0`` ``(B, N, 6)`` with the task's initial std.

        Raises:
            UnsupportedTask: the swarm has more than ``config.max_uavs`` UAVs.
        """
        if self.config.max_uavs is not None and facts.n_uav > self.config.max_uavs:
            raise UnsupportedTask(f"{facts.n_uav} UAVs: isam2-robust runs swarms of at most {self.config.max_uavs} "
                                  f"(a swarm of fully connected peers re-solves a dense graph each step; see MAX_UAVS)")
        if np.shape(x0) != (facts.batch_size, facts.n_uav, 6):
            raise ValueError(f"x0 must have shape (B, N, 6) = {(facts.batch_size, facts.n_uav, 6)}, "
                             f"got {np.shape(x0)}")
        self._facts = facts
        self.models = ChannelModels(facts, self.config)
        self.motion_noise = gtsam.noiseModel.Gaussian.Covariance(motion_covariance(facts.dt, facts.imu_sigma))
        self.graphs = [EpisodeGraph(x0[b], facts, self.config) for b in range(facts.batch_size)]

    def step(self, meas: Measurements) -> EstimatorOutput:
        """Add the step's motion and measurement factors to every episode's graph and re-solve.

        Returns:
            Positions ``(B, N, 3)`` (the latest estimate) and, with ``config.covariance``, their marginal
            covariances ``(B, N, 3, 3)``.
        """
        f = self._facts
        if f is None:
            raise RuntimeError("call reset(facts, x0) before step()")
        imu = np.asarray(meas.imu, dtype=np.float64)
        z = np.asarray(meas.z, dtype=np.float64)
        valid = np.asarray(meas.valid, dtype=bool)
        vel = None if meas.velocity is None else np.asarray(meas.velocity, dtype=np.float64)
        out = [g.step(meas.step, meas.t, imu[b], z[b], valid[b], None if vel is None else vel[b], self.models, f.dt,
                      self.motion_noise, self.config.covariance) for b, g in enumerate(self.graphs)]
        pos = np.stack([p for p, _ in out])
        cov = np.stack([c for _, c in out]) if self.config.covariance else None
        return EstimatorOutput(positions=pos, cov=cov)


#: the largest swarm the registered ``isam2-robust`` runs. Every UAV of a Scale task ranges to
#: every other, so the smoother's window couples all N positions at every step and each update
#: re-factorises a dense block of the whole swarm, through Python-side factors: measured on the
#: 2-core machine beside two training runs, 5 s of flight cost 22 s at N = 8, 44 s at N = 16 and
#: 442 s at N = 32 (Scale*-v2), i.e. about 3 min, 6 min and 1 h per 40 s episode, 40 hours for
#: standard-v2's Scale family; 6 admits GradualFault (6 UAVs, followers ranging to leaders only:
#: 0.1 s per 5 s) and every one-UAV task. A faster graph (keyframes, linear motion factors in C++)
#: would lift it; ``ISAM2Robust(ISAM2Config())`` runs any N.
MAX_UAVS = 6


def isam2_robust() -> ISAM2Robust:
    """Registry factory: ``isam2-robust`` (swarms of at most ``MAX_UAVS``)."""
    return ISAM2Robust(ISAM2Config(max_uavs=MAX_UAVS))
