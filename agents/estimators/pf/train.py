"""Offline fit of the PF-NN weight-correction network (no truth at evaluation time).

The paper trains the network online against ground truth (pf-nn §2.3, eq. 15–16), which
no deployed filter has. Here the same network, inputs and target are fitted *offline*
on training episodes, then frozen:

1. **Collect.** Run the filter on training seeds (round 0: ``adaptive-pf``; later rounds:
   ``pf-nn`` with the network of the previous round, so the data follow the particle
   clouds the network will actually see). Every ``every`` steps, per UAV, take
   ``per_uav`` particles of the pre-step set uniformly and propagate them exactly as the
   kernel does (same random numbers), giving the predicted particles the network scores:
   features ``[p_j − p̂_{k−1}, v_j − v̂_{k−1}]`` (eq. 11), target ``exp(−‖p_j − p_true‖)``.
2. **Fit.** Minimise the mean squared error (eq. 16) with Adam at the paper's learning
   rate over the pooled samples.

Seed policy (which seeds training may use) is the caller's: ``swarmloc train pfnn``
(``bench/training/pfnn.py``) refuses test and dev seeds before calling :func:`fit_pfnn`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from swarmloc.envs.tasks.catalogue import get_spec
from swarmloc.envs.world.sim import World

from swarmloc.agents.estimators.pf import core
from swarmloc.agents.estimators.pf.filters import ADAPTIVE, ParticleFilter, PFConfig
from swarmloc.agents.estimators.pf.pfnn import HIDDEN, N_FEATURES, PFNNWeights
from swarmloc.agents.estimators.pf.reference import normal_pairs_np, uniform_np


@dataclass(frozen=True)
class FitConfig:
    """Settings of the offline fit.

    Attributes:
        task: task the data come from.
        seeds: training episode seeds (the caller checks they are training seeds).
        duration: episode length [s] (None: the task's own).
        rounds: collection rounds (round 0 without the network, later rounds with it).
        every: collect every this many steps (pf-nn T_train = 10).
        per_uav: particles per UAV per collection (pf-nn: 50).
        epochs: passes over the pooled samples per round.
        batch_size: minibatch size.
        lr: Adam learning rate (pf-nn: 0.01).
        hidden: hidden units H (pf-nn: 12).
        torch_seed: seed of the network's initialisation and minibatch order.
        filter: the particle filter the data are collected with.
    """

    task: str = "swarmloc/Indoor-v0"
    seeds: tuple[int, ...] = tuple(range(16))
    duration: float | None = None
    rounds: int = 2
    every: int = 10
    per_uav: int = 50
    epochs: int = 20
    batch_size: int = 1024
    lr: float = 0.01
    hidden: int = HIDDEN
    torch_seed: int = 0
    filter: PFConfig = field(default_factory=lambda: ADAPTIVE)

    def __post_init__(self) -> None:
        if not self.seeds:
            raise ValueError("seeds must not be empty")
        for name in ("rounds", "every", "per_uav", "epochs", "batch_size", "hidden"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name}={getattr(self, name)} must be >= 1")
        if not self.lr > 0:
            raise ValueError(f"lr={self.lr} must be > 0")


@dataclass
class FitResult:
    """Weights and a record of how they were fitted.

    Attributes:
        weights: the fitted network.
        losses: final training MSE of each round.
        n_samples: pooled samples after each round.
        target_mean: mean target of the pooled samples.
        seconds: wall time of the fit.
    """

    weights: PFNNWeights
    losses: list[float]
    n_samples: list[int]
    target_mean: float
    seconds: float


def _predicted_samples(pf: ParticleFilter, key_steps: tuple[np.ndarray, int], imu: np.ndarray, per_uav: int,
                       dt: float, accel_sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """Pick ``per_uav`` particles of each UAV's pre-step set and predict them as the kernel will.

    Returns:
        ``(B, N, S, 6)`` predicted particles and ``(B, N, 6)`` the pre-step estimates.
    """
    keys, step = key_steps
    x_all, counts, est = pf.particles, pf.counts, pf.estimate
    n_b, n = counts.shape
    out = np.empty((n_b, n, per_uav, 6))
    for b in range(n_b):
        key = int(keys[b])
        for i in range(n):
            m = int(counts[b, i])
            # which particles: uniform draws on the SELECT slot (never used by the filter itself)
            pick_idx = (i * core.PARTICLE_STRIDE + np.arange(per_uav)) * core.N_SLOTS + core.SLOT_SELECT
            pick = np.minimum((uniform_np(key, step, pick_idx) * m).astype(np.int64), m - 1)
            x = x_all[b, i, pick].copy()
            base = (i * core.PARTICLE_STRIDE + pick) * core.N_SLOTS + core.SLOT_PROCESS
            g0, g1 = normal_pairs_np(key, step, base)
            g2, _ = normal_pairs_np(key, step, base + 2)
            a = imu[b, i] + accel_sigma * np.stack([g0, g1, g2], axis=1)
            x[:, :3] = x[:, :3] + x[:, 3:] * dt + 0.5 * dt * dt * a
            x[:, 3:] = x[:, 3:] + a * dt
            out[b, i] = x
    return out, est


def collect_samples(cfg: FitConfig, network: PFNNWeights | None) -> tuple[np.ndarray, np.ndarray]:
    """Run the filter on ``cfg.seeds`` and collect (features, targets).

    Args:
        cfg: the fit settings.
        network: the network applied while collecting (None: plain adaptive PF).

    Returns:
        ``(S, 6)`` features and ``(S,)`` targets ``exp(−‖p − p_true‖)``.
    """
    from swarmloc.agents.protocols import Measurements, TaskFacts, episode_keys

    spec = get_spec(cfg.task, **({"duration": cfg.duration} if cfg.duration else {}))
    seeds = np.asarray(cfg.seeds, dtype=np.int64)
    world = World(spec, len(seeds))
    x0 = world.reset(seeds).copy()
    facts = TaskFacts.from_spec(spec, world.layout, x0, episode_keys(seeds))
    pf = ParticleFilter(cfg.filter, network=network, name="pf-nn-collect")
    pf.reset(facts, facts.x0)
    accel_sigma = cfg.filter.accel_inflation * facts.imu_sigma
    feats, targets = [], []
    for k in range(1, spec.n_steps + 1):
        buf = world.sense()
        if k % cfg.every == 0:
            x, est = _predicted_samples(pf, (facts.keys, k), buf.imu, cfg.per_uav, spec.dt, accel_sigma)
            feats.append((x - est[:, :, None, :]).reshape(-1, 6))
            err = np.linalg.norm(x[..., :3] - buf.pos[:, :, None, :], axis=-1)
            targets.append(np.exp(-err).reshape(-1))
        pf.step(Measurements.capture(buf.imu, buf.z, buf.valid, k * spec.dt, k))
    return np.concatenate(feats), np.concatenate(targets)


def _fit(features: np.ndarray, targets: np.ndarray, cfg: FitConfig, init: PFNNWeights | None) -> tuple[
        PFNNWeights, float]:
    """Adam on the MSE between σ-network output and targets; returns weights and final loss."""
    import torch

    gen = torch.Generator().manual_seed(cfg.torch_seed)
    torch.manual_seed(cfg.torch_seed)
    net = torch.nn.Sequential(torch.nn.Linear(N_FEATURES, cfg.hidden, dtype=torch.float64), torch.nn.Tanh(),
                              torch.nn.Linear(cfg.hidden, 1, dtype=torch.float64), torch.nn.Sigmoid())
    if init is not None:
        with torch.no_grad():
            net[0].weight.copy_(torch.from_numpy(init.W1))
            net[0].bias.copy_(torch.from_numpy(init.b1))
            net[2].weight.copy_(torch.from_numpy(init.W2[None, :]))
            net[2].bias.fill_(init.b2)
    f = torch.from_numpy(features)
    t = torch.from_numpy(targets)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    n = f.shape[0]
    for _ in range(cfg.epochs):
        order = torch.randperm(n, generator=gen)
        for start in range(0, n, cfg.batch_size):
            idx = order[start:start + cfg.batch_size]
            # L = (1/M) Σ_j (y_j − t_j)²  (pf-nn eq. 16)
            loss = torch.mean((net(f[idx]).squeeze(-1) - t[idx]) ** 2)
            opt.zero_grad()
            loss.backward()
            opt.step()
    with torch.no_grad():
        final = float(torch.mean((net(f).squeeze(-1) - t) ** 2))
        weights = PFNNWeights(W1=net[0].weight.numpy().copy(), b1=net[0].bias.numpy().copy(),
                              W2=net[2].weight.numpy()[0].copy(), b2=float(net[2].bias.numpy()[0]))
    return weights, final


def fit_pfnn(cfg: FitConfig, log=print) -> FitResult:
    """Collect training samples and fit the network, ``cfg.rounds`` times (data pooled).

    Args:
        cfg: the fit settings (seeds must already be checked as training seeds).
        log: progress printer (``print`` by default; pass ``lambda *_: None`` to silence).

    Returns:
        The fitted weights and a record of the fit.
    """
    t0 = time.perf_counter()
    network: PFNNWeights | None = None
    feats: list[np.ndarray] = []
    targets: list[np.ndarray] = []
    losses, sizes = [], []
    for r in range(cfg.rounds):
        f, t = collect_samples(cfg, network)
        feats.append(f)
        targets.append(t)
        all_f, all_t = np.concatenate(feats), np.concatenate(targets)
        network, loss = _fit(all_f, all_t, cfg, network)
        losses.append(loss)
        sizes.append(int(all_t.size))
        log(f"round {r}: {all_t.size} samples, mean target {all_t.mean():.4f}, train MSE {loss:.6f} "
            f"(constant predictor {all_t.var():.6f})")
    assert network is not None
    return FitResult(weights=network, losses=losses, n_samples=sizes, target_mean=float(all_t.mean()),
                     seconds=time.perf_counter() - t0)
