"""Particle-filter estimators (Track B): ``pf``, ``pf-800``, ``adaptive-pf``, ``pf-nn`` and the
privileged ``pf-nn-online-oracle``.

All share one batched kernel (``core.pf_step``) and differ in configuration:

| method | particles | network |
|---|---|---|
| ``pf`` | fixed 500 | — |
| ``pf-800`` | fixed 800 | — |
| ``adaptive-pf`` | 300 at start, ESS-adaptive in [100, 800] | — |
| ``pf-nn`` | as ``adaptive-pf`` | frozen, trained offline on training seeds (the fit of the task's benchmark version) |
| ``pf-nn-online-oracle`` | as ``adaptive-pf`` | the paper's online training on ground truth (privileged) |

Each estimator receives only :class:`TaskFacts` and :class:`Measurements` (no truth); the
oracle additionally receives the true positions through ``observe_privileged`` and is
shown apart. FLOPs per UAV-step are counted from the particle count actually used.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numba
import numpy as np

from swarmloc.agents.protocols import EstimatorOutput, Measurements, PrivilegedInfo, TaskFacts, UnsupportedTask
from swarmloc.envs.tasks.channels import ANCHOR, GPS, LANDMARK, PEER, PEER_REL, TDOA
from swarmloc.envs.tasks.rng import uniform

from swarmloc.agents.estimators.pf import core
from swarmloc.agents.estimators.pf.pfnn import PFNNWeights, load_weights, random_weights, sgd_step, shipped_weights

_INT = np.int64
#: below this many particle slots (B·N·M_max) one thread beats the pool's synchronisation
PARALLEL_MIN_PARTICLES = 40_000


@dataclass(frozen=True)
class PFConfig:
    """Particle-filter settings (pf-nn Table 2 where the paper states them).

    Attributes:
        n_init: particles per UAV at the start (pf-nn: 300 for the adaptive filter).
        n_min: fewest particles the adaptive rule may reach (100).
        n_max: most particles; the static buffer size (800). ``n_min == n_max`` fixes the count.
        resample_below: resample when ESS < this × M (0.5).
        grow_below: add ``grow_step`` particles when ESS < this × M (0.3).
        shrink_above: drop ``shrink_step`` particles when ESS > this × M (0.8).
        grow_step: particles added (100).
        shrink_step: particles removed (50).
        accel_inflation: process-noise std σ_a as a multiple of the task's nominal IMU σ.
        perturb_pos: roughening std added to positions after resampling [m] (Σ_perturb).
        perturb_vel: roughening std added to velocities after resampling [m/s].
            (2, 0.02, 0.02) is the best of a 12-point grid on Indoor-v0 dev seeds
            2_000_000 … 2_000_007 (flat within ±10 %; less roughening impoverishes the set).
        correction_base, correction_gain: the network's weight factor ``base + gain·(y − 0.5)``.
    """

    n_init: int = 500
    n_min: int = 500
    n_max: int = 500
    resample_below: float = 0.5
    grow_below: float = 0.3
    shrink_above: float = 0.8
    grow_step: int = 100
    shrink_step: int = 50
    accel_inflation: float = 2.0
    perturb_pos: float = 0.02
    perturb_vel: float = 0.02
    correction_base: float = 0.7
    correction_gain: float = 0.6

    def __post_init__(self) -> None:
        if not 1 <= self.n_min <= self.n_init <= self.n_max <= core.PARTICLE_STRIDE:
            raise ValueError(
                f"need 1 <= n_min <= n_init <= n_max <= {core.PARTICLE_STRIDE}; got n_min={self.n_min}, "
                f"n_init={self.n_init}, n_max={self.n_max}")
        for name in ("resample_below", "grow_below", "shrink_above"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"{name}={v} must be an ESS fraction in [0, 1]")
        if self.grow_step < 0 or self.shrink_step < 0:
            raise ValueError(f"grow_step={self.grow_step} and shrink_step={self.shrink_step} must be >= 0")
        for name in ("accel_inflation", "perturb_pos", "perturb_vel"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"{name}={v} must be finite and >= 0")
        lo = self.correction_base - 0.5 * self.correction_gain
        if not lo > 0.0:
            raise ValueError(f"correction range must stay positive; base − gain/2 = {lo}")

    @property
    def adaptive(self) -> bool:
        """Whether the particle count may change."""
        return self.n_min != self.n_max


STANDARD = PFConfig()
FIXED_800 = PFConfig(n_init=800, n_min=800, n_max=800)
ADAPTIVE = PFConfig(n_init=300, n_min=100, n_max=800)


@dataclass
class _State:
    """Per-batch filter buffers (allocated at reset)."""

    keys: np.ndarray
    particles: np.ndarray
    logw: np.ndarray
    count: np.ndarray
    est: np.ndarray
    prior_pos: np.ndarray
    scratch: np.ndarray
    wbuf: np.ndarray
    index: np.ndarray
    ess: np.ndarray
    used: np.ndarray
    resampled: np.ndarray
    used_sum: np.ndarray
    n_steps: int
    W1: np.ndarray
    b1: np.ndarray
    W2: np.ndarray
    b2: np.ndarray
    range_mask: np.ndarray = field(repr=False)
    vector_mask: np.ndarray = field(repr=False)


class ParticleFilter:
    """Batched cooperative particle filter, one particle set per UAV (pf-nn §2).

    Args:
        config: filter settings (see :class:`PFConfig`).
        network: frozen weight-correction network (``None``: plain PF).
        name: method name reported in results.
        parallel: run the kernel over a thread pool (True), on one thread (False), or pick
            by batch size (None: threads from ``PARALLEL_MIN_PARTICLES`` particle slots on).
            Results are identical either way.

    Attributes after each ``step``: ``used`` ``(B, N)`` particles used, ``ess`` ``(B, N)``,
    ``resampled`` ``(B, N)``, ``counts`` ``(B, N)`` particles carried into the next step,
    ``mean_particles`` ``(B, N)`` particles per step averaged since reset.
    """

    privileged: bool = False
    deterministic: bool = True

    def __init__(self, config: PFConfig = STANDARD, network: PFNNWeights | None = None, name: str = "pf",
                 parallel: bool | None = None):
        self.config = config
        self.parallel = parallel
        self.network = network
        self.name = name
        self._s: _State | None = None
        self._facts: TaskFacts | None = None

    # ------------------------------------------------------------------ protocol
    def reset(self, facts: TaskFacts, x0: np.ndarray) -> None:
        """Start B episodes: draw each UAV's particles around the initial prior ``x0``."""
        x0 = np.ascontiguousarray(x0, dtype=np.float64)
        n_b, n = facts.batch_size, facts.n_uav
        if x0.shape != (n_b, n, 6):
            raise ValueError(f"x0 must have shape ({n_b}, {n}, 6), got {x0.shape}")
        if not np.isfinite(x0).all():
            raise ValueError("x0 holds non-finite values")
        if (np.asarray(facts.kind) == TDOA).any():
            raise UnsupportedTask("the particle filters weigh anchor and peer ranges, landmarks, GPS and relative "
                                  "positions; they do not model TDOA range differences")
        c = self.config
        m = c.n_max
        hidden = self.network.hidden if self.network is not None else 1
        s = _State(
            keys=np.array(facts.keys, dtype=_INT), particles=np.zeros((n_b, n, m, 6)),
            logw=np.full((n_b, n, m), -np.inf), count=np.zeros((n_b, n), dtype=_INT), est=np.zeros((n_b, n, 6)),
            prior_pos=np.zeros((n_b, n, 3)), scratch=np.zeros((n_b, n, m, 6)), wbuf=np.zeros((n_b, n, m)),
            index=np.zeros((n_b, n, m), dtype=_INT), ess=np.zeros((n_b, n)), used=np.zeros((n_b, n), dtype=_INT),
            resampled=np.zeros((n_b, n), dtype=np.bool_), used_sum=np.zeros((n_b, n)), n_steps=0,
            W1=np.zeros((n_b, n, hidden, 6)), b1=np.zeros((n_b, n, hidden)), W2=np.zeros((n_b, n, hidden)),
            b2=np.zeros((n_b, n)),
            range_mask=np.isin(facts.kind, (ANCHOR, PEER)), vector_mask=np.isin(facts.kind, (LANDMARK, GPS, PEER_REL)),
        )
        if self.network is not None:
            s.W1[:] = self.network.W1
            s.b1[:] = self.network.b1
            s.W2[:] = self.network.W2
            s.b2[:] = self.network.b2
        core.pf_init(s.keys, x0, facts.init_pos_sigma, facts.init_vel_sigma, c.n_init,
                     s.particles, s.logw, s.count, s.est)
        self._s, self._facts = s, facts
        self._kind = np.ascontiguousarray(facts.kind, dtype=_INT)
        self._target = np.ascontiguousarray(facts.target, dtype=_INT)
        self._sigma = np.ascontiguousarray(facts.sigma, dtype=np.float64)
        self._anchors = np.ascontiguousarray(facts.anchors, dtype=np.float64).reshape(-1, 3)
        self._landmarks = np.ascontiguousarray(facts.landmarks, dtype=np.float64).reshape(-1, 3)
        self._accel_sigma = c.accel_inflation * facts.imu_sigma
        self._prm = core.step_params(facts.dt, self._accel_sigma, c.perturb_pos, c.perturb_vel, c.resample_below,
                                     c.grow_below, c.shrink_above, c.n_min, c.n_max, c.grow_step, c.shrink_step,
                                     self.network is not None, c.correction_base, c.correction_gain)
        if self.parallel is None:
            self._parallel = n_b * n * m >= PARALLEL_MIN_PARTICLES and numba.get_num_threads() > 1
        else:
            self._parallel = bool(self.parallel)
        self._nn_flops = core.nn_particle_flops(hidden) if self.network is not None else 0

    def step(self, meas: Measurements) -> EstimatorOutput:
        """Predict, weight, estimate and resample every UAV's particle set for one step."""
        s, f, c = self._require_state(), self._facts, self.config
        n_b, n, n_l = s.W1.shape[0], f.n_uav, f.n_channels
        if meas.imu.shape != (n_b, n, 3) or meas.z.shape != (n_b, n, n_l, 3) or meas.valid.shape != (n_b, n, n_l):
            raise ValueError(
                f"measurements must have imu ({n_b}, {n}, 3), z ({n_b}, {n}, {n_l}, 3), valid ({n_b}, {n}, {n_l}); "
                f"got {meas.imu.shape}, {meas.z.shape}, {meas.valid.shape}")
        if meas.step < 1:
            raise ValueError(f"meas.step must be >= 1 (1-based filter step), got {meas.step}")
        step_fn = core.pf_step if self._parallel else core.pf_step_serial
        step_fn(s.keys, meas.step, self._prm, meas.imu, meas.z, meas.valid, self._kind, self._target, self._sigma,
                self._anchors, self._landmarks, s.W1, s.b1, s.W2, s.b2, s.particles, s.logw, s.count, s.est,
                s.prior_pos, s.scratch, s.wbuf, s.index, s.ess, s.used, s.resampled)
        s.used_sum += s.used
        s.n_steps += 1
        return EstimatorOutput(positions=s.est[:, :, :3].copy(), flops=self.flops(meas.valid))

    # ------------------------------------------------------------------ accounting
    def flops(self, valid: np.ndarray) -> np.ndarray:
        """FLOPs per UAV of the last step ``(B, N)``, from the particle counts it used.

        Per used particle: prediction, one likelihood term per present range channel and
        one completed-square term for all 3-vector channels, the network (PF-NN),
        normalisation; per present 3-vector channel: its share of the square (once per
        UAV); per drawn particle on resampling steps: resampling and roughening; a shrink
        without resampling: the sort (M·log₂M comparisons).
        """
        s = self._require_state()
        n_range = np.count_nonzero(valid & s.range_mask, axis=-1)
        n_vector = np.count_nonzero(valid & s.vector_mask, axis=-1)
        per_particle = (core.PREDICT_PARTICLE_FLOPS + core.RANGE_CHANNEL_FLOPS * n_range
                        + core.VECTOR_PARTICLE_FLOPS * (n_vector > 0) + core.NORMALIZE_PARTICLE_FLOPS
                        + self._nn_flops)
        used = s.used.astype(np.float64)
        out = used * per_particle + core.VECTOR_CHANNEL_FLOPS * n_vector
        out += np.where(s.resampled, core.RESAMPLE_PARTICLE_FLOPS * s.count, 0.0)
        shrunk = ~s.resampled & (s.count < s.used)
        out += np.where(shrunk, used * np.log2(np.maximum(used, 2.0)), 0.0)
        return out

    @property
    def used(self) -> np.ndarray:
        """``(B, N)`` particles used in the last step."""
        return self._require_state().used.copy()

    @property
    def mean_particles(self) -> np.ndarray:
        """``(B, N)`` particles used per step, averaged over the steps since reset."""
        s = self._require_state()
        return s.used_sum / max(s.n_steps, 1)

    @property
    def particles(self) -> np.ndarray:
        """``(B, N, M_max, 6)`` the particle buffers (a copy; slots ≥ ``counts`` are stale)."""
        return self._require_state().particles.copy()

    @property
    def estimate(self) -> np.ndarray:
        """``(B, N, 6)`` the current state estimates x̂ (a copy)."""
        return self._require_state().est.copy()

    @property
    def counts(self) -> np.ndarray:
        """``(B, N)`` particles carried into the next step."""
        return self._require_state().count.copy()

    @property
    def ess(self) -> np.ndarray:
        """``(B, N)`` effective sample size after the last update."""
        return self._require_state().ess.copy()

    @property
    def resampled(self) -> np.ndarray:
        """``(B, N)`` whether the last step resampled."""
        return self._require_state().resampled.copy()

    def _require_state(self) -> _State:
        if self._s is None:
            raise RuntimeError(f"{self.name}: call reset(facts, x0) before step()")
        return self._s


