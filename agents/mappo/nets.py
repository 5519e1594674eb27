"""The torch modules of MAPPO link-trust training (``swarmloc.agents.mappo.train``).

The centralized critic, the trust-logit distributions (masked, and with held exploration
noise) and the torchrl wiring of actor, policy and critic. The actor network itself is
``ChannelActor`` in ``mappo_policy.py`` (it is all that evaluation needs).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import torch
from torch import nn

from swarmloc.envs.world.observation import INNOVATION, N_FEATURES, SCALE_INNOVATION, VALID, squash

from swarmloc.agents.mappo.policy import ChannelActor

if TYPE_CHECKING:
    from swarmloc.agents.mappo.config import MappoConfig

G = "uav"  # the env's agent group


class SwarmCritic(nn.Module):
    """Centralized per-UAV value V_i(s) from the global state, permutation-invariant over UAVs.

    Channel embeddings φ(o_ij) are mean- and max-pooled over each UAV's present channels
    (so channel order and count do not matter), joined with the UAV's filter state from
    the env's ``"state"`` (speed and prior position std, squashed) into a UAV embedding
    e_i; the swarm context is the mean of e_j over UAVs. V_i = ψ(e_i, mean_j e_j).
    Permuting the UAVs permutes the values and nothing else.

    With ``privileged=True`` each UAV's embedding also gets its true position error of
    the last update (the env's ``("uav", "info", "position_error")``) — truth the critic
    may see because it only exists during training (CTDE); the actor never does. The
    accuracy reward is a function of that error, so the value baseline gets much sharper.

    Args:
        n_features: F.
        width: embedding width.
        privileged: also read the per-UAV position error.
    """

    def __init__(self, n_features: int = N_FEATURES, width: int = 128, privileged: bool = True) -> None:
        super().__init__()
        half = width // 2
        self.privileged = privileged
        n_uav_features = 4 if privileged else 2
        self.channel = nn.Sequential(nn.Linear(n_features, width), nn.ReLU(), nn.Linear(width, half), nn.ReLU())
        self.uav = nn.Sequential(nn.Linear(2 * half + n_uav_features, width), nn.ReLU(), nn.Linear(width, half),
                                 nn.ReLU())
        self.head = nn.Sequential(nn.Linear(2 * half, width), nn.ReLU(), nn.Linear(width, 1))

    def forward(self, obs: torch.Tensor, state: torch.Tensor, error: torch.Tensor | None = None) -> torch.Tensor:
        """Values ``(..., N, 1)`` from observations ``(..., N, L, F)``, state ``(..., S)`` and,
        when privileged, the position errors ``(..., N, 1)`` [m]."""
        n, n_l, n_f = obs.shape[-3:]
        lead = obs.shape[:-3]
        # state = [obs (N·L·F), prior position (3N), velocity (3N), position std (N)]
        tail = state[..., n * n_l * n_f:]
        if tail.shape[-1] != 7 * n:
            raise ValueError(f"state has {state.shape[-1]} entries; expected N·L·F + 7N = {n * n_l * n_f + 7 * n}")
        speed = tail[..., 3 * n:6 * n].reshape(*lead, n, 3).norm(dim=-1)
        pos_std = tail[..., 6 * n:7 * n]
        features = [squash(speed, 1.0), squash(pos_std, 1.0)]
        if self.privileged:
            if error is None:
                raise ValueError("a privileged SwarmCritic needs the per-UAV position error")
            err = error[..., 0]
            features += [squash(err, 1.0), torch.exp(-0.5 * err**2)]  # the latter: last step's accuracy reward
        uav_state = torch.stack(features, dim=-1)  # (..., N, 2 or 4)
        valid = obs[..., VALID:VALID + 1]  # (..., N, L, 1)
        h = self.channel(obs)
        h_mean = (h * valid).sum(-2) / valid.sum(-2).clamp(min=1.0)
        h_max = (h * valid).amax(-2)  # embeddings are ≥ 0 (ReLU), so absent channels never win
        e = self.uav(torch.cat([h_mean, h_max, uav_state], dim=-1))  # (..., N, half)
        context = e.mean(-2, keepdim=True).expand_as(e)
        return self.head(torch.cat([e, context], dim=-1))


class MaskedNormal(torch.distributions.Normal):
    """Gaussian on the trust logit; absent channels carry no decision (log-prob and entropy 0).

    Args:
        loc, scale: ``(..., L)`` mean and std of the logit.
        valid: ``(..., L)`` bool, measurement present.
    """

    def __init__(self, loc: torch.Tensor, scale: torch.Tensor, valid: torch.Tensor) -> None:
        super().__init__(loc, scale, validate_args=False)
        self.valid = valid

    def log_prob(self, value: torch.Tensor) -> torch.Tensor:
        return torch.where(self.valid, super().log_prob(value), torch.zeros_like(value))

    def entropy(self) -> torch.Tensor:
        return torch.where(self.valid, super().entropy(), torch.zeros_like(self.loc))

    @property
    def deterministic_sample(self) -> torch.Tensor:
        return self.loc


class HeldNoiseNormal(MaskedNormal):
    """``MaskedNormal`` that samples u = μ + σ ε with a given standard-normal ε (held over steps).

    The log-probability is the per-step Gaussian's, as for ``MaskedNormal``; only where the
    noise comes from differs (see ``HeldNoise``).
    """

    def __init__(self, loc: torch.Tensor, scale: torch.Tensor, valid: torch.Tensor, noise: torch.Tensor) -> None:
        super().__init__(loc, scale, valid)
        self.noise = noise

    def rsample(self, sample_shape: torch.Size = torch.Size()) -> torch.Tensor:
        if len(sample_shape):
            raise ValueError("HeldNoiseNormal draws one sample per step (its noise is given)")
        return self.loc + self.scale * self.noise

    def sample(self, sample_shape: torch.Size = torch.Size()) -> torch.Tensor:
        with torch.no_grad():
            return self.rsample(sample_shape)


class HeldNoise(nn.Module):
    """Exploration noise ε ~ N(0, 1) per channel, redrawn every ``hold`` policy calls.

    Trust acts on the filter through its error, which builds up over many steps: a
    perturbation held for ``hold`` steps changes the error (and the reward) clearly,
    while per-step noise mostly adds jitter. ``start_batch()`` is called before every
    collector batch, so blocks align with batches (and, as ``hold`` divides the
    rollout length and the rollout length divides the episode length, with episodes).
    Draws come from torch's global generator (deterministic under ``torch.manual_seed``).

    Args:
        hold: steps a draw is kept (1 = independent noise every step).
    """

    def __init__(self, hold: int) -> None:
        super().__init__()
        self.hold = hold
        self._eps: torch.Tensor | None = None
        self._calls = 0

    def start_batch(self) -> None:
        self._eps, self._calls = None, 0

    def forward(self, loc: torch.Tensor) -> torch.Tensor:
        if self._eps is None or self._eps.shape != loc.shape or self._calls % self.hold == 0:
            self._eps = torch.randn(loc.shape)
        self._calls += 1
        return self._eps


class LoopSmoother(nn.Module):
    """Adaptive Markov smoothing inside the training loop (madrl Algorithm 1, phase 2).

    The env applies α_eff = β α_eff(k−1) + (1 − β) α_raw, β = β_max exp(−γ |r(k) − r(k−1)|),
    exactly what ``MarkovSmoothing`` does at execution, so the policy is trained in the
    loop it runs in: its per-step exploration noise reaches the filter (and the jitter
    term of the reward) low-passed. r is read back from the observation's innovation
    feature (``unsquash``; float32). Absent channels keep α_eff and r.

    Episodes of different tasks interleave (one collector per task, cycled per batch), so
    the state is kept per task: ``select(task, fresh)`` before each batch picks it, and
    ``fresh=True`` (a batch that starts an episode) restarts it at α_eff = 1, r = 0.

    Args:
        beta_max, gamma: β_max and γ [1/m] (the execution-time values).
    """

    def __init__(self, beta_max: float, gamma: float) -> None:
        super().__init__()
        self.beta_max = float(beta_max)
        self.gamma = float(gamma)
        self._states: dict[int, tuple[torch.Tensor, torch.Tensor]] = {}
        self._key = 0

    def select(self, key: int, fresh: bool) -> None:
        self._key = key
        if fresh:
            self._states.pop(key, None)

    def forward(self, raw: torch.Tensor, obs: torch.Tensor) -> torch.Tensor:
        valid = obs[..., VALID] > 0.5
        y = obs[..., INNOVATION]
        resid = SCALE_INNOVATION * y / (1.0 - y).clamp(min=1e-6)  # unsquash
        state = self._states.get(self._key)
        if state is None or state[0].shape != raw.shape:
            state = (torch.ones_like(raw), torch.zeros_like(raw))
        alpha_prev, resid_prev = state
        # β = β_max exp(−γ Δr);  α_eff = β α_eff(k−1) + (1 − β) α_raw
        beta = self.beta_max * torch.exp(-self.gamma * (resid - resid_prev).abs())
        alpha = torch.where(valid, beta * alpha_prev + (1.0 - beta) * raw, alpha_prev)
        self._states[self._key] = (alpha.detach(), torch.where(valid, resid, resid_prev).detach())
        return alpha


class PendingLabels(nn.Module):
    """Training only: the error labels of the measurements the policy is deciding, read from the env.

    The collectors run in this process, so the env of the batch's task is at hand
    (``select``); its pending labels are those of the observation the policy sees. They go
    into the batch as ``("uav", "fault_label")`` for the auxiliary loss and never into the actor.
    """

    def __init__(self, envs: list) -> None:
        super().__init__()
        self.envs = envs
        self._key = 0

    def select(self, key: int) -> None:
        self._key = key

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        if self._key >= len(self.envs):  # a collector's probe call while it is being built
            return torch.zeros(obs.shape[:-1], dtype=torch.bool)
        labels = self.envs[self._key].batch.pending_error_labels()
        if labels.shape != obs.shape[:-1]:
            raise RuntimeError(f"labels {labels.shape} do not match the observation {tuple(obs.shape[:-1])}")
        return torch.from_numpy(np.array(labels, dtype=bool))


class _ActorParams(nn.Module):
    """``ChannelActor`` → (μ, σ, valid) per channel, the inputs of ``MaskedNormal``."""

    def __init__(self, actor: ChannelActor) -> None:
        super().__init__()
        self.actor = actor

    def forward(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        loc = self.actor(obs)
        return loc, self.actor.log_std.exp().expand_as(loc), obs[..., VALID] > 0.5


def _logit_to_trust(logit: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """α = sigmoid(u) on present channels, 1 on absent ones (as ``MappoPolicy`` does)."""
    return torch.where(valid, torch.sigmoid(logit), torch.ones_like(logit))


def acting_modules(cfg: "MappoConfig", labels: PendingLabels | None = None) -> list:
    """What follows the actor's (μ, σ, valid) in the acting policy: held exploration noise, the
    sample u = μ + σ ε with its log-probability, α = sigmoid(u), the in-loop smoother if
    ``cfg.train_smoothing``, and, with ``labels``, the pending fault labels (training only)."""
    from tensordict.nn import ProbabilisticTensorDictModule, TensorDictModule
    from torchrl.envs.utils import ExplorationType

    smoother = LoopSmoother(*cfg.smoothing) if cfg.train_smoothing else None
    trust_key = (G, "raw_trust") if smoother is not None else (G, "action")
    # exploration noise held over cfg.noise_hold steps
    sample = ProbabilisticTensorDictModule(
        in_keys={"loc": (G, "loc"), "scale": (G, "scale"), "valid": (G, "valid"), "noise": (G, "noise")},
        out_keys=[(G, "trust_logit")], distribution_class=HeldNoiseNormal, return_log_prob=True,
        log_prob_key=(G, "trust_logit_log_prob"), default_interaction_type=ExplorationType.RANDOM)
    modules = [TensorDictModule(HeldNoise(cfg.noise_hold), in_keys=[(G, "loc")], out_keys=[(G, "noise")]), sample,
               TensorDictModule(_logit_to_trust, in_keys=[(G, "trust_logit"), (G, "valid")], out_keys=[trust_key])]
    if smoother is not None:
        modules.append(TensorDictModule(smoother, in_keys=[(G, "raw_trust"), (G, "observation")],
                                        out_keys=[(G, "action")]))
    if labels is not None:
        modules.append(TensorDictModule(labels, in_keys=[(G, "observation")], out_keys=[(G, "fault_label")]))
    return modules


def build_modules(cfg: "MappoConfig", labels: PendingLabels | None = None) -> tuple:
    """The actor network, its probabilistic torchrl wrapper, the acting policy and the critic module
    (with ``labels``, the acting policy also records the pending fault labels: training only).

    Returns:
        ``(ChannelActor, ProbabilisticActor for the loss, acting policy (``acting_modules`` after
        the actor), critic TensorDictModule, the HeldNoise module, the LoopSmoother or None)``.
    """
    # torchrl is imported here, not at the top, so that the CLI can read MappoConfig quickly
    from tensordict.nn import TensorDictModule, TensorDictSequential
    from torchrl.envs.utils import ExplorationType
    from torchrl.modules import ProbabilisticActor

    actor_net = ChannelActor(N_FEATURES, cfg.hidden, cfg.init_trust, cfg.init_log_std, cfg.channel_context)
    params = TensorDictModule(_ActorParams(actor_net), in_keys=[(G, "observation")],
                              out_keys=[(G, "loc"), (G, "scale"), (G, "valid")])
    prob_actor = ProbabilisticActor(
        params, in_keys={"loc": (G, "loc"), "scale": (G, "scale"), "valid": (G, "valid")},
        out_keys=[(G, "trust_logit")], distribution_class=MaskedNormal, return_log_prob=True,
        log_prob_key=(G, "trust_logit_log_prob"), default_interaction_type=ExplorationType.RANDOM)
    # acting: the same parameters
    policy = TensorDictSequential(params, *acting_modules(cfg, labels))
    noise = next(m.module for m in policy.module if isinstance(getattr(m, "module", None), HeldNoise))
    smoothers = [m.module for m in policy.module if isinstance(getattr(m, "module", None), LoopSmoother)]
    critic_in = [(G, "observation"), "state"] + ([(G, "info", "position_error")] if cfg.privileged_critic else [])
    critic = TensorDictModule(SwarmCritic(N_FEATURES, cfg.critic_hidden, cfg.privileged_critic), in_keys=critic_in,
                              out_keys=[(G, "state_value")])
    return actor_net, prob_actor, policy, critic, noise, (smoothers[0] if smoothers else None)
