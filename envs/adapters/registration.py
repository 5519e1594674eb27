"""Declarative Gymnasium registration of every task in the catalogue.

Each task ID gets a string entry point to its documented class in ``task_envs``, the
batched ``vector_entry_point``, ``max_episode_steps = spec.n_steps`` and the default
kwargs ``{"task_id": ...}`` (the vector entry point is shared and needs to know which
task). Registration imports only the catalogue (pydantic specs): no numba, no torch.
"""

from __future__ import annotations

import gymnasium as gym

from swarmloc.envs.tasks.catalogue import CATALOGUE

VECTOR_ENTRY_POINT = "swarmloc.envs.adapters.vector_env:SwarmLocVectorEnv"


def class_name(task_id: str) -> str:
    """The task's class in ``task_envs``: ``"swarmloc/NLOS-v0"`` → ``"NLOSEnv"``, ``"swarmloc/NLOS-v1"`` → ``"NLOSV1Env"``.

    Versions after v0 carry their number, so two versions of one task never share a class
    (or a docs page).
    """
    name, version = task_id.removeprefix("swarmloc/").rsplit("-v", 1)
    return f"{name}Env" if version == "0" else f"{name}V{version}Env"


def entry_point(task_id: str) -> str:
    """String entry point of ``task_id``'s Gymnasium class."""
    return f"swarmloc.envs.adapters.task_envs:{class_name(task_id)}"


def register_tasks() -> list[str]:
    """Register every catalogue task not registered yet; returns the registered IDs."""
    for task_id, factory in CATALOGUE.items():
        if task_id in gym.registry:
            continue
        gym.register(id=task_id, entry_point=entry_point(task_id), vector_entry_point=VECTOR_ENTRY_POINT,
                     max_episode_steps=factory().n_steps, kwargs={"task_id": task_id})
    return list(CATALOGUE)
