"""Speed of the Track B particle filters (and the factor-graph smoother) on identical recorded inputs, in one run.

Rows (``impl``), all on the same recorded Indoor-v0 measurements (6 UAVs, B episodes):

* ``pf-nn`` — the batched numba PF-NN step at the paper's average particle count
  (720 per UAV, held fixed so every repeat does the same work; pf-nn Table 4/5);
* ``pf-nn-numpy-reference`` — the same filter written the straightforward way (a Python
  loop over UAVs, numpy over particles: ``agents/estimators/pf/reference.py``), same particles, same
  random numbers; ``speedup_vs_reference`` on the ``pf-nn`` row is the ratio of the two;
* ``pf``, ``pf-800``, ``adaptive-pf`` and ``pf-nn`` (adaptive) as shipped, and ``cekf``
  (the uniform-trust CEKF predict + update kernels) — the time-per-step column of
  pf-nn Table 5;
* ``pf-nn`` at B = 32 (not in quick mode): batching throughput;
* ``isam2-robust`` as shipped (the fixed-lag gtsam smoother, marginal covariances included), where
  gtsam (the ``factorgraph`` extra) is installed.

Each time is taken per step over ``steps`` consecutive filter steps (the estimator's
``step`` only; measurements are recorded and captured beforehand); ``ms_per_step`` is
the median step of the best of a few repeats, ``mean_ms_per_step`` the mean.

Measured by ``swarmloc bench speed`` (these rows among the others).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numba
import numpy as np

from swarmloc.agents.estimators.pf.filters import ADAPTIVE, FIXED_800, STANDARD, ParticleFilter, PFConfig
from swarmloc.agents.estimators.pf.pfnn import PFNNWeights, load_weights, random_weights
from swarmloc.agents.estimators.pf.reference import ReferenceParticleFilter
from swarmloc.agents.protocols import Measurements, TaskFacts, episode_keys
from swarmloc.envs.filter import cekf
from swarmloc.envs.tasks.catalogue import get_spec
from swarmloc.envs.world.sim import World

TASK = "swarmloc/Indoor-v0"
#: the paper's average PF-NN particle count (pf-nn Table 4)
PAPER_PARTICLES = 720
#: the paper's PF-NN time per step, MATLAB R2025b on an Apple M1 (pf-nn Table 5) [ms]
PAPER_PFNN_MS = 63.4


@dataclass
class Recorded:
    """Recorded measurements of B Indoor-v0 episodes: the identical input of every row."""

    facts: TaskFacts
    meas: list[Measurements]
    x0: np.ndarray


def record(batch: int, n_steps: int, seed0: int = 3_100_000) -> Recorded:
    """Record ``n_steps`` of Indoor-v0 for ``batch`` episodes (reserved seeds, never scored)."""
    spec = get_spec(TASK, duration=n_steps * 0.1)
    seeds = np.arange(seed0, seed0 + batch)
    world = World(spec, batch)
    x0 = world.reset(seeds).copy()
    facts = TaskFacts.from_spec(spec, world.layout, x0, episode_keys(seeds))
    meas = []
    for k in range(1, spec.n_steps + 1):
        buf = world.sense()
        meas.append(Measurements.capture(buf.imu, buf.z, buf.valid, k * spec.dt, k))
    return Recorded(facts, meas, x0)


def _network() -> PFNNWeights:
    try:
        return load_weights()
    except FileNotFoundError:  # same cost with any weights
        return random_weights(0, 0)


@dataclass
class Timing:
    """Per-step wall times of one run [s]: the median (robust to the shared machine's
    preemptions, which are not the filter's cost), the mean and the standard deviation."""

    median: float
    mean: float
    std: float


def _timing(per_step: list[float]) -> Timing:
    arr = np.asarray(per_step)
    return Timing(median=float(np.median(arr)), mean=float(np.mean(arr)), std=float(np.std(arr)))


def _best(timings: list[Timing]) -> Timing:
    return min(timings, key=lambda t: t.median)


def time_estimator(make, rec: Recorded, repeats: int) -> tuple[Timing, float]:
    """Per-step times of a fresh estimator over the recording (best repeat), and its mean particles."""
    runs, particles = [], float("nan")
    for _ in range(repeats):
        est = make()
        est.reset(rec.facts, rec.x0)
        per_step = []
        for m in rec.meas:
            t0 = time.perf_counter()
            est.step(m)
            per_step.append(time.perf_counter() - t0)
        runs.append(_timing(per_step))
        particles = float(np.mean(est.mean_particles)) if hasattr(est, "mean_particles") else float("nan")
    return _best(runs), particles


def time_reference(config: PFConfig, network: PFNNWeights | None, rec: Recorded, repeats: int) -> Timing:
    """Per-step times of the per-UAV numpy reference on the recording (best repeat)."""
    f = rec.facts
    runs = []
    for _ in range(repeats):
        ref = ReferenceParticleFilter(f.keys, rec.x0, f.kind, f.target, f.sigma, f.anchors, f.landmarks, f.dt,
                                      f.init_pos_sigma, f.init_vel_sigma, config.accel_inflation * f.imu_sigma,
                                      config, network)
        per_step = []
        for m in rec.meas:
            t0 = time.perf_counter()
            ref.step(m.step, m.imu, m.z, m.valid)
            per_step.append(time.perf_counter() - t0)
        runs.append(_timing(per_step))
    return _best(runs)


def time_cekf(rec: Recorded, repeats: int) -> Timing:
    """Per-step times of the uniform-trust CEKF predict + update kernels, on one thread (best repeat)."""
    f = rec.facts
    n_b, n, n_l = f.batch_size, f.n_uav, f.n_channels
    kind, target = np.ascontiguousarray(f.kind), np.ascontiguousarray(f.target)
    r0 = np.ascontiguousarray(f.sigma) ** 2
    anchors = np.ascontiguousarray(f.anchors).reshape(-1, 3)
    landmarks = np.ascontiguousarray(f.landmarks)
    alpha = np.ones((n_b, n, n_l))
    runs = []
    threads = numba.get_num_threads()
    numba.set_num_threads(1)  # B = 1: a thread pool only adds synchronisation
    try:
        for _ in range(repeats):
            x = rec.x0.copy()
            P = cekf.initial_covariance(n_b, n, f.init_pos_sigma, f.init_vel_sigma)
            prior = np.zeros((n_b, n, 3))
            active = np.zeros((n_b, n, n_l), dtype=np.bool_)
            flops = np.zeros((n_b, n))
            per_step = []
            for m in rec.meas:
                t0 = time.perf_counter()
                cekf.cekf_predict(x, P, m.imu, f.dt, f.imu_sigma, prior)
                cekf.cekf_update(x, P, m.z, m.valid, alpha, kind, target, r0, anchors, landmarks, prior,
                                 f.alpha_th, f.alpha_min, active, flops)
                per_step.append(time.perf_counter() - t0)
            runs.append(_timing(per_step))
    finally:
        numba.set_num_threads(threads)
    return _best(runs)


def _row(impl: str, batch: int, n_uav: int, t: Timing, **extra) -> dict:
    return {"impl": impl, "B": batch, "env_steps_per_s": batch / t.median, "uav_steps_per_s": batch * n_uav / t.median,
            "ms_per_step": 1e3 * t.median, "mean_ms_per_step": 1e3 * t.mean, **extra}


def measure_rows(quick: bool = False) -> list[dict]:
    """Speed rows of the particle filters (see the module docstring).

    ``ms_per_step`` is the median over the steps of the best repeat (the machine is
    shared, and a preempted step measures the neighbours, not the filter);
    ``mean_ms_per_step`` is the plain mean of the same steps.

    Args:
        quick: fewer steps and repeats, and no B = 32 row.

    Returns:
        Rows ``{"impl", "B", "env_steps_per_s", "uav_steps_per_s", "ms_per_step", ...}``.
    """
    steps, repeats, ref_steps = (30, 2, 10) if quick else (200, 3, 40)
    rec = record(1, steps)
    n = rec.facts.n_uav
    net = _network()
    fixed = PFConfig(n_init=PAPER_PARTICLES, n_min=PAPER_PARTICLES, n_max=PAPER_PARTICLES)
    # warm the JIT (both drivers, both branches) outside the timings
    warm = record(2, 3)
    for parallel in (False, True):
        time_estimator(lambda: ParticleFilter(fixed, network=net, parallel=parallel), warm, 1)
    t_nn, _ = time_estimator(lambda: ParticleFilter(fixed, network=net, name="pf-nn"), rec, repeats)
    ref_rec = Recorded(rec.facts, rec.meas[:ref_steps], rec.x0)
    t_ref = time_reference(fixed, net, ref_rec, max(1, repeats - 1))
    rows = [
        _row("pf-nn", 1, n, t_nn, particles=PAPER_PARTICLES, speedup_vs_reference=t_ref.median / t_nn.median,
             paper_ms_per_step=PAPER_PFNN_MS),
        _row("pf-nn-numpy-reference", 1, n, t_ref, particles=PAPER_PARTICLES),
    ]
    for impl, make in (("pf", lambda: ParticleFilter(STANDARD, name="pf")),
                       ("pf-800", lambda: ParticleFilter(FIXED_800, name="pf-800")),
                       ("adaptive-pf", lambda: ParticleFilter(ADAPTIVE, name="adaptive-pf")),
                       ("pf-nn-adaptive", lambda: ParticleFilter(ADAPTIVE, network=net, name="pf-nn"))):
        t, particles = time_estimator(make, rec, repeats)
        rows.append(_row(impl, 1, n, t, particles=particles))
    rows.append(_row("cekf", 1, n, time_cekf(rec, repeats)))
    try:
        from swarmloc.agents.estimators.isam2 import ISAM2Robust
    except ModuleNotFoundError:  # the factorgraph extra is optional: no row without it
        pass
    else:
        t, _ = time_estimator(ISAM2Robust, rec, max(1, repeats - 1))
        rows.append(_row("isam2-robust", 1, n, t))
    if not quick:
        big = record(32, 50)
        t, _ = time_estimator(lambda: ParticleFilter(fixed, network=net, name="pf-nn"), big, 2)
        rows.append(_row("pf-nn", 32, n, t, particles=PAPER_PARTICLES))
    return rows
