"""The configuration of a MAPPO link-trust training run (no torch: the CLI reads it at ``--help``).

The algorithm is in ``swarmloc.agents.mappo.train``; ``swarmloc train mappo`` parses this dataclass.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from swarmloc.envs.world.reward import RewardWeights
from swarmloc.envs.tasks.seeds import TRAINING_SEED_LIMIT

from swarmloc.agents.trust.smoothing import BETA_MAX, SMOOTHING_GAMMA

#: the training mixture (madrl Exp. 1, 2/4/6, 3, 5)
DEFAULT_TASKS: tuple[str, ...] = (
    "NLOS-v0", "NLOSStep-v0", "Scale2-v0", "Scale4-v0", "Scale6-v0", "Scale8-v0",
    "CascadedFault-v0", "CascadedFaultRandom-v0", "Ideal-v0",
)
@dataclass
class MappoConfig:
    """Hyper-parameters of a MAPPO link-trust training run."""

    tasks: tuple[str, ...] = DEFAULT_TASKS
    """training tasks (registered IDs, ``swarmloc/`` prefix optional); one collector each, cycled per batch"""
    frames: int = 1_000_000
    """total environment frames (one frame = one env step of one episode, all its UAVs and channels)"""
    seed: int = 1
    """run seed: torch's generator and the training episode seeds derive from it (must be < 1_000_000)"""
    num_envs: int = 16
    """episodes stepped together per task (the env's batch size B)"""
    rollout_steps: int = 100
    """steps per collector batch; a divisor of every task's episode length keeps seeds aligned"""
    epochs: int = 3
    """PPO epochs over each batch"""
    minibatches: int = 8
    """minibatches per epoch (small minibatches: many optimizer steps per frame, frames are dear)"""
    learning_rate: float = 2e-3
    """Adam learning rate (linearly annealed to 0)"""
    anneal_lr: bool = True
    """linearly anneal the learning rate over the run"""
    gamma: float = 0.95
    """discount per 0.1 s step (horizon ≈ 2 s, the CEKF's error memory)"""
    gae_lambda: float = 0.9
    """GAE λ"""
    clip_epsilon: float = 0.2
    """PPO ratio clip"""
    entropy_coef: float = 1e-3
    """entropy bonus weight"""
    critic_coef: float = 0.5
    """value loss weight"""
    max_grad_norm: float = 0.5
    """gradient clipping (global norm)"""
    reward_scale: float = 0.1
    """rewards are multiplied by this before GAE (returns of order 1 for the critic)"""
    hidden: tuple[int, ...] = (128, 64)
    """actor hidden widths (madrl §2.2.2: 128, 64)"""
    channel_context: bool = True
    """each channel also sees its UAV's mean innovation and NIS (False: the paper's per-channel input only)"""
    critic_hidden: int = 64
    """critic embedding width"""
    privileged_critic: bool = True
    """the critic also sees each UAV's true position error (training only; the actor never does)"""
    init_trust: float = 0.5
    """trust the untrained actor outputs (0.5: the logit's middle, where no side of the jitter-driven pull
    towards saturation at 0 or 1 is favoured before the accuracy term decides)"""
    init_log_std: float = 0.7
    """initial log σ of the Gaussian on the trust logit: σ = 2 spans α ≈ 0.04 … 0.99, because
    isolation only pays off near α → 0 (R = R0/α), far from the initial trust"""
    noise_hold: int = 1
    """steps (0.1 s each) an exploration draw is held (1: a new draw every step; with
    ``train_smoothing`` the smoother low-passes it. Without, 10 moves the filter's error visibly)"""
    train_smoothing: bool = True
    """apply the adaptive Markov smoothing in the training loop, as at execution (madrl Algorithm 1):
    the env gets α_eff, and the per-step exploration noise reaches filter and jitter term low-passed"""
    smoothing: tuple[float, float] = (BETA_MAX, SMOOTHING_GAMMA)
    """(β_max, γ) of the in-loop smoothing (the execution-time values)"""
    accuracy_only: bool = False
    """madrl Exp. 7 ablation: λ = 0 for delay, energy and jitter"""
    eval_every: int = 500_000
    """frames between dev-seed evaluations (needs an evaluator; 0 = only at the end)"""
    checkpoint_every: int = 500_000
    """frames between checkpoints in ``run_dir`` (0 = only at the end)"""
    run_dir: str = "runs/mappo"
    """TensorBoard logs and checkpoints go here"""
    threads: int = 1
    """numba threads of the world's kernels (1: polite on a shared machine). torch always runs on one thread:
    a threaded BLAS (MKL on AVX-512 Intel CPUs) sums a matrix product in an order that depends on the thread
    count, so a threaded update would give other weights for another ``threads``. With torch on one thread,
    the same seed gives the same weights bit for bit for any ``threads``, collector count held fixed, on one
    machine; across CPUs, BLAS picks its kernels by instruction set and the last bits may differ."""
    collectors: int = 0
    """collector workers per task (0: collect in this process; N: N synchronized workers per task, each
    stepping num_envs / N of its episodes, weights sent before every batch; same seed → same weights for a
    fixed N and backend)"""
    backend: Literal["process", "ray"] = "process"
    """where the collector workers run with ``collectors`` ≥ 1: worker processes here (torchrl
    MultiSyncCollector) or Ray actors (torchrl RayCollector)"""
    address: str | None = None
    """Ray cluster to join with ``backend ray`` (``auto`` or HOST:PORT; default: $RAY_ADDRESS, else a local
    cluster of ``collectors`` CPUs)"""
    progress: bool = True
    """show a tqdm progress bar"""
    label_coef: float = 0.0
    """weight of a privileged auxiliary loss: the actor's logit is also fitted (binary cross-entropy) to
    "healthy" = not fault-labelled (error labels of the collected measurements; training only, as the
    privileged critic's position error; needs collectors=0). 0: the paper's MAPPO"""
    label_coef_final: float | None = None
    """the label loss weight at the end of the run, reached linearly from ``label_coef`` (a warm start that
    hands the trust over to the reward: unlabelled links that still cost accuracy can then be down-weighted);
    None: ``label_coef`` throughout"""
    reward_weights: dict = field(default_factory=dict)
    """extra ``RewardWeights`` overrides (advanced; ``accuracy_only`` sets delay/energy/jitter to 0)"""

    def __post_init__(self) -> None:
        if not self.tasks:
            raise ValueError("tasks must name at least one task")
        for name in ("frames", "num_envs", "rollout_steps", "epochs", "minibatches", "threads"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)!r}")
        if self.collectors < 0 or (self.collectors and self.num_envs % self.collectors):
            raise ValueError(f"collectors must be 0 or a divisor of num_envs={self.num_envs}, got {self.collectors!r}")
        if self.backend not in ("process", "ray"):
            raise ValueError(f"backend must be 'process' or 'ray', got {self.backend!r}")
        if self.label_coef < 0 or (self.label_coef > 0 and self.collectors):
            raise ValueError(f"label_coef={self.label_coef} must be >= 0, and 0 with collectors >= 1 (the labels are "
                             "read from the env in this process)")
        if self.label_coef_final is not None and not (0 <= self.label_coef_final and self.label_coef > 0):
            raise ValueError(f"label_coef_final={self.label_coef_final} must be >= 0, and needs label_coef > 0 "
                             f"(got label_coef={self.label_coef})")
        if self.address is not None and (self.backend != "ray" or not self.collectors):
            raise ValueError(f"address={self.address!r} names a Ray cluster; it needs collectors >= 1 and backend ray")
        if not 0 <= self.seed < TRAINING_SEED_LIMIT:
            raise ValueError(f"seed must be a training seed in [0, {TRAINING_SEED_LIMIT}), got {self.seed!r}")
        if self.noise_hold < 1 or self.rollout_steps % self.noise_hold:
            raise ValueError(f"noise_hold={self.noise_hold} must be >= 1 and divide rollout_steps={self.rollout_steps}")
        if (self.num_envs * self.rollout_steps) % self.minibatches:
            raise ValueError(f"num_envs·rollout_steps = {self.num_envs * self.rollout_steps} must be divisible by "
                             f"minibatches = {self.minibatches}")
        beta_max, gamma = self.smoothing
        if not (0.0 <= beta_max < 1.0 and gamma >= 0.0):
            raise ValueError(f"smoothing = (beta_max, gamma) needs beta_max in [0, 1) and gamma >= 0, "
                             f"got {self.smoothing!r}")
        if not (0.0 < self.gamma <= 1.0 and 0.0 <= self.gae_lambda <= 1.0):
            raise ValueError(f"gamma must be in (0, 1] and gae_lambda in [0, 1], got {self.gamma}, {self.gae_lambda}")

    @property
    def frames_per_batch(self) -> int:
        """Frames per collector batch (B · rollout_steps)."""
        return self.num_envs * self.rollout_steps

    def label_weight(self, iteration: int, n_iterations: int) -> float:
        """The label loss weight at ``iteration`` of ``n_iterations`` (linear from ``label_coef`` to
        ``label_coef_final``, as the learning rate anneals)."""
        if self.label_coef_final is None:
            return self.label_coef
        return self.label_coef + (self.label_coef_final - self.label_coef) * iteration / n_iterations

    def weights(self) -> RewardWeights:
        """The reward weights of this run (standard v0 unless ``accuracy_only`` / overrides)."""
        extra = dict(self.reward_weights)
        if self.accuracy_only:
            extra.update(delay=0.0, energy=0.0, jitter=0.0)
        return RewardWeights(**extra)


