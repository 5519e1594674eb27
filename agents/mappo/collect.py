"""Collection for MAPPO training: in this process, or on torchrl's process and Ray collectors.

Each task of the mixture has its own collector, cycled per batch (``mappo.py``). Before
every batch of a task, :class:`BatchSchedule` does what keeps batches aligned with the
task's episodes (they all start and end together): the seeds of the next B episodes
when this batch ends one (training seeds drawn from the run seed, checked before use),
a fresh in-loop smoother state when it starts one, a new exploration-noise block.

* ``collectors = 0`` — one torchrl ``Collector`` per task, in this process (the shipped
  runs were trained so);
* ``collectors = N``, ``backend = "process"`` — a ``MultiSyncCollector`` of N worker
  processes per task; ``backend = "ray"`` — a ``RayCollector`` of N Ray actors per task
  (``sync=True``). Worker j steps episodes j·B/N … (j+1)·B/N − 1 of the task's B (the
  seeds the in-process run plays), runs the same schedule on its own copy of the policy
  (:class:`AlignedCollector`) and draws its exploration noise from its own torch
  generator, seeded from (run seed, task, j). The workers' batches are stacked and
  flattened to (B, T); the policy's weights go to the workers before every batch.

The same seed gives the same weights for a fixed ``collectors`` and backend. Different
``collectors`` draw the exploration noise in different processes, so their runs differ.
Each task keeps its N workers for the whole run (tasks × N processes or actors; a
task's workers wait while the others collect), and collection is synchronous: the PPO
update runs while every worker waits, so N workers speed up collection only.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
import torch
from torchrl.collectors import Collector

from swarmloc.envs import torchrl_env
from swarmloc.envs.tasks.seeds import TRAINING_SEED_LIMIT

from swarmloc.agents.mappo.nets import HeldNoise, LoopSmoother


class EpisodeSeeds:
    """Training episode seeds for one task's batched env: deterministic, all < 1_000_000.

    Episodes of a task have a fixed length and all B envs start together, so they end
    together; before each reset the env is told the next B seeds (``set_seed(s)`` plays
    s … s+B−1). ``drawn`` lists every seed handed out (checked by the caller).
    """

    def __init__(self, run_seed: int, task_index: int, batch_size: int) -> None:
        self.rng = np.random.default_rng([run_seed, task_index, 0x5EED])
        self.batch_size = batch_size
        self.drawn: list[int] = []

    def next_base(self) -> int:
        base = int(self.rng.integers(0, TRAINING_SEED_LIMIT - self.batch_size))
        self.drawn.extend(range(base, base + self.batch_size))
        return base


@dataclass(frozen=True)
class TaskPlan:
    """One task's collection, as one collector (or one of its workers) sees it.

    Attributes:
        run_seed: the run's seed.
        task_index: the task's place in the mixture.
        num_envs: B, the task's episodes per batch (all workers together).
        n_steps: episode length, in steps.
        rollout_steps: steps per batch (divides ``n_steps``).
        offset: this worker's first episode among the B (0 in this process).
        threads: numba threads of a worker (torch runs on one thread).
    """

    run_seed: int
    task_index: int
    num_envs: int
    n_steps: int
    rollout_steps: int
    offset: int = 0
    threads: int = 1


class BatchSchedule:
    """What happens before each batch of one task's collector (see the module docstring).

    Args:
        plan: the task's plan.
        check_seeds: called with every B episode seeds before they are used (or None).
    """

    def __init__(self, plan: TaskPlan, check_seeds: Callable[[list[int]], None] | None = None) -> None:
        self.plan = plan
        self.seeds = EpisodeSeeds(plan.run_seed, plan.task_index, plan.num_envs)
        self.check_seeds = check_seeds
        self.steps_done = 0

    def next_seed(self) -> int:
        """The seed to give ``env.set_seed`` for the next episodes (this worker's share)."""
        base = self.seeds.next_base()
        if self.check_seeds is not None:
            self.check_seeds(list(range(base, base + self.plan.num_envs)))
        return base + self.plan.offset

    def before_batch(self, env: Any | None, noise: HeldNoise | None, smoother: LoopSmoother | None) -> None:
        """Seeds when this batch ends an episode, noise block, smoother state (None: only keep count)."""
        p = self.plan
        if (self.steps_done + p.rollout_steps) % p.n_steps == 0:  # the env resets at this batch's end
            seed = self.next_seed()
            if env is not None:
                env.set_seed(seed)
        if noise is not None:
            noise.start_batch()
        if smoother is not None:
            smoother.select(p.task_index, fresh=self.steps_done % p.n_steps == 0)
        self.steps_done += p.rollout_steps


def training_env(task: str, num_envs: int, seed: int, **kwargs: Any) -> Any:
    """The task's batched torchrl env, its first episodes seeded (a picklable env factory for workers)."""
    env = torchrl_env(task, num_envs, **kwargs)
    env.set_seed(seed)
    return env


def _module_of(policy: Any, kind: type) -> Any:
    found = [m for m in policy.modules() if isinstance(m, kind)] if isinstance(policy, torch.nn.Module) else []
    return found[0] if found else None


def worker_torch_seed(run_seed: int, task_index: int, worker: int) -> int:
    """The torch seed of collector worker ``worker`` of task ``task_index`` (its exploration noise)."""
    return int(np.random.default_rng([run_seed, task_index, worker, 0xC011]).integers(0, 2**62))


class AlignedCollector(Collector):
    """A torchrl ``Collector`` that runs its task's :class:`BatchSchedule` before each batch (in a worker).

    Takes ``plans`` (one :class:`TaskPlan` per worker of the task) and picks its own by
    ``worker_idx``, which both ``MultiSyncCollector`` and ``RayCollector`` pass; seeds its
    worker's torch generator (the exploration noise), runs torch on one thread and numba on ``plan.threads``.
    """

    def __init__(self, *args: Any, plans: Sequence[TaskPlan] = (), worker_idx: int | None = None,
                 **kwargs: Any) -> None:
        super().__init__(*args, worker_idx=worker_idx, **kwargs)
        j = worker_idx or 0
        plan = plans[j]
        torch.set_num_threads(1)  # portable bit-identity: see MappoConfig.threads
        numba.set_num_threads(min(plan.threads, numba.config.NUMBA_NUM_THREADS))
        torch.manual_seed(worker_torch_seed(plan.run_seed, plan.task_index, j))
        self.schedule = BatchSchedule(plan)
        self.schedule.next_seed()  # the first seeds went to the env factory
        self._noise = _module_of(self.policy, HeldNoise)
        self._smoother = _module_of(self.policy, LoopSmoother)

    def rollout(self) -> Any:
        self.schedule.before_batch(self.env, self._noise, self._smoother)
        return super().rollout()

    def __repr__(self) -> str:  # Ray prefixes the actor's log lines with it
        plan = self.schedule.plan
        return f"AlignedCollector(task {plan.task_index}, episodes {plan.offset}+)"


class Collection:
    """One collector per task; ``collect(t)`` returns task t's next ``(B, T)`` batch.

    Args:
        tasks: task IDs.
        num_envs, rollout_steps, run_seed: as in ``MappoConfig``.
        policy: the acting policy (its held-noise and smoother modules, if any, are found in it).
        env_kwargs: per task, the env's keyword arguments (reward weights, policy FLOPs).
        collectors: 0 (this process) or N workers per task.
        backend: ``process`` or ``ray`` (N ≥ 1).
        address: Ray cluster to join (``ray``; default ``$RAY_ADDRESS``, else a local one).
        check_seeds: the episode-seed guard.
        threads: numba threads of each worker (torch runs on one thread).
    """

    def __init__(self, tasks: Sequence[str], num_envs: int, rollout_steps: int, run_seed: int, policy: Any,
                 env_kwargs: Sequence[dict], collectors: int = 0, backend: str = "process",
                 address: str | None = None, check_seeds: Callable[[list[int]], None] | None = None,
                 threads: int = 1) -> None:
        from torchrl.envs.utils import ExplorationType

        from swarmloc.envs.tasks.catalogue import get_spec

        if collectors and num_envs % collectors:
            raise ValueError(f"num_envs={num_envs} must be divisible by collectors={collectors}")
        if backend not in ("process", "ray"):
            raise ValueError(f"collector backend must be 'process' or 'ray', got {backend!r}")
        self.num_envs, self.rollout_steps, self.collectors = num_envs, rollout_steps, collectors
        self.noise, self.smoother = _module_of(policy, HeldNoise), _module_of(policy, LoopSmoother)
        common = dict(trust_policy=True, exploration_type=ExplorationType.RANDOM)
        self.schedules: list[BatchSchedule] = []
        self.envs: list[Any] = []
        self._collectors: list[Any] = []
        self._ray_started = False
        for t, task in enumerate(tasks):
            n_steps = get_spec(task).n_steps
            if n_steps % rollout_steps:
                raise ValueError(f"rollout_steps={rollout_steps} must divide the episode length of {task} "
                                 f"({n_steps} steps) so that reset seeds can be set between batches")
            schedule = BatchSchedule(TaskPlan(run_seed, t, num_envs, n_steps, rollout_steps), check_seeds)
            self.schedules.append(schedule)
            first = schedule.next_seed()
            frames = num_envs * rollout_steps
            if not collectors:
                env = training_env(task, num_envs, first, **env_kwargs[t])
                self.envs.append(env)
                self._collectors.append(Collector(env, policy, frames_per_batch=frames, total_frames=-1,
                                                  auto_register_policy_transforms=False, **common))
                continue
            share = num_envs // collectors
            plans = [TaskPlan(run_seed, t, num_envs, n_steps, rollout_steps, j * share, threads)
                     for j in range(collectors)]
            makers = [functools.partial(training_env, task, share, first + j * share, **env_kwargs[t])
                      for j in range(collectors)]
            self._collectors.append(self._workers(makers, policy, frames, plans, len(tasks), backend, address,
                                                  common))
        self._iterators = [iter(c) for c in self._collectors]

    def _workers(self, makers: list, policy: Any, frames: int, plans: list[TaskPlan], n_tasks: int, backend: str,
                 address: str | None, common: dict) -> Any:
        cls = AlignedCollector
        if backend == "process":
            from torchrl.collectors import MultiSyncCollector

            return MultiSyncCollector(makers, policy, frames_per_batch=frames, total_frames=-1,
                                      collector_class=functools.partial(cls, plans=plans), cat_results="stack",
                                      auto_register_policy_transforms=False, **common)
        from torchrl.collectors.distributed import RayCollector

        self._connect_ray(address)
        # a task's actors collect one task at a time: together the tasks reserve N CPUs, not tasks × N
        remote = {"num_cpus": 1.0 / n_tasks}
        kwargs = {"plans": plans, "auto_register_policy_transforms": False}
        # RayCollector stops at total_frames (no "-1: forever"): the training loop decides when to stop
        return RayCollector(makers, policy, frames_per_batch=frames, total_frames=2**62, collector_class=cls,
                            sync=True, num_collectors=len(makers), collector_kwargs=[dict(kwargs) for _ in makers],
                            remote_configs=remote, **common)

    def _connect_ray(self, address: str | None) -> None:
        import ray

        if ray.is_initialized():
            return
        address = address or os.environ.get("RAY_ADDRESS") or None
        if address is not None:
            ray.init(address=address, logging_level="warning")
        else:
            ray.init(address="local", num_cpus=self.collectors, include_dashboard=False, logging_level="warning",
                     object_store_memory=256 * 1024**2)
        self._ray_started = True

    def collect(self, t: int) -> Any:
        """Task t's next batch, ``(B, T)``, collected with the current weights."""
        if not self.collectors:
            self.schedules[t].before_batch(self.envs[t], self.noise, self.smoother)
            return next(self._iterators[t])
        self.schedules[t].before_batch(None, None, None)  # the workers apply it; here: seed checks, count
        self._collectors[t].update_policy_weights_()
        batch = next(self._iterators[t])  # (N, B/N, T)
        return batch.reshape(self.num_envs, -1)

    def n_steps(self, t: int) -> int:
        """Episode length of task t."""
        return self.schedules[t].plan.n_steps

    def episode_seeds(self) -> list[int]:
        """Every episode seed handed out so far."""
        return [s for schedule in self.schedules for s in schedule.seeds.drawn]

    def shutdown(self) -> None:
        """Stop every collector (and a Ray cluster started here)."""
        for c in self._collectors:
            c.shutdown()
        if self._ray_started:
            import ray

            ray.shutdown()


__all__ = ["AlignedCollector", "BatchSchedule", "Collection", "EpisodeSeeds", "TaskPlan", "training_env",
           "worker_torch_seed"]
