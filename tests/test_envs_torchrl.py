"""torchrl native batched env: specs, partial reset, seeding equal to the Gymnasium vector env."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch
from torchrl.envs.utils import check_env_specs

import swarmloc.envs
from swarmloc.envs.tasks.catalogue import CATALOGUE
from swarmloc.envs.adapters.torchrl_env import SwarmLocTorchRLEnv

from envs_helpers import short, skip_without_data

TASKS = sorted(CATALOGUE)


@pytest.mark.parametrize("task_id", TASKS)
def test_check_env_specs(task_id):
    skip_without_data(task_id)
    env = swarmloc.envs.torchrl_env(task_id, 3, **short(task_id, 2))
    check_env_specs(env, seed=0, break_when_any_done="both")


def test_keys_shapes_and_dtypes():
    env = swarmloc.envs.torchrl_env("swarmloc/NLOS-v0", 5, duration=1.0)
    assert isinstance(env, SwarmLocTorchRLEnv) and env.batch_size == torch.Size([5])
    td = env.rand_step(env.reset())
    assert td["uav", "observation"].shape == (5, 4, 11, 11) and td["uav", "observation"].dtype == torch.float32
    assert td["uav", "action"].shape == (5, 4, 11)
    nxt = td["next"]
    assert nxt["uav", "reward"].shape == (5, 4, 1) and nxt["uav", "reward"].dtype == torch.float32
    assert nxt["state"].shape == (5, env.batch.state_size)
    for key in ("done", "terminated", "truncated"):
        assert nxt[key].shape == (5, 1) and nxt[key].dtype == torch.bool
    assert nxt["uav", "info", "position_error"].shape == (5, 4, 1)
    spec = env.full_action_spec["uav", "action"]
    assert float(spec.space.low.min()) == 0.0 and float(spec.space.high.max()) == 1.0


def test_seeded_torchrl_equals_vector_env():
    n_b, steps = 3, 15
    env = swarmloc.envs.torchrl_env("swarmloc/CascadedFault-v0", n_b, duration=1.0)
    vec = gym.make_vec("swarmloc/CascadedFault-v0", num_envs=n_b, duration=1.0)
    actions = torch.rand((steps, n_b, 4, 6), generator=torch.Generator().manual_seed(0))
    env.set_seed(21)
    td = env.reset()
    obs, _ = vec.reset(seed=21)
    np.testing.assert_array_equal(td["uav", "observation"].numpy(), obs)
    for k in range(steps):
        td.set(("uav", "action"), actions[k])
        td, nxt = env.step_and_maybe_reset(td)
        obs, reward, _, truncated, info = vec.step(actions[k].numpy())
        if k < 9:  # before the first autoreset the step outputs line up one to one
            np.testing.assert_array_equal(td["next", "uav", "observation"].numpy(), obs)
            np.testing.assert_allclose(td["next", "uav", "reward"].numpy()[..., 0].mean(1), reward, rtol=1e-6)
            np.testing.assert_array_equal(td["next", "truncated"].numpy()[:, 0], truncated)
        td = nxt
    assert env.batch.core.world.seeds.tolist() == vec.unwrapped.batch.core.world.seeds.tolist()


def test_partial_reset_restarts_only_the_masked_envs():
    n_b = 4
    env = swarmloc.envs.torchrl_env("swarmloc/NLOS-v0", n_b, duration=2.0)
    ref = swarmloc.envs.torchrl_env("swarmloc/NLOS-v0", n_b, duration=2.0)
    env.set_seed(3)
    ref.set_seed(3)
    td, td_ref = env.reset(), ref.reset()
    action = torch.full((n_b, 4, 11), 0.7)
    for _ in range(5):
        td = env.step(td.set(("uav", "action"), action))["next"].clone()
        td_ref = ref.step(td_ref.set(("uav", "action"), action))["next"].clone()
    mask = torch.tensor([[True], [False], [True], [False]])
    before = td["uav", "observation"].clone()
    td.set("_reset", mask)
    td = env.reset(td)
    steps = env.batch.core._out.steps
    assert steps.tolist() == [0, 5, 0, 5]
    np.testing.assert_array_equal(td["uav", "observation"][1].numpy(), before[1].numpy())
    assert not torch.equal(td["uav", "observation"][0], before[0])
    # the envs that were not reset go on exactly as in an untouched env
    for _ in range(3):
        td = env.step(td.set(("uav", "action"), action))["next"].clone()
        td_ref = ref.step(td_ref.set(("uav", "action"), action))["next"].clone()
    for b in (1, 3):
        np.testing.assert_array_equal(td["uav", "observation"][b].numpy(), td_ref["uav", "observation"][b].numpy())
        np.testing.assert_array_equal(td["uav", "reward"][b].numpy(), td_ref["uav", "reward"][b].numpy())


def test_rollout_outputs_are_not_aliased():
    env = swarmloc.envs.torchrl_env("swarmloc/Ideal-v0", 2, duration=1.0)
    roll = env.rollout(4)
    obs = roll["next", "uav", "observation"]
    assert not torch.equal(obs[:, 0], obs[:, 3])


def test_bad_action_and_batch_size():
    env = swarmloc.envs.torchrl_env("swarmloc/NLOS-v0", 2, duration=1.0)
    td = env.reset()
    bad = torch.ones(2, 4, 11)
    bad[0, 1, 2] = float("nan")
    with pytest.raises(ValueError, match="finite"):
        env.step(td.set(("uav", "action"), bad))
    with pytest.raises(ValueError, match="batch_size"):
        swarmloc.envs.torchrl_env("swarmloc/NLOS-v0", 0)
