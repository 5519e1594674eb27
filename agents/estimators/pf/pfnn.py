"""The PF-NN weight-correction network (pf-nn §2.3): 6 inputs, 12 tanh units, 1 sigmoid output.

Input ``f = [p_j − p̂_{k−1}, v_j − v̂_{k−1}]`` (a particle's deviation from the previous
estimate, eq. 11), ``y = σ(W2 · tanh(W1 f + b1) + b2)`` (eq. 12–13), and the particle's
weight is multiplied by ``0.7 + 0.6·(y − 0.5)`` ∈ [0.4, 1.0] (eq. 14). Training targets
are ``exp(−‖p_j − p_true‖)`` (eq. 15) with a mean-squared loss (eq. 16).

Weights live in a small ``.npz`` (``W1 (H, 6)``, ``b1 (H,)``, ``W2 (H,)``, ``b2 ()``), each
with its provenance ``.json`` beside it. One fit is shipped per benchmark version, on that
version's Indoor task (training seeds only): ``agents/weights/pfnn.npz`` (Indoor-v0, frozen
with v0) and ``pfnn_v1.npz`` (Indoor-v1); ``shipped_weights`` picks the one of a task's
version. This module is numpy only; the offline fit (torch) is in ``bench/training/pfnn.py``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from gymnasium.envs.registration import parse_env_id

from swarmloc.envs.tasks.rng import Stream, normal_array

from swarmloc.agents.registry import WEIGHTS_DIR, shipped_for_version

from swarmloc.agents.estimators.pf.core import SLOT_NN_INIT, rng_index

N_FEATURES = 6
HIDDEN = 12
#: the shipped, offline-trained weights of the v0 tasks (fitted on Indoor-v0; frozen with v0)
WEIGHTS_PATH = WEIGHTS_DIR / "pfnn.npz"
#: the shipped weights per benchmark version, each fitted on that version's Indoor task
SHIPPED_WEIGHTS: dict[int, Path] = {0: WEIGHTS_PATH, 1: WEIGHTS_DIR / "pfnn_v1.npz"}


def shipped_weights(task_id: str) -> Path:
    """The shipped weights for ``task_id``: the fit of its benchmark version, else of the newest older one.

    ``swarmloc/Indoor-v0`` → ``pfnn.npz``; ``swarmloc/Indoor-v1`` and every other v1 task →
    ``pfnn_v1.npz``. A task ID without a version is an error.
    """
    _, _, version = parse_env_id(task_id)
    if version is None:
        raise ValueError(f"task ID {task_id!r} has no version; expected e.g. 'swarmloc/Indoor-v1'")
    return shipped_for_version(SHIPPED_WEIGHTS, version)


@dataclass(frozen=True)
class PFNNWeights:
    """Parameters of one 6–H–1 network.

    Attributes:
        W1: ``(H, 6)`` hidden weights; b1: ``(H,)`` hidden biases.
        W2: ``(H,)`` output weights; b2: output bias.
    """

    W1: np.ndarray
    b1: np.ndarray
    W2: np.ndarray
    b2: float

    def __post_init__(self) -> None:
        h = np.shape(self.W1)[0] if np.ndim(self.W1) == 2 else -1
        if np.shape(self.W1) != (h, N_FEATURES) or h < 1:
            raise ValueError(f"W1 must have shape (H, {N_FEATURES}) with H >= 1, got {np.shape(self.W1)}")
        if np.shape(self.b1) != (h,) or np.shape(self.W2) != (h,):
            raise ValueError(f"b1 and W2 must have shape ({h},), got {np.shape(self.b1)} and {np.shape(self.W2)}")
        for name in ("W1", "b1", "W2", "b2"):
            if not np.isfinite(getattr(self, name)).all():
                raise ValueError(f"network parameter {name} holds non-finite values")

    @property
    def hidden(self) -> int:
        """H, the number of hidden units."""
        return int(self.W1.shape[0])

    def forward(self, features: np.ndarray) -> np.ndarray:
        """Network output ``y ∈ (0, 1)`` for features ``(..., 6)`` → ``(...)``."""
        a = np.tanh(features @ self.W1.T + self.b1)
        return 1.0 / (1.0 + np.exp(-(a @ self.W2 + self.b2)))

    def save(self, path: Path) -> None:
        """Write the parameters to ``path`` (``.npz``)."""
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez(path, W1=self.W1, b1=self.b1, W2=self.W2, b2=np.float64(self.b2))


def load_weights(path: Path | str | None = None) -> PFNNWeights:
    """Load network weights (default: the shipped ``agents/weights/pfnn.npz``).

    Raises:
        FileNotFoundError: no weights at ``path`` (with the command that makes them).
    """
    path = WEIGHTS_PATH if path is None else Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no PF-NN weights at {path}; train them with `swarmloc train pfnn`")
    with np.load(path) as data:
        missing = {"W1", "b1", "W2", "b2"} - set(data.files)
        if missing:
            raise ValueError(f"{path} lacks network arrays {sorted(missing)}")
        return PFNNWeights(W1=np.array(data["W1"], dtype=np.float64), b1=np.array(data["b1"], dtype=np.float64),
                           W2=np.array(data["W2"], dtype=np.float64), b2=float(data["b2"]))


def random_weights(key: int, uav: int, hidden: int = HIDDEN) -> PFNNWeights:
    """Seeded random initial weights (Xavier-normal scale), keyed by ``envs.rng``.

    Args:
        key: the episode's random key; uav: the UAV the network belongs to.
        hidden: H.
    """
    n_params = hidden * (N_FEATURES + 2) + 1
    idx = np.array([rng_index(uav, p, SLOT_NN_INIT) for p in range(n_params)], dtype=np.int64)
    g = normal_array(int(key), 0, int(Stream.ESTIMATOR), idx)
    W1 = g[: hidden * N_FEATURES].reshape(hidden, N_FEATURES) * np.sqrt(2.0 / (N_FEATURES + hidden))
    W2 = g[hidden * N_FEATURES: hidden * (N_FEATURES + 1)] * np.sqrt(2.0 / (hidden + 1))
    return PFNNWeights(W1=W1, b1=np.zeros(hidden), W2=W2, b2=0.0)


def correction(y: np.ndarray, base: float = 0.7, gain: float = 0.6) -> np.ndarray:
    """Weight correction factor ``base + gain·(y − 0.5)`` (pf-nn eq. 14)."""
    return base + gain * (np.asarray(y) - 0.5)


def sgd_step(W1: np.ndarray, b1: np.ndarray, W2: np.ndarray, b2: np.ndarray,
             features: np.ndarray, targets: np.ndarray, lr: float) -> np.ndarray:
    """One gradient-descent step on ``L = mean_s (y_s − t_s)²`` for a batch of networks (in place).

    Args:
        W1 ``(..., H, 6)``, b1 ``(..., H)``, W2 ``(..., H)``, b2 ``(...)``: networks (updated in place).
        features: ``(..., S, 6)`` inputs; targets ``(..., S)``.
        lr: learning rate.

    Returns:
        ``(...)`` the loss before the step.
    """
    # forward: a = W1 f + b1, h = tanh a, y = σ(W2·h + b2)
    a = np.einsum("...hf,...sf->...sh", W1, features) + b1[..., None, :]
    h = np.tanh(a)
    o = np.einsum("...h,...sh->...s", W2, h) + b2[..., None]
    y = 1.0 / (1.0 + np.exp(-o))
    err = y - targets
    loss = np.mean(err * err, axis=-1)
    # backward: ∂L/∂o = 2 (y − t) y (1 − y) / S
    g_o = 2.0 * err * y * (1.0 - y) / features.shape[-2]
    g_a = g_o[..., None] * W2[..., None, :] * (1.0 - h * h)
    W2 -= lr * np.einsum("...s,...sh->...h", g_o, h)
    b2 -= lr * np.sum(g_o, axis=-1)
    W1 -= lr * np.einsum("...sh,...sf->...hf", g_a, features)
    b1 -= lr * np.sum(g_a, axis=-2)
    return loss
