"""MAPPO link trust (madrl §2.2–2.3): CTDE training on the native batched torchrl env.

CleanRL style: the configuration and the training loop are here, the torch modules in
``nets.py``, the actor (all that evaluation needs) in ``policy.py``; ``TrainingRun`` below holds the
boilerplate that this loop and ``set_gru.py``'s share.

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
  (torchrl's ``MultiSyncCollector`` or ``RayCollector``; ``collect.py``).

At execution the actor is deterministic and wrapped in adaptive Markov smoothing
(madrl eq. 15–17), see ``policy.py``.

Run: ``swarmloc train mappo --frames 1000000`` (``swarmloc.bench.training.mappo``: seed checks,
dev-seed evaluation, provenance).
"""

from __future__ import annotations

import copy
import time
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass
from pathlib import Path

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


class TrainingRun:
    """The boilerplate both MAPPO loops share around their PPO update (``train`` here, ``set_gru.train``).

    Construction fixes determinism and threads and opens the run folder and the TensorBoard
    writer; then ``iterations`` cycles the tasks batch by batch, ``collect`` brings in and
    prepares each batch, ``log_iteration`` and ``evaluate_and_checkpoint`` end each
    iteration, and ``finish`` returns the ``TrainResult``.

    Args:
        cfg: the run's configuration (``MappoConfig`` or ``SetGruConfig``).
        writer: a TensorBoard ``SummaryWriter``, or None for one in ``cfg.run_dir`` (closed by ``finish``).
    """

    def __init__(self, cfg: MappoConfig, writer=None) -> None:
        import numba
        from torch.utils.tensorboard import SummaryWriter

        torch.manual_seed(cfg.seed)
        torch.set_num_threads(1)  # portable bit-identity: see MappoConfig.threads
        numba.set_num_threads(min(cfg.threads, numba.config.NUMBA_NUM_THREADS))
        self.cfg = cfg
        self.run_dir = Path(cfg.run_dir)
        self.run_dir.mkdir(parents=True, exist_ok=True)
        self._own_writer = writer is None
        self.writer = writer or SummaryWriter(str(self.run_dir))
        self.writer.add_text("config", "\n".join(f"- {k}: {v}" for k, v in asdict(cfg).items()))
        self.n_iters = -(-cfg.frames // cfg.frames_per_batch)
        self.frames = 0
        self.last_eval: dict[str, float] = {}
        self.probe_x, self._probe_channels = probe_features()
        self._next_eval, self._next_ckpt = cfg.eval_every or cfg.frames, cfg.checkpoint_every or cfg.frames
        self._running = [np.zeros(cfg.num_envs) for _ in cfg.tasks]  # partial team returns per task
        self._task, self._returns = "", []  # the iteration's task and finished episodes' team returns
        self._timings: dict[str, float] = {}  # the iteration's seconds: collect, gae, update
        self._start, self._update_start, self._bar = time.time(), time.perf_counter(), None

    def iterations(self, desc: str) -> Iterator[tuple[int, int]]:
        """``(iteration, task index)`` for every iteration, the tasks in turn; starts the clock and the
        progress bar (labelled ``desc``)."""
        from tqdm import tqdm

        self._start = time.time()
        self._bar = tqdm(total=self.cfg.frames, disable=not self.cfg.progress, unit="frame", desc=desc)
        for it in range(self.n_iters):
            yield it, it % len(self.cfg.tasks)

    def collect(self, it: int, collection: Collection, gae, optimizer: torch.optim.Optimizer,
                labels: PendingLabels | None = None):
        """Iteration ``it``'s ``(B, T)`` batch of its task, ready for the update.

        The pending labels switch to the task, the batch is collected (next seeds, noise
        block and smoother state set first), its frames counted, the learning rate annealed,
        the rollout logged and the standardized advantages computed (``normalized_advantages``).
        """
        cfg = self.cfg
        t = it % len(cfg.tasks)
        self._task = cfg.tasks[t]
        if labels is not None:
            labels.select(t)
        tic = time.perf_counter()
        batch = collection.collect(t)
        self._timings["collect"] = time.perf_counter() - tic
        self.frames += batch.numel()
        if cfg.anneal_lr:
            optimizer.param_groups[0]["lr"] = cfg.learning_rate * (1.0 - it / self.n_iters)
        self._returns = log_rollout(self.writer, batch, self._running[t], self._task, self.frames)
        self._timings["gae"] = normalized_advantages(batch, gae, cfg.reward_scale)
        self._update_start = time.perf_counter()
        return batch

    def log_iteration(self, stats: dict[str, list[float]], log_std: float, probe_trust: torch.Tensor,
                      optimizer: torch.optim.Optimizer, batch_frames: int) -> None:
        """The end of an iteration's logging: losses, log σ, the probe UAV's trust (``probe_x``), learning
        rate, SPS, timings and the progress bar."""
        writer, frames = self.writer, self.frames
        self._timings["update"] = time.perf_counter() - self._update_start
        for key, vals in stats.items():
            writer.add_scalar(f"losses/{key.removeprefix('loss_')}", float(np.mean(vals)), frames)
        writer.add_scalar("charts/log_std", log_std, frames)
        for name, index in self._probe_channels.items():
            writer.add_scalar(f"probe/trust_{name}", probe_trust[index].item(), frames)
        writer.add_scalar("charts/learning_rate", optimizer.param_groups[0]["lr"], frames)
        sps = frames / max(time.time() - self._start, 1e-9)
        writer.add_scalar("charts/SPS", sps, frames)
        for name, seconds in self._timings.items():
            writer.add_scalar(f"charts/time_{name}_s", seconds, frames)
        self._bar.update(batch_frames)
        self._bar.set_postfix(task=self._task.removeprefix("swarmloc/")[:12],
                              ret=f"{np.mean(self._returns):.1f}" if self._returns else "-", sps=f"{sps:.0f}")

    def evaluate_and_checkpoint(self, it: int, actor: torch.nn.Module, critic, optimizer: torch.optim.Optimizer,
                                evaluate: Callable | None, policy: Callable[[torch.nn.Module], object]) -> None:
        """Every ``eval_every`` frames and after the last iteration, ``evaluate`` a deterministic, unsmoothed
        ``policy(copy of actor)`` (logged under ``eval/``); every ``checkpoint_every`` frames and after the last
        iteration, save actor, critic and optimizer to ``run_dir/checkpoint.pt``."""
        cfg, final = self.cfg, it == self.n_iters - 1
        if evaluate is not None and (self.frames >= self._next_eval or final):
            self._next_eval += cfg.eval_every or cfg.frames
            self.last_eval = evaluate(policy(copy.deepcopy(actor).eval()))
            for key, value in self.last_eval.items():
                self.writer.add_scalar(f"eval/{key}", value, self.frames)
        if self.frames >= self._next_ckpt or final:
            self._next_ckpt += cfg.checkpoint_every or cfg.frames
            torch.save({"actor": actor.state_dict(), "critic": critic.module.state_dict(),
                        "optimizer": optimizer.state_dict(), "frames": self.frames, "config": asdict(cfg)},
                       self.run_dir / "checkpoint.pt")

    def finish(self, collection: Collection, actor: torch.nn.Module) -> TrainResult:
        """Close the progress bar, the collectors and the writer (if the run opened it); the run's result."""
        self._bar.close()
        collection.shutdown()
        self.writer.flush()
        if self._own_writer:
            self.writer.close()
        return TrainResult(actor_state={k: v.detach().clone() for k, v in actor.state_dict().items()},
                           frames=self.frames, wall_time_s=time.time() - self._start, iterations=self.n_iters,
                           episode_seeds=collection.episode_seeds(), last_eval=self.last_eval)


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
    from torchrl.data import LazyTensorStorage, ReplayBuffer, SamplerWithoutReplacement
    from torchrl.objectives import ClipPPOLoss
    from torchrl.objectives.value import GAE

    run = TrainingRun(cfg, writer)  # determinism and threads, run folder, TensorBoard

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

    for it, t in run.iterations("mappo"):
        batch = run.collect(it, collection, gae, optimizer, labels)  # (B, T), advantages set
        label_weight = cfg.label_weight(it, run.n_iters)

        # ---- PPO epochs over minibatches
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
            probe_trust = actor_net.trust(run.probe_x)
        run.log_iteration(stats, actor_net.log_std.item(), probe_trust, optimizer, batch.numel())
        run.evaluate_and_checkpoint(it, actor_net, critic, optimizer, evaluate, MappoPolicy)
    return run.finish(collection, actor_net)
