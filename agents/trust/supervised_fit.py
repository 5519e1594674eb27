"""Offline fit of ``supervised-trust``: collect labelled channel-steps, fit the classifier (no RL).

1. **Collect.** Roll out ``LinkTrustCore`` with uniform trust (α = 1) on each training task's
   seeds. At every step, every present channel gives one frame: its features
   (``supervised.ChannelHistory``, the same assembly the policy runs) and, as the target, the
   error label of that pending measurement (``LinkTrustCore.pending_error_label``). The labels
   are read here, in the training process, only.
2. **Fit.** A ReLU MLP F → H → H → 1 by binary cross-entropy with Adam on the pooled frames
   (unweighted, so that its output stays a calibrated probability); torch on one thread, seeded,
   so a fit is reproducible on one machine.
3. **Held out.** The same collection on other training-range seeds gives the record's ROC AUC,
   average precision and precision/recall at P = 0.5 (α = 0.5), per task and pooled, beside
   the AUC of the step's NIS alone (the statistic the χ² rules threshold).

Which seeds may be used is the caller's: ``swarmloc train supervised-trust``
(``bench/training/supervised_trust.py``) refuses test and dev seeds before calling :func:`fit`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import rankdata

from swarmloc.agents.trust.supervised import FEATURE_NAMES, HISTORY, ChannelHistory, ClassifierWeights
from swarmloc.envs.tasks.catalogue import get_spec
from swarmloc.envs.world.core import LinkTrustCore
from swarmloc.envs.world.observation import build_observation, kind_one_hot

#: the step's squashed NIS among the features (the held-out baseline's score)
_NIS_COLUMN = FEATURE_NAMES.index("nis")
_KIND_COLUMNS = slice(FEATURE_NAMES.index("kind_anchor"), FEATURE_NAMES.index("kind_peer_rel") + 1)


@dataclass(frozen=True)
class FitConfig:
    """Settings of the fit.

    Attributes:
        tasks: training tasks (the v2 randomized families).
        seeds: per task, the training episode seeds (the caller checks they are training seeds).
        heldout_seeds: per task, the held-out episode seeds of the record's metrics.
        steps: filter steps per episode (None: the task's own).
        batch: episodes stepped together while collecting.
        hidden: hidden units H of both layers.
        epochs: Adam passes over the pooled frames.
        minibatch: frames per Adam step.
        lr: Adam learning rate.
        torch_seed: seed of the initialisation and the minibatch order.
    """

    tasks: tuple[str, ...] = ("swarmloc/ScaleRandom-v2", "swarmloc/AnchorNLOSRandom-v2")
    seeds: tuple[tuple[int, ...], ...] = (tuple(range(16)), tuple(range(64)))
    heldout_seeds: tuple[tuple[int, ...], ...] = (tuple(range(900_000, 900_008)), tuple(range(900_000, 900_032)))
    steps: int | None = None
    batch: int = 16
    hidden: int = 32
    epochs: int = 12
    minibatch: int = 4096
    lr: float = 3e-3
    torch_seed: int = 0


@dataclass
class FitResult:
    """The fitted weights and what the record states about the fit."""

    weights: ClassifierWeights
    data: dict = field(default_factory=dict)
    losses: list[float] = field(default_factory=list)
    heldout: dict = field(default_factory=dict)
    seconds: float = 0.0


def collect_frames(task: str, seeds: tuple[int, ...], steps: int | None = None,
                   batch: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """Features and error labels of every present channel-step of uniform-trust rollouts.

    Args:
        task: registered task ID.
        seeds: episode seeds.
        steps: filter steps per episode (None: the task's ``n_steps``).
        batch: episodes stepped together.

    Returns:
        ``(M, F)`` float32 features and ``(M,)`` bool error labels, M the present channel-steps.
    """
    spec = get_spec(task)
    n_steps = spec.n_steps if steps is None else min(int(steps), spec.n_steps)
    xs, ys = [], []
    for start in range(0, len(seeds), batch):
        chunk = np.asarray(seeds[start:start + batch], dtype=np.int64)
        core = LinkTrustCore(spec, len(chunk))
        one_hot = kind_one_hot(core.layout.kind)
        history = ChannelHistory(HISTORY)
        history.reset(len(chunk), core.n_uav, core.n_channels)
        step = core.reset(chunk)
        trust = np.ones(step.valid.shape)
        obs = None
        for _ in range(n_steps):
            obs = build_observation(step, one_hot, obs)
            x = history.features(obs)
            valid = step.valid.copy()
            xs.append(x[valid])
            ys.append(core.pending_error_label[valid].copy())
            step = core.step(trust)
    return np.concatenate(xs), np.concatenate(ys)


def roc_auc(score: np.ndarray, label: np.ndarray) -> float | None:
    """Area under the ROC curve (Mann–Whitney U with mid-ranks for ties); None with one class only."""
    pos = label.astype(bool)
    n_pos, n_neg = int(pos.sum()), int((~pos).sum())
    if n_pos == 0 or n_neg == 0:
        return None
    ranks = rankdata(score)
    # AUC = (Σ ranks of positives − n₊(n₊+1)/2) / (n₊ n₋)
    return float((ranks[pos].sum() - n_pos * (n_pos + 1) / 2) / (n_pos * n_neg))


def average_precision(score: np.ndarray, label: np.ndarray) -> float | None:
    """Average precision: the mean, over the positives, of the precision at each one's rank (score descending)."""
    pos = label.astype(bool)
    if not pos.any():
        return None
    order = np.argsort(-score, kind="stable")
    hits = pos[order]
    precision = np.cumsum(hits) / np.arange(1, hits.size + 1)
    return float(precision[hits].mean())


def detection_metrics(prob: np.ndarray, x: np.ndarray, label: np.ndarray) -> dict:
    """The held-out record of one set of frames: size, label rate, AUC, AP, precision/recall at P = 0.5."""
    flagged = prob > 0.5
    tp = int((flagged & label).sum())
    return {
        "frames": int(label.size), "label_rate": float(label.mean()) if label.size else None,
        "roc_auc": roc_auc(prob, label), "average_precision": average_precision(prob, label),
        "precision_at_0.5": tp / int(flagged.sum()) if flagged.any() else None,
        "recall_at_0.5": tp / int(label.sum()) if label.any() else None,
        "nis_only_roc_auc": roc_auc(x[:, _NIS_COLUMN], label),
        "nis_only_average_precision": average_precision(x[:, _NIS_COLUMN], label),
    }


def _fit_mlp(x: np.ndarray, y: np.ndarray, cfg: FitConfig, log) -> tuple[ClassifierWeights, list[float]]:
    """Binary cross-entropy fit of the MLP on standardized features (torch, one thread, seeded)."""
    import torch

    torch.set_num_threads(1)
    gen = torch.Generator().manual_seed(cfg.torch_seed)
    torch.manual_seed(cfg.torch_seed)
    mean = x.mean(0).astype(np.float64)
    # a constant column (a kind absent from every task) keeps std 1: standardizing it divides by nothing
    std = np.where(x.std(0) > 1e-6, x.std(0), 1.0).astype(np.float64)
    xt = torch.from_numpy(((x - mean) / std).astype(np.float32))
    yt = torch.from_numpy(y.astype(np.float32))
    net = torch.nn.Sequential(torch.nn.Linear(x.shape[1], cfg.hidden), torch.nn.ReLU(),
                              torch.nn.Linear(cfg.hidden, cfg.hidden), torch.nn.ReLU(),
                              torch.nn.Linear(cfg.hidden, 1))
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    loss_fn = torch.nn.BCEWithLogitsLoss()
    losses = []
    for epoch in range(cfg.epochs):
        order = torch.randperm(len(yt), generator=gen)
        total = 0.0
        for i in range(0, len(yt), cfg.minibatch):
            idx = order[i:i + cfg.minibatch]
            loss = loss_fn(net(xt[idx])[:, 0], yt[idx])
            opt.zero_grad()
            loss.backward()
            opt.step()
            total += float(loss.detach()) * len(idx)
        losses.append(total / len(yt))
        log(f"epoch {epoch}: BCE {losses[-1]:.5f}")
    linear = [m for m in net if isinstance(m, torch.nn.Linear)]
    layers = tuple((m.weight.detach().numpy().T.astype(np.float64).copy(), m.bias.detach().numpy().astype(np.float64).copy())
                   for m in linear)
    kinds = tuple(int(k) for k in np.nonzero(x[:, _KIND_COLUMNS].max(0) > 0)[0])
    return ClassifierWeights(layers=layers, mean=mean, std=std, kinds=kinds, history=HISTORY), losses


def fit(cfg: FitConfig, log=print) -> FitResult:
    """Collect the training frames, fit the classifier, score it on the held-out frames.

    Args:
        cfg: the fit settings (seeds must already be checked as training seeds).
        log: progress printer.

    Returns:
        The weights and the record of the fit.
    """
    if len(cfg.seeds) != len(cfg.tasks) or len(cfg.heldout_seeds) != len(cfg.tasks):
        raise ValueError(f"seeds and heldout_seeds need one tuple per task ({len(cfg.tasks)}), "
                         f"got {len(cfg.seeds)} and {len(cfg.heldout_seeds)}")
    t0 = time.perf_counter()
    xs, ys, data = [], [], {}
    for task, seeds in zip(cfg.tasks, cfg.seeds):
        x, y = collect_frames(task, seeds, cfg.steps, cfg.batch)
        xs.append(x)
        ys.append(y)
        data[task] = {"episodes": len(seeds), "frames": int(y.size), "label_rate": float(y.mean())}
        log(f"{task}: {y.size} frames from {len(seeds)} episodes, label rate {y.mean():.4f}")
    x, y = np.concatenate(xs), np.concatenate(ys)
    data["all"] = {"frames": int(y.size), "label_rate": float(y.mean())}
    weights, losses = _fit_mlp(x, y, cfg, log)
    heldout, hx, hy, hp = {}, [], [], []
    from swarmloc.agents.trust.supervised import error_probability

    for task, seeds in zip(cfg.tasks, cfg.heldout_seeds):
        x, y = collect_frames(task, seeds, cfg.steps, cfg.batch)
        p = error_probability(weights, x)
        heldout[task] = {"episodes": len(seeds), **detection_metrics(p, x, y)}
        hx.append(x)
        hy.append(y)
        hp.append(p)
        log(f"held out {task}: AUC {heldout[task]['roc_auc']}, AP {heldout[task]['average_precision']} "
            f"(NIS alone: AUC {heldout[task]['nis_only_roc_auc']})")
    heldout["all"] = detection_metrics(np.concatenate(hp), np.concatenate(hx), np.concatenate(hy))
    return FitResult(weights=weights, data=data, losses=losses, heldout=heldout, seconds=time.perf_counter() - t0)
