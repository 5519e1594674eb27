"""MAPPO link trust (madrl §2.2–2.3): CTDE training on the native batched torchrl env.

CleanRL style: the configuration and the training loop are here, the torch modules in
``mappo_nets.py``, the actor (all that evaluation needs) in ``mappo_policy.py``.

* **Actor** (``ChannelActor``): the paper's 128–64 ReLU MLP applied to every channel of
  every UAV with the same weights. Per channel it sees that channel's F = 11 features and
  outputs a trust logit μ; the applied trust is α = sigmoid(u), u ~ N(μ, σ²) while
  training (the paper's sigmoid output; sampling the logit keeps PPO's log-probabilities
  exact, with no inverse squashing) and u = μ at execution. Each channel is a decision
  with its own PPO ratio and its UAV's advantage (per-UAV standard reward v0).
* **Exploration**: σ starts at 2 in logit space (α spans ≈ 0.04 … 0.99), because
  isolating a faulty link only pays off close to α → 0 (R = R0/α), far from any initial
  trust. A fresh draw every step (``noise_hold`` = 1), low-passed by the smoother below.
* **Smoothing in the loop** (madrl Algorithm 1): while training, the env applies the
  adaptively smoothed α_eff (eq. 15–17, the execution-time β_max and γ), not the raw
  sample. Per-step exploration noise then reaches the filter — and the reward's jitter
  term — low-passed, instead of being paid in full as jitter. Without it (the first
  shipped runs) the λ3 = 5 jitter penalty pulled the nine-task policy to α ≈ 1 on every
  link within ≈ 80k frames.
* **Critic** (``SwarmCritic``): centralized, training only. It sees the whole swarm (every
  UAV's channels, the env's ``"state"``, and — privileged, since it never runs at
  execution — each UAV's position error) and is permutation-invariant over UAVs, so one
  critic trains across swarm sizes.
* **Multi-task**: one torchrl collector per task (each on its own batched env), cycled
  per batch: NLOS, step NLOS, swarm sizes 2…8, cascaded faults, the ideal case. Episode
  seeds are training seeds (< 1_000_000) drawn deterministically from the run's seed.
  The collectors run here or, with ``collectors = N``, as N synchronized workers per task
  (torchrl's ``MultiSyncCollector`` or ``RayCollector``; ``mappo_collect.py``).

At execution the actor is deterministic and wrapped in adaptive Markov smoothing
(madrl eq. 15–17), see ``mappo_policy.py``.

Run: ``swarmloc train mappo --frames 1000000`` (``swarmloc.bench.training.mappo``: seed checks,
dev-seed evaluation, provenance).
"""

from __future__ import annotations

import copy
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from swarmloc.envs.world.observation import N_FEATURES, VALID
from swarmloc.envs.tasks.catalogue import get_spec

from swarmloc.agents.mappo.collect import Collection, EpisodeSeeds  # noqa: F401  (EpisodeSeeds re-exported)
from swarmloc.agents.mappo.config import DEFAULT_TASKS, MappoConfig  # noqa: F401  (re-exported)
from swarmloc.agents.mappo.nets import G, PendingLabels, build_modules
from swarmloc.agents.mappo.policy import MappoPolicy, count_flops_per_channel
from swarmloc.agents.trust.smoothing import SMOOTHING_FLOPS_PER_CHANNEL

#: where the per-UAV reward terms live in the env's tensordict, and their TensorBoard names
REWARD_TERMS = {"accuracy": "reward_accuracy", "delay_penalty": "reward_delay", "energy_penalty": "reward_energy",
                "jitter_penalty": "reward_jitter", "position_error": "position_error", "delay_ms": "delay_ms"}



# --------------------------------------------------------------------------- boilerplate


@dataclass
class TrainResult:
    """What ``train`` returns."""

    actor_state: dict
    frames: int
    wall_time_s: float
    iterations: int
    episode_seeds: list[int]
    last_eval: dict[str, float]


