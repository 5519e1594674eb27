"""swarmloc.envs: the world, the CEKF backbone and the environment APIs.

Importing this package registers every task with Gymnasium (cheaply: no numba compile,
no torch import), so ``gym.make("swarmloc/NLOS-v0")`` and ``gym.make_vec(...)`` work.
The factories below import their API lazily:

- ``parallel_env(task_id, **kwargs)`` / ``env(task_id, **kwargs)``: PettingZoo Parallel / AEC;
- ``torchrl_env(task_id, batch_size, device="cpu", **kwargs)``: native batched torchrl env;
- ``make(task_id, **kwargs)`` / ``make_vec(task_id, num_envs, **kwargs)``: Gymnasium.
"""

from __future__ import annotations

from typing import Any

from .registration import register_tasks
from .tasks import CATALOGUE, get_spec

TASK_IDS: tuple[str, ...] = tuple(register_tasks())

__all__ = ["CATALOGUE", "TASK_IDS", "env", "get_spec", "make", "make_vec", "parallel_env", "torchrl_env"]


def _known(task_id: str) -> str:
    """Canonical ID of ``task_id`` (``swarmloc/`` prefix optional); unknown IDs list the known ones."""
    key = task_id if task_id.startswith("swarmloc/") else f"swarmloc/{task_id}"
    if key not in CATALOGUE:
        raise ValueError(f"unknown task ID {task_id!r}; known: {', '.join(TASK_IDS)}")
    return key


def make(task_id: str, **kwargs: Any):
    """``gymnasium.make`` of a swarmloc task (with its TimeLimit and checker wrappers)."""
    import gymnasium as gym

    return gym.make(_known(task_id), **kwargs)


def make_vec(task_id: str, num_envs: int, **kwargs: Any):
    """Batched Gymnasium vector env of a swarmloc task (``SwarmLocVectorEnv``)."""
    import gymnasium as gym

    return gym.make_vec(_known(task_id), num_envs=num_envs, **kwargs)


def parallel_env(task_id: str, **kwargs: Any):
    """PettingZoo ``ParallelEnv`` of a swarmloc task, one agent per UAV."""
    from .pettingzoo_env import parallel_env as _parallel_env

    return _parallel_env(_known(task_id), **kwargs)


def env(task_id: str, **kwargs: Any):
    """PettingZoo ``AECEnv`` of a swarmloc task (``parallel_to_aec`` of ``parallel_env``)."""
    from .pettingzoo_env import env as _env

    return _env(_known(task_id), **kwargs)


def torchrl_env(task_id: str, batch_size: int, device: str = "cpu", **kwargs: Any):
    """Native batched torchrl ``EnvBase`` of a swarmloc task (group ``uav``)."""
    from .torchrl_env import make_torchrl_env

    return make_torchrl_env(_known(task_id), batch_size, device, **kwargs)
