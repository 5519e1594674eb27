"""Gymnasium vector env: equals the single envs seed for seed, next-step autoreset, determinism."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import swarmloc.envs  # noqa: F401
from swarmloc.envs.tasks.catalogue import CATALOGUE
from swarmloc.envs.adapters.vector_env import SwarmLocVectorEnv

from envs_helpers import short, skip_without_data

TASKS = sorted(CATALOGUE)


def vector_rollout(env: gym.vector.VectorEnv, seed: int, actions: np.ndarray) -> list[tuple]:
    out = [env.reset(seed=seed)]
    for action in actions:
        out.append(env.step(action))
    return out


def single_rollout(task_id: str, seed: int, actions: np.ndarray, **kwargs) -> list[tuple]:
    """What next-step autoreset should reproduce: a single env reset() after each truncation."""
    env = gym.make(task_id, **kwargs)
    obs, _ = env.reset(seed=seed)
    out, done = [obs], False
    for action in actions:
        if done:
            obs, _ = env.reset()
            out.append((obs, 0.0, False, None))
            done = False
            continue
        obs, reward, _, truncated, info = env.step(action)
        out.append((obs, reward, truncated, info))
        done = truncated
    return out


@pytest.mark.parametrize("task_id", TASKS)
def test_vector_env_equals_single_envs_across_autoresets(task_id):
    skip_without_data(task_id)
    n_b, kwargs = 3, short(task_id, 12)
    actions = np.random.default_rng(1).uniform(0, 1.2, (40, n_b, *gym.make(task_id).action_space.shape))
    vec = gym.make_vec(task_id, num_envs=n_b, **kwargs)
    assert isinstance(vec, SwarmLocVectorEnv)
    with pytest.warns(RuntimeWarning, match="clipped"):
        got = vector_rollout(vec, 100, actions.astype(np.float32))
    for b in range(n_b):
        with pytest.warns(RuntimeWarning, match="clipped"):
            want = single_rollout(task_id, 100 + b, actions[:, b].astype(np.float32), **kwargs)
        np.testing.assert_array_equal(got[0][0][b], want[0])
        for k in range(1, len(want)):
            obs, reward, terminated, truncated, info = got[k]
            w_obs, w_reward, w_trunc, w_info = want[k]
            np.testing.assert_array_equal(obs[b], w_obs)
            assert reward[b] == w_reward and not terminated[b]
            if w_info is None:  # the autoreset step
                assert not truncated[b] and not info.get("_accuracy", np.zeros(n_b, bool))[b]
            else:
                assert truncated[b] == w_trunc and info["_accuracy"][b]
                for key, value in w_info.items():
                    np.testing.assert_array_equal(info[key][b], value)


def test_vector_metadata_spaces_and_determinism():
    vec = gym.make_vec("swarmloc/CascadedFault-v0", num_envs=4)
    assert vec.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
    assert vec.num_envs == 4 and vec.single_action_space.shape == (4, 6)
    assert vec.observation_space.shape == (4, 4, 6, 11) and vec.action_space.shape == (4, 4, 6)
    vec.action_space.seed(3)
    actions = np.stack([vec.action_space.sample() for _ in range(200)])
    first = vector_rollout(vec, 5, actions)
    second = vector_rollout(gym.make_vec("swarmloc/CascadedFault-v0", num_envs=4), 5, actions)
    for a, b in zip(first, second):
        for x, y in zip(a, b):
            if isinstance(x, dict):
                assert x.keys() == y.keys()
                for key in x:
                    np.testing.assert_array_equal(x[key], y[key])
            else:
                np.testing.assert_array_equal(x, y)


def test_vector_returns_new_arrays_unless_copy_false():
    vec = gym.make_vec("swarmloc/Ideal-v0", num_envs=2, duration=1.0)
    obs0, _ = vec.reset(seed=0)
    obs1, *_ = vec.step(np.ones((2, 4, 9), np.float32))
    assert not np.shares_memory(obs0, obs1)
    fast = SwarmLocVectorEnv("swarmloc/Ideal-v0", 2, duration=1.0, copy=False)
    a, _ = fast.reset(seed=0)
    b, *_ = fast.step(np.ones((2, 4, 9), np.float32))
    assert a is b


def test_vector_truncates_at_max_episode_steps_and_reset_mask():
    vec = SwarmLocVectorEnv("swarmloc/NLOS-v0", 3, max_episode_steps=4)
    vec.reset(seed=[1, 2, 3])
    act = np.ones((3, 4, 11), np.float32)
    for _ in range(3):
        assert not vec.step(act)[3].any()
    assert vec.step(act)[3].all()
    vec.reset(seed=[7, None, None], options={"reset_mask": np.array([True, False, False])})
    assert vec.batch.core.world.seeds[0] == 7
    assert vec.batch.core._out.steps.tolist() == [0, 4, 4]
    vec.reset(seed=50, options={"reset_mask": np.array([False, True, False])})
    assert vec.batch.core.world.seeds[1] == 51
    for _ in range(5):  # env 1 truncates one step after envs 0 and 2; each autoresets
        vec.step(act)
    seeds = vec.batch.core.world.seeds
    assert seeds[0] not in (7, 50) and seeds[2] not in (3, 52)  # drawn from their own generators
    with pytest.raises(ValueError, match="reset_mask"):
        vec.reset(options={"reset_mask": np.array([1, 0, 0])})


def test_vector_bad_actions():
    vec = gym.make_vec("swarmloc/NLOS-v0", num_envs=2, duration=1.0)
    vec.reset(seed=0)
    with pytest.raises(ValueError, match=r"\(B, N, L\) = \(2, 4, 11\)"):
        vec.step(np.ones((4, 11)))
    bad = np.ones((2, 4, 11))
    bad[1, 0, 0] = -np.inf
    with pytest.raises(ValueError, match="finite"):
        vec.step(bad)


def test_batched_vector_env_equals_gymnasium_sync_vector_env():
    """Gymnasium's own SyncVectorEnv (next-step autoreset) over the single envs is the reference."""
    sync = gym.make_vec("swarmloc/HybridNoise10-v0", num_envs=3, vectorization_mode="sync", duration=1.0)
    batched = gym.make_vec("swarmloc/HybridNoise10-v0", num_envs=3, duration=1.0)
    assert sync.metadata["autoreset_mode"] is batched.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
    actions = np.random.default_rng(2).uniform(0, 1, (25, 3, 9, 9)).astype(np.float32)
    np.testing.assert_array_equal(sync.reset(seed=4)[0], batched.reset(seed=4)[0])
    for action in actions:
        r1, r2 = sync.step(action), batched.step(action)
        for k in range(4):
            np.testing.assert_array_equal(r1[k], r2[k])
        for key in ("accuracy", "position_error", "_accuracy"):
            if key in r1[4] or key in r2[4]:
                np.testing.assert_array_equal(r1[4][key], r2[4][key])