def probe_features() -> tuple[torch.Tensor, dict[str, int]]:
    """A fixed UAV whose trust is logged while training (is isolation being learned?).

    8 anchor and 3 peer links, all clean (innovation ≈ 0.1 m, NIS ≈ 0.5) except one
    faulty anchor and one faulty peer (≈ 3 m, NIS ≈ 45); previous trust 0.8; features as
    ``build_observation`` scales them. Returns the ``(L, F)`` input and the logged channels.
    """
    x = torch.zeros(11, N_FEATURES)
    x[:, :5] = torch.tensor([0.1, 0.6, 0.8, 0.1, 0.1])
    x[:8, 5] = 1.0  # anchors
    x[8:, 6] = 1.0  # peers
    x[:, VALID] = 1.0
    for faulty in (0, 8):
        x[faulty, 0], x[faulty, 4] = 0.75, 0.9
    return x, {"anchor_faulty": 0, "anchor_clean": 1, "peer_faulty": 8, "peer_clean": 9}


def _team_returns(reward: torch.Tensor, done: torch.Tensor, running: np.ndarray) -> list[float]:
    """Finished episodes' team returns from a ``(B, T)`` batch (``running`` carries partial sums)."""
    team = reward.mean(dim=(-2, -1)).numpy()  # (B, T): mean over UAVs
    ended = done.reshape(done.shape[0], done.shape[1]).numpy()
    out: list[float] = []
    for k in range(team.shape[1]):
        running += team[:, k]
        if ended[:, k].any():
            out.extend(running[ended[:, k]].tolist())
            running[ended[:, k]] = 0.0
    return out


def log_rollout(writer, batch, running: np.ndarray, task: str, frames: int) -> list[float]:
    """Log a collected ``(B, T)`` batch (episodic returns, reward terms, mean trust); returns the finished
    episodes' team returns. Shared by both MAPPO training loops."""
    nxt = batch["next"]
    returns = _team_returns(nxt[G, "reward"], nxt["done"], running)
    if returns:
        writer.add_scalar("charts/episodic_return", float(np.mean(returns)), frames)
        writer.add_scalar(f"charts/episodic_return_{task.removeprefix('swarmloc/')}", float(np.mean(returns)), frames)
    for term, name in REWARD_TERMS.items():
        writer.add_scalar(f"charts/{name}", nxt[G, "info", term].mean().item(), frames)
    writer.add_scalar("charts/trust_mean", batch[G, "action"][batch[G, "valid"]].mean().item(), frames)
    return returns


def normalized_advantages(batch, gae, reward_scale: float) -> float:
    """GAE on the per-UAV reward (done flags broadcast to every UAV, rewards scaled), then the advantage
    standardized over the batch, in place; returns the seconds GAE took."""
    nxt = batch["next"]
    reward_shape = nxt[G, "reward"].shape
    for flag in ("done", "terminated"):
        nxt.set((G, flag), nxt[flag].unsqueeze(-1).expand(reward_shape))
    nxt.set((G, "reward"), nxt[G, "reward"] * reward_scale)
    tic = time.perf_counter()
    with torch.no_grad():
        gae(batch)
    seconds = time.perf_counter() - tic
    adv = batch[G, "advantage"]
    batch.set((G, "advantage"), (adv - adv.mean()) / adv.std().clamp(min=1e-6))
    return seconds


