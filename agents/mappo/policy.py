"""MAPPO link trust at execution time: the shared per-channel actor as a ``LinkTrustPolicy``.

The actor is the madrl §2.2.2 network: per channel, the F = 11 features (see
``swarmloc.envs.world.observation``) pass through a 128–64 ReLU MLP to one trust logit μ and
α_raw = sigmoid(μ) ∈ (0, 1] — the paper's sigmoid output layer. The same weights serve
every channel of every UAV, so one policy runs on any number of UAVs N and channels L.
During training (``swarmloc.agents.mappo.train``) the logit is sampled, u ~ N(μ, σ²), and
α = sigmoid(u); at execution the actor is deterministic (u = μ) and, for the ``mappo``
method, wrapped in adaptive Markov smoothing (madrl eq. 15–17, β_max 0.85, γ 2.0).

Methods registered from this module (see ``swarmloc.agents.registry``):

| name | what runs |
|---|---|
| ``mappo`` | shipped weights, deterministic actor + adaptive Markov smoothing |
| ``mappo-no-smoothing`` | the same weights, raw α (madrl Exp. 6 "no smoothing") |
| ``mappo-no-isolation`` | trust fixed at 1 after training (madrl Exp. 6 "no evaluation") + smoothing |
| ``mappo-accuracy-only`` | weights trained with λ = 0 for delay, energy and jitter (madrl Exp. 7) + smoothing |

**Shipped weights per benchmark version** (``SHIPPED``; the runner passes the version of the
task it runs, ``load_method(..., version=)``): the v0 tasks run ``mappo.pt`` and
``mappo_accuracy_only.pt``, trained on nine v0 UWB ranging tasks and frozen with v0; the v1
tasks run ``mappo_v1.pt`` and ``mappo_accuracy_only_v1.pt``, trained on the six v1 randomized
families' training seeds with the privileged auxiliary label loss (``--label-coef 1``, as for
``mappo-set-gru``): without it the paper's actor collapses to α ≈ 1 there (docs/learned.md).
A method loaded without a version gets the newest.

Only torch is needed here (no torchrl): evaluation stays cheap to import.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch
from torch import nn

from swarmloc.envs.tasks.channels import N_KINDS, ChannelLayout
from swarmloc.envs.world.observation import INNOVATION, KIND0, N_FEATURES, NIS, VALID

from swarmloc.agents.protocols import TrustInput
from swarmloc.agents.registry import WEIGHTS_DIR, shipped_for_version
from swarmloc.agents.trust.smoothing import BETA_MAX, SMOOTHING_GAMMA, MarkovSmoothing  # noqa: F401  (re-exported)

#: the logit is soft-limited to ±LOGIT_LIMIT, so α ∈ [3.4e-4, 0.99966]: below α_th (0.05)
#: the CEKF skips the channel; near 1 it is the nominal R0
LOGIT_LIMIT = 8.0


def limit_logit(raw: torch.Tensor) -> torch.Tensor:
    """The trust logit μ = c · tanh(raw / c), c = ``LOGIT_LIMIT``: a smooth limit that keeps gradients (a clamp
    would not)."""
    return LOGIT_LIMIT * torch.tanh(raw / LOGIT_LIMIT)


def trust_output_layer(width: int, init_trust: float) -> nn.Linear:
    """A trust actor's last layer, ``width`` → one logit, initialized so that the untrained actor starts near
    α = ``init_trust`` everywhere (small weights, bias logit(init_trust)).

    Raises:
        ValueError: ``init_trust`` not in (0, 1).
    """
    if not 0.0 < init_trust < 1.0:
        raise ValueError(f"init_trust must be in (0, 1), got {init_trust!r}")
    last = nn.Linear(width, 1)
    nn.init.uniform_(last.weight, -1e-3, 1e-3)
    nn.init.constant_(last.bias, float(np.log(init_trust / (1.0 - init_trust))))
    return last


#: per-UAV context appended to every channel: masked means of these features over the UAV's
#: present channels (innovation, NIS) — how this link compares with the UAV's other links
CONTEXT_FEATURES = (INNOVATION, NIS)


def channel_context(obs: torch.Tensor) -> torch.Tensor:
    """Per-UAV context ``(..., L, C)``: masked means over the UAV's present channels of ``CONTEXT_FEATURES``.

    Args:
        obs: ``(..., L, F)`` one UAV's channels (any leading dims).
    """
    valid = obs[..., VALID:VALID + 1]  # (..., L, 1)
    feats = obs[..., list(CONTEXT_FEATURES)]  # (..., L, C)
    mean = (feats * valid).sum(-2, keepdim=True) / valid.sum(-2, keepdim=True).clamp(min=1.0)
    return mean.expand_as(feats)


class ChannelActor(nn.Module):
    """Per-channel trust actor shared across channels and UAVs (madrl §2.2.2).

    ``forward(obs)`` maps one UAV's channels ``(..., L, F)`` to trust logits μ ``(..., L)``,
    soft-limited to ±``LOGIT_LIMIT``; α_raw = sigmoid(μ). Every channel goes through the same
    MLP; with ``context`` (default) its input is its own F features plus the UAV's
    ``channel_context`` (mean innovation and NIS over the UAV's present channels): a
    channel's innovation means little alone — it is large on every link when the UAV's own
    estimate is off, and on one link when that link is faulty. The context is a
    permutation-invariant pooling over the UAV's own channels, so the actor stays
    decentralized and serves any L and N. ``log_std`` is the state-independent log σ of the
    training-time Gaussian on the logit (unused at execution).

    Args:
        n_features: F.
        hidden: hidden layer widths (the paper: 128, 64).
        init_trust: α the untrained actor outputs (sets the last bias), in (0, 1).
        init_log_std: initial log σ of the logit noise.
        context: append the UAV context (False: the paper's purely per-channel input).
    """

    def __init__(self, n_features: int = N_FEATURES, hidden: tuple[int, ...] = (128, 64), init_trust: float = 0.8,
                 init_log_std: float = -0.5, context: bool = True) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        width = n_features + (len(CONTEXT_FEATURES) if context else 0)
        for h in hidden:
            layers += [nn.Linear(width, h), nn.ReLU()]
            width = h
        self.body = nn.Sequential(*layers, trust_output_layer(width, init_trust))
        self.log_std = nn.Parameter(torch.tensor(float(init_log_std)))
        # a buffer, so that the weights file says which input the network expects
        self.register_buffer("context", torch.tensor(bool(context)))
        self.n_features = n_features

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """Trust logits μ ``(..., L)`` from one UAV's channels ``(..., L, F)``."""
        if obs.ndim < 2 or obs.shape[-1] != self.n_features:
            raise ValueError(f"obs must have shape (..., L, F = {self.n_features}), got {tuple(obs.shape)}")
        x = torch.cat([obs, channel_context(obs)], dim=-1) if bool(self.context) else obs
        return limit_logit(self.body(x).squeeze(-1))

    def trust(self, obs: torch.Tensor) -> torch.Tensor:
        """Deterministic α_raw = sigmoid(μ) ``(..., L)`` in (0, 1)."""
        return torch.sigmoid(self(obs))


def hidden_sizes(state_dict: dict[str, torch.Tensor]) -> tuple[int, ...]:
    """Hidden widths of a ``ChannelActor`` from its state_dict (``body.{2k}.weight`` rows)."""
    widths = []
    k = 0
    while f"body.{k}.weight" in state_dict:
        widths.append(int(state_dict[f"body.{k}.weight"].shape[0]))
        k += 2
    if len(widths) < 2:
        raise ValueError(f"not a ChannelActor state_dict: keys {sorted(state_dict)}")
    return tuple(widths[:-1])


def read_state_dict(weights: str | Path, method: str, network: str, keys: tuple[str, ...]) -> dict[str, torch.Tensor]:
    """The tensors of a plain state_dict file (``torch.save(actor.state_dict())``) of ``method``'s ``network``,
    on the CPU (``weights_only``).

    Raises:
        FileNotFoundError: no such file (the message says how to train one: ``swarmloc train <method>``).
        ValueError: not a dict holding every one of ``keys``.
    """
    path = Path(weights)
    if not path.is_file():
        raise FileNotFoundError(f"{method} weights {path} not found; train them with "
                                f"`swarmloc train {method} --weights-out {path}`")
    state = torch.load(path, map_location="cpu", weights_only=True)
    if not isinstance(state, dict) or any(k not in state for k in keys):
        raise ValueError(f"{path} is not a {network} state_dict (expected the keys {', '.join(keys)})")
    return state


def load_actor(weights: str | Path) -> ChannelActor:
    """A ``ChannelActor`` from a plain state_dict file (widths and input read from the tensors).

    Raises:
        FileNotFoundError, ValueError: see ``read_state_dict``.
    """
    state = read_state_dict(weights, "mappo", "ChannelActor", ("body.0.weight",))
    # weights from before the context input carry no flag: they are purely per-channel
    state.setdefault("context", torch.tensor(False))
    context = bool(state["context"])
    n_features = int(state["body.0.weight"].shape[1]) - (len(CONTEXT_FEATURES) if context else 0)
    actor = ChannelActor(n_features=n_features, hidden=hidden_sizes(state), context=context)
    actor.load_state_dict(state)
    actor.eval()
    return actor


def count_flops_per_channel(actor: ChannelActor) -> float:
    """FLOPs of one channel's forward pass, counted once with ``torch.utils.flop_counter``.

    ``FlopCounterMode`` counts the matrix products (2 FLOPs per multiply-add); the biases,
    ReLUs, tanh limit and sigmoid add a few per unit, counted here as one FLOP per unit.
    """
    from torch.utils.flop_counter import FlopCounterMode

    x = torch.zeros(1, actor.n_features)  # one UAV with one channel
    with torch.no_grad(), FlopCounterMode(display=False) as counter:
        actor.trust(x)
    units = sum(m.out_features for m in actor.body if isinstance(m, nn.Linear))
    # the context: per channel, one multiply-add per context feature into the means, plus the division
    context = 3 * len(CONTEXT_FEATURES) if bool(actor.context) else 0
    return float(counter.get_total_flops() + 2 * units + 4 + context)


def trained_kinds(tasks) -> np.ndarray:
    """``(N_KINDS,)`` bool: the channel kinds (anchor, peer, landmark, GPS, relative position)
    that occur in any of ``tasks`` (registered IDs), i.e. that a policy trained on them has seen."""
    from swarmloc.envs.tasks.channels import build_layout
    from swarmloc.envs.tasks.catalogue import get_spec

    seen = np.zeros(N_KINDS, dtype=bool)
    for task in tasks:
        layout = build_layout(get_spec(task))
        seen[np.unique(layout.kind[layout.linked])] = True
    return seen


def weights_kinds(weights: str | Path) -> np.ndarray | None:
    """The channel kinds the weights were trained on, from the training tasks in their
    provenance record (``<name>.json``); None (every kind) without a record."""
    tasks = weights_metadata(weights).get("config", {}).get("tasks")
    return trained_kinds(tasks) if tasks else None


def kinds_mask(kinds: np.ndarray | None) -> np.ndarray:
    """The ``(N_KINDS,)`` bool mask of the channel kinds a learned actor decides; None: every kind.

    Raises:
        ValueError: not one flag per channel kind.
    """
    kinds = np.ones(N_KINDS, dtype=bool) if kinds is None else np.asarray(kinds, dtype=bool)
    if kinds.shape != (N_KINDS,):
        raise ValueError(f"kinds must be a ({N_KINDS},) bool mask over the channel kinds, got shape {kinds.shape}")
    return kinds


def decided_trust(alpha: torch.Tensor, obs: np.ndarray, kinds: np.ndarray) -> np.ndarray:
    """The actor's α ``(B, N, L)`` (float64) on the channels it decides, the nominal trust 1 elsewhere.

    Absent channels are skipped by the CEKF anyway, and a channel of a kind the actor was
    not trained on (``kinds`` False) gets the plain CEKF's trust: report 1 on both.
    """
    decided = (obs[..., VALID] > 0.5) & (obs[..., KIND0:KIND0 + N_KINDS] @ kinds.astype(np.float32) > 0.5)
    return np.where(decided, alpha.numpy().astype(np.float64), 1.0)


class MappoPolicy:
    """The trained MAPPO actor as a ``LinkTrustPolicy`` (numpy in, numpy out).

    A learned policy is only defined where it was trained: channels of a kind that its
    training tasks never had (``kinds``; e.g. GPS and relative-position links for the
    shipped weights, trained on UWB ranging tasks) get the nominal trust α = 1, i.e. the
    plain CEKF, instead of the output of a network that never saw such inputs.

    Args:
        actor: a ``ChannelActor`` (e.g. from ``load_actor``).
        isolation: False → trust fixed at 1 (the madrl "no evaluation" ablation; the
            network is not run and costs no FLOPs).
        kinds: ``(N_KINDS,)`` bool, the channel kinds the actor decides (default: all;
            ``weights_kinds`` reads them from a weights file's record).

    Attributes:
        privileged: False (reads only the observation).
        deterministic: True (the mean logit, no sampling).
        flops_per_channel: FLOPs of the network per present channel per step.
    """

    privileged = False
    deterministic = True

    def __init__(self, actor: ChannelActor, isolation: bool = True, kinds: np.ndarray | None = None) -> None:
        self.actor = actor.eval()
        self.isolation = bool(isolation)
        self.kinds = kinds_mask(kinds)
        self.flops_per_channel = count_flops_per_channel(actor) if self.isolation else 0.0
        self._shape: tuple[int, int, int] = (0, 0, 0)

    def reset(self, batch_size: int, layout: ChannelLayout, keys: np.ndarray) -> None:
        """Start B episodes (the actor is memoryless: its memory is the previous-trust feature)."""
        if batch_size < 1:
            raise ValueError(f"batch_size must be >= 1, got {batch_size}")
        self._shape = (batch_size, *layout.kind.shape)

    def act(self, inp: TrustInput) -> np.ndarray:
        """α_raw ``(B, N, L)`` float64 in (0, 1] from the observation ``(B, N, L, F)``."""
        obs = np.asarray(inp.obs)
        if obs.ndim != 4 or obs.shape[-1] != self.actor.n_features:
            raise ValueError(f"obs must have shape (B, N, L, {self.actor.n_features}), got {obs.shape}")
        if not self.isolation:
            return np.ones(obs.shape[:-1])
        with torch.no_grad():
            # a copy: the caller's buffers are read-only views that it reuses
            alpha = self.actor.trust(torch.tensor(obs, dtype=torch.float32))
        return decided_trust(alpha, obs, self.kinds)

    def __repr__(self) -> str:
        return (f"MappoPolicy(isolation={self.isolation}, kinds={self.kinds.astype(int).tolist()}, "
                f"flops_per_channel={self.flops_per_channel:.0f})")


def weights_metadata(weights: str | Path) -> dict:
    """The provenance record next to a weights file (``<name>.json``), or {} if absent."""
    meta = Path(weights).with_suffix(".json")
    return json.loads(meta.read_text()) if meta.is_file() else {}


# --------------------------------------------------------------------------- registry factories


#: the shipped weights of each benchmark version, trained on that version's tasks (v0: the
#: v0 UWB ranging tasks, frozen with v0; v1: the v1 randomized families' training seeds; v2: the run
#: of the three whose dev-v2 score is the median, the rule of docs/learned.md); a version
#: without an entry runs the newest older one (``mappo-set-gru`` was first trained on v1 and runs
#: those weights on v0 tasks too)
SHIPPED: dict[str, dict[int, str]] = {
    "mappo": {0: "mappo.pt", 1: "mappo_v1.pt", 2: "mappo_v2.seed2.pt"},
    "mappo-accuracy-only": {0: "mappo_accuracy_only.pt", 1: "mappo_accuracy_only_v1.pt"},
    "mappo-set-gru": {0: "mappo_set_gru.pt", 2: "mappo_set_gru_v2.seed3.pt"},
}


def shipped_weights(method: str, version: int | None = None) -> Path:
    """The shipped weights file of ``method`` (``SHIPPED``) for benchmark ``version`` (None: the newest)."""
    return shipped_for_version({v: WEIGHTS_DIR / name for v, name in SHIPPED[method].items()}, version)


def _policy(weights: str | Path | None, version: int | None, shipped: str, isolation: bool = True) -> MappoPolicy:
    path = Path(weights) if weights is not None else shipped_weights(shipped, version)
    return MappoPolicy(load_actor(path), isolation=isolation, kinds=weights_kinds(path))


def mappo(weights: str | Path | None = None, version: int | None = None) -> MarkovSmoothing:
    """``mappo``: the shipped weights of the benchmark version (``SHIPPED``), deterministic actor + adaptive
    Markov smoothing (β_max 0.85, γ 2)."""
    return MarkovSmoothing(_policy(weights, version, "mappo"), BETA_MAX, SMOOTHING_GAMMA)


def mappo_no_smoothing(weights: str | Path | None = None, version: int | None = None) -> MappoPolicy:
    """``mappo-no-smoothing``: the same weights, raw α applied (madrl Exp. 6)."""
    return _policy(weights, version, "mappo")


def mappo_no_isolation(weights: str | Path | None = None, version: int | None = None) -> MarkovSmoothing:
    """``mappo-no-isolation``: trust fixed at 1 after training, smoothing kept (madrl Exp. 6 "no evaluation")."""
    return MarkovSmoothing(_policy(weights, version, "mappo", isolation=False), BETA_MAX, SMOOTHING_GAMMA)


def mappo_accuracy_only(weights: str | Path | None = None, version: int | None = None) -> MarkovSmoothing:
    """``mappo-accuracy-only``: weights trained with λ_delay = λ_energy = λ_jitter = 0 (madrl Exp. 7) + smoothing."""
    return MarkovSmoothing(_policy(weights, version, "mappo-accuracy-only"), BETA_MAX, SMOOTHING_GAMMA)