#: the v1 randomized families (their in-distribution tasks; training seeds only)
V1_RANDOM_TASKS: tuple[str, ...] = (
    "NLOSRandom-v1", "ScaleRandom-v1", "CascadedFaultRandom-v1", "HybridNoiseRandom-v1", "GradualFaultRandom-v1",
    "VisionLossRandom-v1",
)


@dataclass
class SetGruConfig(MappoConfig):
    """Hyper-parameters of a ``mappo-set-gru`` run (``MappoConfig``'s, with these changes)."""

    tasks: tuple[str, ...] = V1_RANDOM_TASKS
    """training tasks (registered IDs); one collector each, cycled per batch"""
    frames: int = 3_000_000
    """total environment frames"""
    minibatches: int = 4
    """minibatches per epoch, each ``num_envs / minibatches`` whole rollouts (sequences)"""
    learning_rate: float = 1e-3
    """Adam learning rate (linearly annealed to 0)"""
    embed: int = 64
    """E, the channel embedding width"""
    gru_hidden: int = 64
    """H, the per-channel GRU state width"""
    label_coef: float = 1.0
    """weight of the privileged auxiliary loss (see ``MappoConfig.label_coef``)"""

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.num_envs % self.minibatches:
            raise ValueError(f"num_envs={self.num_envs} must be divisible by minibatches={self.minibatches} "
                             "(a minibatch is whole rollouts)")
        if self.collectors:
            raise ValueError(f"collectors={self.collectors}: the recurrent actor's state lives in this process; "
                             "use collectors=0")
        if self.embed < 1 or self.gru_hidden < 1:
            raise ValueError(f"embed and gru_hidden must be >= 1, got {self.embed}, {self.gru_hidden}")