def label_loss(logits: torch.Tensor, fault_label: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """The privileged auxiliary loss: binary cross-entropy of the trust logits against "healthy" (not
    fault-labelled), averaged over the present channels (``valid``, bool or 0/1)."""
    bce = torch.nn.functional.binary_cross_entropy_with_logits(logits, (~fault_label).float(), reduction="none")
    valid = valid.float()
    return (bce * valid).sum() / valid.sum().clamp(min=1)


def log_iteration(writer, bar, stats: dict[str, list[float]], log_std: float, probe_trust: torch.Tensor,
                  probe_channels: dict[str, int], lr: float, frames: int, start: float,
                  timings: dict[str, float], n_frames: int, task: str, returns: list[float]) -> None:
    """The end of an iteration's logging: losses, log σ, the probe UAV's trust, learning rate, SPS,
    timings and the progress bar."""
    for key, vals in stats.items():
        writer.add_scalar(f"losses/{key.removeprefix('loss_')}", float(np.mean(vals)), frames)
    writer.add_scalar("charts/log_std", log_std, frames)
    for name, index in probe_channels.items():
        writer.add_scalar(f"probe/trust_{name}", probe_trust[index].item(), frames)
    writer.add_scalar("charts/learning_rate", lr, frames)
    sps = frames / max(time.time() - start, 1e-9)
    writer.add_scalar("charts/SPS", sps, frames)
    for name, seconds in timings.items():
        writer.add_scalar(f"charts/time_{name}_s", seconds, frames)
    bar.update(n_frames)
    bar.set_postfix(task=task.removeprefix("swarmloc/")[:12], ret=f"{np.mean(returns):.1f}" if returns else "-",
                    sps=f"{sps:.0f}")


def train(cfg: MappoConfig, evaluate: Callable[[MappoPolicy], dict[str, float]] | None = None,
          check_seeds: Callable[[list[int]], None] | None = None, writer=None) -> TrainResult:
    """Train the MAPPO link-trust actor and critic.

    Args:
        cfg: the run's configuration.
        evaluate: optional dev-seed evaluator, called with a deterministic, unsmoothed
            ``MappoPolicy`` snapshot every ``cfg.eval_every`` frames and at the end;
            returns metrics logged under ``eval/``.
        check_seeds: optional guard called with every episode seed before it is used
            (e.g. ``swarmloc.bench.evaluation.suites.check_training_seeds``).
        writer: optional TensorBoard ``SummaryWriter`` (default: one in ``cfg.run_dir``).

    Returns:
        ``TrainResult`` with the actor's state_dict.
    """
    import numba
    from torch.utils.tensorboard import SummaryWriter
    from torchrl.data import LazyTensorStorage, ReplayBuffer, SamplerWithoutReplacement
    from torchrl.objectives import ClipPPOLoss
    from torchrl.objectives.value import GAE
    from tqdm import tqdm

    # ---- determinism and threads
    torch.manual_seed(cfg.seed)
    torch.set_num_threads(1)  # portable bit-identity: see MappoConfig.threads
    numba.set_num_threads(min(cfg.threads, numba.config.NUMBA_NUM_THREADS))
    run_dir = Path(cfg.run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    own_writer = writer is None
    writer = writer or SummaryWriter(str(run_dir))
    writer.add_text("config", "\n".join(f"- {k}: {v}" for k, v in asdict(cfg).items()))

    envs: list = []  # the collectors' envs, for the privileged labels (filled once they are built)
    labels = PendingLabels(envs) if cfg.label_coef > 0 else None
    actor_net, prob_actor, policy, critic, _, _ = build_modules(cfg, labels)  # noise, smoother: found by Collection
    flops_per_channel = count_flops_per_channel(actor_net) + SMOOTHING_FLOPS_PER_CHANNEL

    # ---- one batched env + collector per task (here, or N workers each); training seeds only
    env_kwargs = [dict(reward_weights=cfg.weights(), policy_flops=flops_per_channel * get_spec(task).n_channels)
                  for task in cfg.tasks]
    collection = Collection(cfg.tasks, cfg.num_envs, cfg.rollout_steps, cfg.seed, policy, env_kwargs,
                            collectors=cfg.collectors, backend=cfg.backend, address=cfg.address,
                            check_seeds=check_seeds, threads=cfg.threads)
    envs.extend(collection.envs)
    probe_x, probe_channels = probe_features()
    running = [np.zeros(cfg.num_envs) for _ in cfg.tasks]

    # ---- PPO pieces
    loss = ClipPPOLoss(prob_actor, critic, clip_epsilon=cfg.clip_epsilon, entropy_bonus=True,
                       entropy_coeff=cfg.entropy_coef, critic_coeff=cfg.critic_coef, loss_critic_type="l2",
                       normalize_advantage=False)
    keys = dict(action=(G, "trust_logit"), sample_log_prob=(G, "trust_logit_log_prob"), value=(G, "state_value"),
                reward=(G, "reward"), done=(G, "done"), terminated=(G, "terminated"), advantage=(G, "advantage"),
                value_target=(G, "value_target"))
    loss.set_keys(**keys)
    gae = GAE(gamma=cfg.gamma, lmbda=cfg.gae_lambda, value_network=critic, average_gae=False)
    gae.set_keys(**{k: v for k, v in keys.items() if k not in ("action", "sample_log_prob")})
    optimizer = torch.optim.Adam(loss.parameters(), lr=cfg.learning_rate)
    # one buffer per task: N and L (the storage's shape) differ between tasks
    replays = [ReplayBuffer(storage=LazyTensorStorage(cfg.frames_per_batch), sampler=SamplerWithoutReplacement(),
                            batch_size=cfg.frames_per_batch // cfg.minibatches) for _ in cfg.tasks]

    n_iters = -(-cfg.frames // cfg.frames_per_batch)
    frames, last_eval, next_eval, next_ckpt = 0, {}, cfg.eval_every or cfg.frames, cfg.checkpoint_every or cfg.frames
    start = time.time()
    bar = tqdm(total=cfg.frames, disable=not cfg.progress, unit="frame", desc="mappo")
    for it in range(n_iters):
        t = it % len(cfg.tasks)
        task = cfg.tasks[t]
        if labels is not None:
            labels.select(t)
        tic = time.perf_counter()
        batch = collection.collect(t)  # (B, T): next seeds, noise block and smoother state set first
        t_collect = time.perf_counter() - tic
        frames += batch.numel()
        if cfg.anneal_lr:
            optimizer.param_groups[0]["lr"] = cfg.learning_rate * (1.0 - it / n_iters)
        label_weight = cfg.label_weight(it, n_iters)

        returns = log_rollout(writer, batch, running[t], task, frames)
        t_gae = normalized_advantages(batch, gae, cfg.reward_scale)

        # ---- PPO epochs over minibatches
        tic = time.perf_counter()
        replay = replays[t]
        replay.extend(batch.reshape(-1))
        stats: dict[str, list[float]] = {}
        for _ in range(cfg.epochs):
            for _ in range(cfg.minibatches):
                mb = replay.sample()
                out = loss(mb)
                total = out["loss_objective"] + out["loss_critic"] + out["loss_entropy"]
                if labels is not None:
                    # privileged auxiliary loss (``label_coef``): logit → "healthy", present channels only
                    obs = mb[G, "observation"]
                    loss_label = label_loss(actor_net(obs), mb[G, "fault_label"], obs[..., VALID])
                    total = total + label_weight * loss_label
                    stats.setdefault("label_bce", []).append(float(loss_label.detach()))
                optimizer.zero_grad()
                total.backward()
                torch.nn.utils.clip_grad_norm_(loss.parameters(), cfg.max_grad_norm)
                optimizer.step()
                for key in ("loss_objective", "loss_critic", "entropy", "kl_approx", "clip_fraction",
                            "explained_variance"):
                    if key in out.keys():
                        stats.setdefault(key, []).append(float(out[key].detach().mean()))
        with torch.no_grad():
            probe_trust = actor_net.trust(probe_x)
        log_iteration(writer, bar, stats, actor_net.log_std.item(), probe_trust, probe_channels,
                      optimizer.param_groups[0]["lr"], frames, start,
                      {"collect": t_collect, "gae": t_gae, "update": time.perf_counter() - tic}, batch.numel(), task,
                      returns)

        # ---- evaluation and checkpoints
        final = it == n_iters - 1
        if evaluate is not None and (frames >= next_eval or final):
            next_eval += cfg.eval_every or cfg.frames
            last_eval = evaluate(MappoPolicy(copy.deepcopy(actor_net).eval()))
            for key, value in last_eval.items():
                writer.add_scalar(f"eval/{key}", value, frames)
        if frames >= next_ckpt or final:
            next_ckpt += cfg.checkpoint_every or cfg.frames
            torch.save({"actor": actor_net.state_dict(), "critic": critic.module.state_dict(),
                        "optimizer": optimizer.state_dict(), "frames": frames, "config": asdict(cfg)},
                       run_dir / "checkpoint.pt")
    bar.close()
    collection.shutdown()
    writer.flush()
    if own_writer:
        writer.close()
    seeds = collection.episode_seeds()
    return TrainResult(actor_state={k: v.detach().clone() for k, v in actor_net.state_dict().items()},
                       frames=frames, wall_time_s=time.time() - start, iterations=n_iters, episode_seeds=seeds,
                       last_eval=last_eval)