class PFNNOnlineOracle(ParticleFilter):
    """PF-NN with the paper's online training on ground truth (pf-nn §2.3, Alg. 1 line 31).

    **Privileged**: every ``train_every`` steps each UAV's network takes one gradient step
    on ``n_train`` randomly chosen particles with targets ``exp(−‖p_j − p_true‖)``, which
    needs the true positions. The runner hands them over through ``observe_privileged``
    before each step; results are shown apart from the honest methods. Networks start from
    seeded random weights, one per UAV and episode.

    Args:
        config: filter settings (default: the adaptive configuration).
        train_every: training period in steps (10); n_train: particles per training (50);
        lr: learning rate (0.01); hidden: H (12).
    """

    privileged: bool = True

    def __init__(self, config: PFConfig = ADAPTIVE, train_every: int = 10, n_train: int = 50, lr: float = 0.01,
                 hidden: int = 12, name: str = "pf-nn-online-oracle"):
        if train_every < 1 or n_train < 1 or not lr > 0:
            raise ValueError(f"need train_every >= 1, n_train >= 1, lr > 0; got {train_every}, {n_train}, {lr}")
        super().__init__(config, random_weights(0, 0, hidden), name)
        self.train_every, self.n_train, self.lr = train_every, n_train, lr
        self._truth: np.ndarray | None = None

    def reset(self, facts: TaskFacts, x0: np.ndarray) -> None:
        """Start B episodes with seeded random networks (one per episode and UAV)."""
        super().reset(facts, x0)
        s = self._s
        for b, key in enumerate(s.keys):
            for i in range(facts.n_uav):
                w = random_weights(int(key), i, self.network.hidden)
                s.W1[b, i], s.b1[b, i], s.W2[b, i], s.b2[b, i] = w.W1, w.b1, w.W2, w.b2
        self._truth = None

    def observe_privileged(self, info: PrivilegedInfo) -> None:
        """Receive the true positions ``(B, N, 3)`` of the pending step (privileged channel)."""
        pos = getattr(info, "pos", None)
        if pos is None:
            raise ValueError("pf-nn-online-oracle needs the true positions: PrivilegedInfo.pos (B, N, 3)")
        self._truth = np.array(pos, dtype=np.float64)

    def step(self, meas: Measurements) -> EstimatorOutput:
        """A PF-NN step, then (every ``train_every`` steps) one online training step on truth."""
        s = self._require_state()
        prev = s.est.copy()
        out = super().step(meas)
        if meas.step % self.train_every == 0:
            if self._truth is None or self._truth.shape != prev[..., :3].shape:
                raise ValueError("pf-nn-online-oracle: no true positions for this step (observe_privileged first)")
            feats, targets = self._training_batch(meas.step, prev)
            sgd_step(s.W1, s.b1, s.W2, s.b2, feats, targets, self.lr)
            # one gradient step ≈ forward + backward ≈ 3 forward passes per training particle
            out = EstimatorOutput(positions=out.positions, flops=out.flops + 3.0 * self.n_train * self._nn_flops)
        return out

    def _training_batch(self, step: int, prev: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``n_train`` particles per UAV drawn uniformly (keyed RNG): features and targets."""
        s = self._s
        n_b, n = s.count.shape
        feats = np.empty((n_b, n, self.n_train, 6))
        targets = np.empty((n_b, n, self.n_train))
        for b in range(n_b):
            for i in range(n):
                m = int(s.count[b, i])
                pick = [min(int(uniform(int(s.keys[b]), step, core._ESTIMATOR, core.rng_index(i, q, core.SLOT_SELECT))
                                * m), m - 1) for q in range(self.n_train)]
                x = s.particles[b, i, pick]
                feats[b, i] = x - prev[b, i]
                targets[b, i] = np.exp(-np.linalg.norm(x[:, :3] - self._truth[b, i], axis=-1))
        return feats, targets


# ---------------------------------------------------------------------- factories


def make_pf() -> ParticleFilter:
    """Standard PF, 500 particles per UAV."""
    return ParticleFilter(STANDARD, name="pf")


def make_pf800() -> ParticleFilter:
    """Fixed PF, 800 particles per UAV."""
    return ParticleFilter(FIXED_800, name="pf-800")


def make_adaptive_pf() -> ParticleFilter:
    """ESS-adaptive PF, 300 particles at start, [100, 800]."""
    return ParticleFilter(ADAPTIVE, name="adaptive-pf")


class ShippedPFNN(ParticleFilter):
    """PF-NN with the shipped network of each task's benchmark version, chosen at ``reset``.

    A v0 task runs the Indoor-v0 fit (``pfnn.npz``, so v0 results stay as shipped), a v1 task
    the Indoor-v1 fit (``pfnn_v1.npz``); see ``pfnn.shipped_weights``.
    """

    def __init__(self, parallel: bool | None = None):
        super().__init__(ADAPTIVE, network=None, name="pf-nn", parallel=parallel)
        self._loaded: dict[Path, PFNNWeights] = {}

    def reset(self, facts: TaskFacts, x0: np.ndarray) -> None:
        """Load the network of ``facts.task_id``'s version, then start B episodes as ``ParticleFilter``."""
        path = shipped_weights(facts.task_id)
        if path not in self._loaded:
            self._loaded[path] = load_weights(path)
        self.network = self._loaded[path]
        super().reset(facts, x0)


def make_pfnn(weights: str | None = None) -> ParticleFilter:
    """PF-NN: the adaptive PF with the frozen, offline-trained weight-correction network.

    Args:
        weights: path of a ``.npz`` used on every task (default: the shipped fit of each
            task's benchmark version, ``ShippedPFNN``).
    """
    if weights is None:
        return ShippedPFNN()
    return ParticleFilter(ADAPTIVE, network=load_weights(weights), name="pf-nn")


def make_pfnn_online_oracle() -> PFNNOnlineOracle:
    """PF-NN trained online on ground truth as in the paper (privileged; shown apart)."""
    return PFNNOnlineOracle()
