"""MAPPO for the set + GRU link-trust actor (``mappo-set-gru``), CleanRL style: one file, one loop.

What differs from ``swarmloc.agents.mappo.train`` (the paper's per-channel MLP) is the actor and,
because the actor is recurrent, how the PPO update replays it:

* **Actor** (``SetGruActor``, ``set_gru_policy.py``): DeepSets over the UAV's channels and
  a GRU memory per channel. While collecting, ``RecurrentParams`` steps it once per env
  step and keeps the hidden states per task (tasks interleave batch by batch); a batch
  that starts an episode starts from h = 0.
* **Recurrent PPO update** (as CleanRL's ``ppo_atari_lstm``): the hidden state at the start
  of each batch is kept; minibatches are whole episodes' rollouts (``B / minibatches``
  envs × T steps), and the actor is replayed over the T steps from that state, so the
  log-probabilities are the collected ones at the first epoch (ratio 1) and the gradient
  flows through time (truncated BPTT over T = ``rollout_steps``).
* **Loss**: the clipped PPO surrogate per channel with its UAV's advantage (GAE on the
  per-UAV standard reward), the entropy bonus, the value loss of the centralized critic,
  and a **privileged auxiliary loss** (``label_coef``): the binary cross-entropy of the
  actor's logit against "healthy", i.e. not fault-labelled (error labels of the collected
  measurements, read from the env in this process). Like the critic's position error, the
  labels exist only while training; the actor never sees them. Without it (``label_coef
  0``) both this actor and the paper's collapse to α ≈ 1 on the v1 families within 0.4–0.8 M
  frames: isolating a link pays off only near α → 0, far from where exploration starts,
  while "trust more" pays at once from α = 0.5.

Everything else is ``mappo``'s: the training mixture (here the v1 randomized families'
training seeds), the centralized privileged critic (``SwarmCritic``), held exploration
noise on the logit, the adaptive Markov smoothing in the loop and at execution,
TensorBoard keys, seeds checked by the bench glue (``swarmloc train mappo-set-gru``).
Collection runs in this process (the hidden state lives here).

Run: ``swarmloc train mappo-set-gru --frames 3000000``.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import nn

from swarmloc.envs.world.observation import N_FEATURES, VALID
from swarmloc.envs.tasks.catalogue import get_spec

from swarmloc.agents.mappo.train import TrainingRun, TrainResult, label_loss
from swarmloc.agents.mappo.collect import Collection
from swarmloc.agents.mappo.config import V1_RANDOM_TASKS, SetGruConfig  # noqa: F401  (re-exported)
from swarmloc.agents.mappo.nets import G, MaskedNormal, PendingLabels, SwarmCritic, acting_modules
from swarmloc.agents.mappo.set_gru_policy import SetGruActor, SetGruPolicy, count_flops_per_channel
from swarmloc.agents.trust.smoothing import SMOOTHING_FLOPS_PER_CHANNEL


class RecurrentParams(nn.Module):
    """``SetGruActor`` one env step at a time for the collectors: (μ, σ, valid), state kept per task.

    ``select(task, fresh)`` before each batch picks the task's hidden state (``fresh``: a
    batch that starts an episode, h = 0) and records it as ``h0``, the state the update
    replays the batch from.
    """

    def __init__(self, actor: SetGruActor) -> None:
        super().__init__()
        self.actor = actor
        self._states: dict[int, torch.Tensor] = {}
        self._key = 0
        self.h0: torch.Tensor | None = None

    def select(self, key: int, fresh: bool) -> None:
        self._key = key
        if fresh:
            self._states.pop(key, None)
        self.h0 = self._states.get(key)

    def forward(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        h = self._states.get(self._key)
        if h is None or h.shape[:-1] != obs.shape[:-1]:
            h = self.actor.initial_state(tuple(obs.shape[:-1]))
            if self.h0 is None or self.h0.shape != h.shape:
                self.h0 = h
        with torch.no_grad():
            loc, h = self.actor.step(obs, h)
        self._states[self._key] = h
        return loc, self.actor.log_std.exp().detach().expand_as(loc), obs[..., VALID] > 0.5


def build_policy(actor: SetGruActor, cfg: SetGruConfig,
                 labels: PendingLabels | None = None) -> tuple[nn.Module, RecurrentParams]:
    """The acting policy (recurrent μ, then ``acting_modules``: held noise, sample, sigmoid, in-loop
    smoother) and its recurrent module; with ``labels``, it also records the pending fault labels."""
    from tensordict.nn import TensorDictModule, TensorDictSequential

    recurrent = RecurrentParams(actor)
    params = TensorDictModule(recurrent, in_keys=[(G, "observation")], out_keys=[(G, "loc"), (G, "scale"), (G, "valid")])
    return TensorDictSequential(params, *acting_modules(cfg, labels)), recurrent


def train(cfg: SetGruConfig, evaluate: Callable[[SetGruPolicy], dict[str, float]] | None = None,
          check_seeds: Callable[[list[int]], None] | None = None, writer=None) -> TrainResult:
    """Train the set + GRU link-trust actor and the centralized critic with recurrent MAPPO.

    Args:
        cfg: the run's configuration.
        evaluate: optional dev-seed evaluator, called with a deterministic, unsmoothed
            ``SetGruPolicy`` snapshot every ``cfg.eval_every`` frames and at the end.
        check_seeds: optional guard called with every episode seed before it is used.
        writer: optional TensorBoard ``SummaryWriter`` (default: one in ``cfg.run_dir``).

    Returns:
        ``TrainResult`` with the actor's state_dict.
    """
    from tensordict.nn import TensorDictModule
    from torchrl.objectives.value import GAE

    run = TrainingRun(cfg, writer)  # determinism and threads, run folder, TensorBoard
    # backpropagating through T GRU steps from a near-zero last layer makes denormal floats,
    # 50-70x slower on CPU; flushed to 0 they change nothing measurable
    torch.set_flush_denormal(True)

    # ---- actor, acting policy, critic
    actor = SetGruActor(N_FEATURES, cfg.embed, cfg.gru_hidden, cfg.init_trust, cfg.init_log_std)
    envs: list = []  # filled below, once the collectors have built their envs
    labels = PendingLabels(envs) if cfg.label_coef > 0 else None
    policy, recurrent = build_policy(actor, cfg, labels)
    critic_in = [(G, "observation"), "state"] + ([(G, "info", "position_error")] if cfg.privileged_critic else [])
    critic = TensorDictModule(SwarmCritic(N_FEATURES, cfg.critic_hidden, cfg.privileged_critic), in_keys=critic_in,
                              out_keys=[(G, "state_value")])
    flops_per_channel = count_flops_per_channel(actor) + SMOOTHING_FLOPS_PER_CHANNEL

    # ---- one batched env + collector per task, in this process; training seeds only
    env_kwargs = [{"reward_weights": cfg.weights(), "policy_flops": flops_per_channel * get_spec(task).n_channels}
                  for task in cfg.tasks]
    collection = Collection(cfg.tasks, cfg.num_envs, cfg.rollout_steps, cfg.seed, policy, env_kwargs,
                            check_seeds=check_seeds, threads=cfg.threads)
    envs.extend(collection.envs)

    gae = GAE(gamma=cfg.gamma, lmbda=cfg.gae_lambda, value_network=critic, average_gae=False)
    gae.set_keys(value=(G, "state_value"), reward=(G, "reward"), done=(G, "done"), terminated=(G, "terminated"),
                 advantage=(G, "advantage"), value_target=(G, "value_target"))
    optimizer = torch.optim.Adam([*actor.parameters(), *critic.parameters()], lr=cfg.learning_rate)

    for it, t in run.iterations("mappo-set-gru"):
        schedule = collection.schedules[t]
        recurrent.select(t, fresh=schedule.steps_done % schedule.plan.n_steps == 0)
        batch = run.collect(it, collection, gae, optimizer, labels)  # (B, T), advantages set
        h0 = recurrent.h0  # (B, N, L, H): the state the batch was collected from
        label_weight = cfg.label_weight(it, run.n_iters)

        # ---- recurrent PPO: minibatches of whole rollouts, the actor replayed from h0
        stats: dict[str, list[float]] = {}
        per_mb = cfg.num_envs // cfg.minibatches
        for epoch in range(cfg.epochs):
            order = torch.randperm(cfg.num_envs)
            for j in range(cfg.minibatches):
                idx = order[j * per_mb:(j + 1) * per_mb]
                mb = batch[idx]  # (b, T)
                obs = mb[G, "observation"]
                loc = actor.sequence(obs, h0[idx])  # (b, T, N, L)
                valid = obs[..., VALID] > 0.5
                dist = MaskedNormal(loc, actor.log_std.exp().expand_as(loc), valid)
                log_ratio = dist.log_prob(mb[G, "trust_logit"]) - mb[G, "trust_logit_log_prob"]
                ratio = log_ratio.exp()
                a = mb[G, "advantage"]  # (b, T, N, 1): the UAV's advantage for each of its channels
                surrogate = torch.minimum(ratio * a, ratio.clamp(1.0 - cfg.clip_epsilon, 1.0 + cfg.clip_epsilon) * a)
                n_valid = valid.sum().clamp(min=1)
                loss_objective = -(surrogate * valid).sum() / n_valid
                entropy = (dist.entropy() * valid).sum() / n_valid
                value = critic(mb.select(*critic.in_keys).clone())[G, "state_value"]
                loss_critic = (value - mb[G, "value_target"]).pow(2).mean()
                total = loss_objective + cfg.critic_coef * loss_critic - cfg.entropy_coef * entropy
                if labels is not None:
                    # privileged auxiliary loss: logit → "healthy" (not fault-labelled), present channels only
                    loss_label = label_loss(loc, mb[G, "fault_label"], valid)
                    total = total + label_weight * loss_label
                    stats.setdefault("label_bce", []).append(float(loss_label.detach()))
                optimizer.zero_grad()
                total.backward()
                torch.nn.utils.clip_grad_norm_([*actor.parameters(), *critic.parameters()], cfg.max_grad_norm)
                optimizer.step()
                with torch.no_grad():
                    lr_ = log_ratio[valid]
                    stats.setdefault("objective", []).append(float(loss_objective))
                    stats.setdefault("critic", []).append(float(loss_critic))
                    stats.setdefault("entropy", []).append(float(entropy))
                    stats.setdefault("kl_approx", []).append(float(((lr_.exp() - 1) - lr_).mean()))
                    stats.setdefault("clip_fraction", []).append(
                        float(((ratio[valid] - 1.0).abs() > cfg.clip_epsilon).float().mean()))
                    if epoch == 0 and j == 0:
                        # the replay reproduces the collected log-probabilities (before any step of this batch)
                        stats["replay_log_ratio_max"] = [float(lr_.abs().max())]
        with torch.no_grad():
            probe_mu, _ = actor.step(run.probe_x, actor.initial_state((run.probe_x.shape[0],)))
        run.log_iteration(stats, actor.log_std.item(), torch.sigmoid(probe_mu), optimizer, batch.numel())
        run.evaluate_and_checkpoint(it, actor, critic, optimizer, evaluate, SetGruPolicy)
    return run.finish(collection, actor)
