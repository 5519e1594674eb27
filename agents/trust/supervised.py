"""``supervised-trust``: a per-channel classifier of the error label, used as trust (Track A).

The question behind it (benchmark v2, part 3): how much of what the learned trust methods gain
comes from reinforcement learning, and how much from the privileged labels they are also
fitted to? This method takes the labels alone. A small MLP is fitted offline, by binary
cross-entropy and with no reward, to the error label (``LinkTrustCore.pending_error_label``,
``swarmloc.envs.world.labels``: systematic error above k·σ_eff) of every present channel of
uniform-trust rollouts of the v2 randomized families (training seeds;
``swarmloc train supervised-trust``, ``agents/trust/supervised_fit.py``). At execution it reads
the observation only (``privileged = False``):

    α = 1 − P(error label | features)

clipped to [0, 1]; the CEKF then applies its floor (``R = R0 / max(α, α_min)``) and skips
channels with α ≤ α_th, as for every Track A method. Absent channels and channel kinds the
training tasks never had get α = 1.

**Features** (``FEATURE_NAMES``, F = 18 per present channel), all from ``TrustInput.obs``:
the step's innovation, predicted distance, IMU jerk and NIS (squashed as in
``observation.py``), the kind one-hot, the UAV's mean squashed NIS over its present channels
(the per-UAV context the ``mappo`` actor also gets), and the channel's squashed NIS at the
previous ``HISTORY`` = 4 steps with a present flag each (0 where the channel was absent or
before the episode's first step). The previous applied trust is left out: in uniform-trust
training data it is always 1, at execution it is the method's own output.

**Execution** is NumPy only (the weights are a ``.npz``; torch is needed to fit them, not to run them).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from swarmloc.agents.protocols import TrustInput
from swarmloc.envs.tasks.channels import N_KINDS, ChannelLayout
from swarmloc.envs.world.observation import DISTANCE, INNOVATION, JERK, KIND0, NIS, VALID, kind_one_hot

#: previous steps of a channel's NIS in its features
HISTORY = 4
FEATURE_NAMES = (
    "innovation", "predicted_distance", "imu_jerk", "nis",
    "kind_anchor", "kind_peer", "kind_landmark", "kind_gps", "kind_peer_rel",
    "uav_mean_nis",
    *(f"nis_prev{h}" for h in range(1, HISTORY + 1)),
    *(f"present_prev{h}" for h in range(1, HISTORY + 1)),
)
N_FEATURES = len(FEATURE_NAMES)
#: the step's own observation columns, in ``FEATURE_NAMES`` order
_OBS_COLUMNS = (INNOVATION, DISTANCE, JERK, NIS, *range(KIND0, KIND0 + N_KINDS))
#: the shipped weights (v2 randomized families) and their provenance record (same stem, ``.json``)
WEIGHTS_PATH = Path(__file__).resolve().parents[1] / "weights" / "supervised_trust.npz"


class ChannelHistory:
    """The short per-channel NIS history and the feature assembly of ``supervised-trust``.

    One instance follows B episodes. ``features(obs)`` returns the step's ``(B, N, L, F)``
    features (history of the steps before it), then records the step, so call it exactly once
    per step; ``reset`` starts the episodes with an empty history.
    """

    def __init__(self, history: int = HISTORY) -> None:
        if history < 0:
            raise ValueError(f"history must be >= 0, got {history}")
        self.history = int(history)
        self._nis = np.zeros((0, 0, 0, self.history), dtype=np.float32)
        self._present = np.zeros((0, 0, 0, self.history), dtype=np.float32)

    def reset(self, batch_size: int, n_uav: int, n_channels: int) -> None:
        """Empty history for B episodes of N UAVs and L channels."""
        shape = (batch_size, n_uav, n_channels, self.history)
        self._nis = np.zeros(shape, dtype=np.float32)
        self._present = np.zeros(shape, dtype=np.float32)

    def features(self, obs: np.ndarray) -> np.ndarray:
        """Features of the step, then push the step into the history.

        Args:
            obs: ``(B, N, L, 11)`` the step's observation (``build_observation``).

        Returns:
            ``(B, N, L, F)`` float32 features (``FEATURE_NAMES``).
        """
        if obs.shape[:3] != self._nis.shape[:3]:
            raise ValueError(f"obs has shape {obs.shape}; the history was reset for {self._nis.shape[:3]} (B, N, L)")
        valid = obs[..., VALID]
        nis = obs[..., NIS]
        # the UAV's mean squashed NIS over its present channels (0 where none is present)
        uav_mean = (nis * valid).sum(-1) / np.maximum(valid.sum(-1), 1.0)
        out = np.empty((*obs.shape[:3], N_FEATURES), dtype=np.float32)
        n_obs = len(_OBS_COLUMNS)
        out[..., :n_obs] = obs[..., _OBS_COLUMNS]
        out[..., n_obs] = uav_mean[..., None]
        out[..., n_obs + 1:n_obs + 1 + self.history] = self._nis
        out[..., n_obs + 1 + self.history:] = self._present
        if self.history:
            # newest first: slot 0 is the step just before the next one
            self._nis[..., 1:] = self._nis[..., :-1]
            self._present[..., 1:] = self._present[..., :-1]
            self._nis[..., 0] = nis * valid
            self._present[..., 0] = valid
        return out


@dataclass(frozen=True)
class ClassifierWeights:
    """A ReLU MLP F → H → H → 1 on standardized features; its output is the error label's logit.

    Attributes:
        layers: ``((W, b), ...)`` with ``W`` ``(in, out)``, float32.
        mean, std: ``(F,)`` feature standardization.
        kinds: observation kind columns (0 anchor … 4 peer_rel) the training data had; others get α = 1.
        history: the NIS history length the features were built with.
    """

    layers: tuple[tuple[np.ndarray, np.ndarray], ...]
    mean: np.ndarray
    std: np.ndarray
    kinds: tuple[int, ...]
    history: int = HISTORY

    @property
    def flops_per_channel(self) -> float:
        """Multiply-adds (2 FLOPs each) and activations of one forward pass, plus the sigmoid (≈ 4)."""
        flops = 2.0 * N_FEATURES  # standardization
        for w, b in self.layers:
            flops += 2.0 * w.size + b.size * 2.0  # W x + b, ReLU
        return flops + 4.0

    def logit(self, x: np.ndarray) -> np.ndarray:
        """``(..., F)`` features → ``(...)`` logit of the error label (float64)."""
        h = (np.asarray(x, dtype=np.float64) - self.mean) / self.std
        for j, (w, b) in enumerate(self.layers):
            h = h @ w + b
            if j < len(self.layers) - 1:
                h = np.maximum(h, 0.0)
        return h[..., 0]

    def save(self, path: str | Path) -> None:
        """Write a ``.npz`` (``np.savez``; loaded by :meth:`load`)."""
        arrays = {f"w{j}": w for j, (w, _) in enumerate(self.layers)}
        arrays |= {f"b{j}": b for j, (_, b) in enumerate(self.layers)}
        np.savez(path, mean=self.mean, std=self.std, kinds=np.array(self.kinds, dtype=np.int64),
                 history=np.array(self.history), feature_names=np.array(FEATURE_NAMES), **arrays)

    @classmethod
    def load(cls, path: str | Path) -> ClassifierWeights:
        """Read weights written by :meth:`save`.

        Raises:
            ValueError: the file was built with other features than this code assembles.
        """
        with np.load(path, allow_pickle=False) as f:
            names = tuple(str(n) for n in f["feature_names"])
            if names != FEATURE_NAMES or int(f["history"]) != HISTORY:
                raise ValueError(f"{path}: weights for features {names} (history {int(f['history'])}); "
                                 f"this code builds {FEATURE_NAMES} (history {HISTORY})")
            n_layers = sum(1 for k in f.files if k.startswith("w"))
            layers = tuple((f[f"w{j}"].astype(np.float64), f[f"b{j}"].astype(np.float64)) for j in range(n_layers))
            return cls(layers=layers, mean=f["mean"].astype(np.float64), std=f["std"].astype(np.float64),
                       kinds=tuple(int(k) for k in f["kinds"]), history=int(f["history"]))


def error_probability(weights: ClassifierWeights, x: np.ndarray) -> np.ndarray:
    """P(error label | features) = sigmoid(logit), computed in the overflow-free form for either sign."""
    z = weights.logit(x)
    # sigmoid(z) = 1 / (1 + e^{-z}) for z ≥ 0, e^{z} / (1 + e^{z}) for z < 0
    e = np.exp(-np.abs(z))
    return np.where(z >= 0, 1.0 / (1.0 + e), e / (1.0 + e))


class SupervisedTrust:
    """``supervised-trust``: α = 1 − P(error label | features) of a classifier fitted offline (module docstring).

    Args:
        weights: the fitted classifier.
    """

    privileged: bool = False
    deterministic: bool = True

    def __init__(self, weights: ClassifierWeights) -> None:
        self.weights = weights
        self.flops_per_channel = weights.flops_per_channel
        self._history = ChannelHistory(weights.history)
        self._known = np.ones((1, 1), dtype=bool)

    def reset(self, batch_size: int, layout: ChannelLayout, keys: np.ndarray) -> None:
        """Start B episodes: empty NIS history; mark the channel kinds the classifier was trained on.

        Args:
            batch_size: B.
            layout: the task's channel layout.
            keys: ``(B,)`` per-episode random keys (unused: the method is deterministic).
        """
        if batch_size < 1:
            raise ValueError(f"batch_size must be >= 1, got {batch_size}")
        n, n_l = layout.kind.shape
        self._history.reset(batch_size, n, n_l)
        column = kind_one_hot(layout.kind).argmax(-1)  # (N, L) observation kind column
        self._known = np.isin(column, self.weights.kinds)

    def act(self, inp: TrustInput) -> np.ndarray:
        """Trust of the pending update. Returns ``(B, N, L)`` α in [0, 1]."""
        x = self._history.features(inp.obs)
        alpha = np.ones(inp.valid.shape)
        use = inp.valid & self._known
        if use.any():
            alpha[use] = np.clip(1.0 - error_probability(self.weights, x[use]), 0.0, 1.0)
        return alpha

    def __repr__(self) -> str:
        return f"SupervisedTrust(history={self.weights.history})"


def supervised_trust(weights: str | Path | None = None) -> SupervisedTrust:
    """Registry factory: ``supervised-trust`` with the shipped weights (v2 randomized families) or ``weights``.

    Args:
        weights: a ``.npz`` written by ``swarmloc train supervised-trust``; default the shipped one.
    """
    return SupervisedTrust(ClassifierWeights.load(WEIGHTS_PATH if weights is None else weights))
