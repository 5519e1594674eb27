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

from swarmloc.envs.world.kernel_cache import guard_kernel_cache

guard_kernel_cache()  # before any numba kernel loads from its disk cache (see kernel_cache)

from swarmloc.envs.adapters.registration import register_tasks  # noqa: E402
from swarmloc.envs.tasks.catalogue import CATALOGUE, UnknownTaskError, canonical_task_id, get_spec  # noqa: E402

TASK_IDS: tuple[str, ...] = tuple(register_tasks())

__all__ = ["CATALOGUE", "TASK_IDS", "UnknownTaskError", "canonical_task_id", "env", "get_spec", "make", "make_vec",
           "parallel_env", "torchrl_env"]


def make(task_id: str, **kwargs: Any):
    """``gymnasium.make`` of a swarmloc task (with its TimeLimit and checker wrappers)."""
    import gymnasium as gym

    return gym.make(canonical_task_id(task_id), **kwargs)


def make_vec(task_id: str, num_envs: int, **kwargs: Any):
    """Batched Gymnasium vector env of a swarmloc task (``SwarmLocVectorEnv``)."""
    import gymnasium as gym

    return gym.make_vec(canonical_task_id(task_id), num_envs=num_envs, **kwargs)


def parallel_env(task_id: str, **kwargs: Any):
    """PettingZoo ``ParallelEnv`` of a swarmloc task, one agent per UAV."""
    from swarmloc.envs.adapters.pettingzoo_env import parallel_env as _parallel_env

    return _parallel_env(canonical_task_id(task_id), **kwargs)


def env(task_id: str, **kwargs: Any):
    """PettingZoo ``AECEnv`` of a swarmloc task (``parallel_to_aec`` of ``parallel_env``)."""
    from swarmloc.envs.adapters.pettingzoo_env import env as _env

    return _env(canonical_task_id(task_id), **kwargs)


def torchrl_env(task_id: str, batch_size: int, device: str = "cpu", **kwargs: Any):
    """Native batched torchrl ``EnvBase`` of a swarmloc task (group ``uav``)."""
    try:
        from swarmloc.envs.adapters.torchrl_env import make_torchrl_env
    except ModuleNotFoundError as err:
        if (err.name or "").split(".")[0] not in ("torch", "tensordict", "torchrl"):
            raise
        raise ModuleNotFoundError(f"the torchrl env needs the 'torchrl' extra: pip install 'swarmloc[torchrl]' ({err})",
                                  name=err.name) from err

    return make_torchrl_env(canonical_task_id(task_id), batch_size, device, **kwargs)
