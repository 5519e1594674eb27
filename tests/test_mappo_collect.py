"""Distributed MAPPO collection: workers collect with the current weights; same seed → same weights.

``collectors = 2`` on torchrl's ``MultiSyncCollector`` (processes) and ``RayCollector``
(actors on one local 2-CPU Ray cluster for the module), a few hundred frames each.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import ray
import torch

from swarmloc.agents.mappo.train import MappoConfig, train
from swarmloc.agents.mappo.collect import Collection
from swarmloc.agents.mappo.nets import G, build_modules


@pytest.fixture(scope="module")
def ray_cluster():
    """A real local Ray cluster of 2 CPUs for the module (Ray ≥ 2.54 has no local_mode)."""
    ray.init(address="local", num_cpus=2, include_dashboard=False, logging_level="warning",
             object_store_memory=128 * 1024**2)
    yield
    ray.shutdown()


def _config(tmp_path: Path, **kw) -> MappoConfig:
    base = dict(tasks=("CascadedFault-v0",), frames=800, num_envs=4, rollout_steps=100, epochs=1, minibatches=2,
                run_dir=str(tmp_path), progress=False, eval_every=0, checkpoint_every=0, seed=5)
    return MappoConfig(**(base | kw))


@pytest.mark.parametrize("backend", ["process", "ray"])
def test_training_with_two_collectors_is_deterministic(backend: str, tmp_path: Path, request) -> None:
    if backend == "ray":
        request.getfixturevalue("ray_cluster")
    a, b = (train(_config(tmp_path / str(i), collectors=2, backend=backend)) for i in range(2))
    assert a.frames == 800 and a.actor_state.keys() == b.actor_state.keys()
    assert all(torch.equal(a.actor_state[k], b.actor_state[k]) for k in a.actor_state)
    # the workers play the very episodes an in-process run plays
    assert a.episode_seeds == train(_config(tmp_path / "here", frames=400)).episode_seeds[:len(a.episode_seeds)]


@pytest.mark.parametrize("backend", ["process", "ray"])
def test_workers_collect_with_the_weights_of_the_moment(backend: str, tmp_path: Path, request) -> None:
    if backend == "ray":
        request.getfixturevalue("ray_cluster")
    cfg = _config(tmp_path)
    actor, _, policy, _, _, _ = build_modules(cfg)
    collection = Collection(cfg.tasks, cfg.num_envs, cfg.rollout_steps, cfg.seed, policy, [{}], collectors=2,
                            backend=backend)
    try:
        first = collection.collect(0)
        assert first.batch_size == torch.Size([cfg.num_envs, cfg.rollout_steps])
        with torch.no_grad():
            for p in actor.parameters():
                p.add_(0.05)
        second = collection.collect(0)
    finally:
        collection.shutdown()
    with torch.no_grad():  # the actor as it is now, and as the workers used it for each batch
        now_on_second, now_on_first = actor(second[G, "observation"]), actor(first[G, "observation"])
    assert torch.allclose(second[G, "loc"], now_on_second, atol=1e-5)
    assert not torch.allclose(first[G, "loc"], now_on_first, atol=1e-5)  # the first batch had the old weights
