"""Gymnasium single env over every registered task: checker, determinism, actions, render, kwargs."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import swarmloc.envs  # noqa: F401  (registers the tasks)
from swarmloc.envs.tasks.catalogue import CATALOGUE, get_spec

from envs_helpers import assert_same, short, skip_without_data

TASKS = sorted(CATALOGUE)


def rollout(env: gym.Env, seed: int, n_steps: int) -> list[tuple]:
    """Seeded reset and seeded random actions; resets after truncation. Returns every output."""
    env.action_space.seed(seed)
    obs, info = env.reset(seed=seed)
    out: list[tuple] = [(obs, info)]
    for _ in range(n_steps):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        out.append((obs, reward, terminated, truncated, info))
        if terminated or truncated:
            out.append(env.reset())
    return out


@pytest.mark.parametrize("task_id", TASKS)
def test_check_env_passes_without_warnings(task_id):
    skip_without_data(task_id)
    env = gym.make(task_id, **short(task_id, 30))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        # the benchmark v1 tasks' deprecation is their one intended warning (tests/test_tasks_v2.py holds it)
        warnings.filterwarnings("ignore", message=".*is a benchmark v1 task, frozen and deprecated",
                                category=DeprecationWarning)
        check_env(env.unwrapped)
    env.close()


@pytest.mark.parametrize("task_id", TASKS)
def test_same_seed_same_200_steps(task_id):
    skip_without_data(task_id)
    first = rollout(gym.make(task_id), 7, 200)
    second = rollout(gym.make(task_id), 7, 200)
    assert_same(first, second)
    other = rollout(gym.make(task_id), 8, 5)
    if get_spec(task_id).trajectory.kind != "recorded":  # a replay differs only in its prior
        assert not np.array_equal(first[3][0], other[3][0])


def test_step_outputs_and_info():
    env = gym.make("swarmloc/NLOS-v0", duration=0.3)
    obs, info = env.reset(seed=3)
    assert obs.dtype == np.float32 and obs.shape == (4, 11, 11) and info == {}
    for k in range(3):
        obs, reward, terminated, truncated, info = env.step(np.ones((4, 11), np.float32))
        assert isinstance(reward, float) and terminated is False
        assert truncated is (k == 2)
        assert reward == pytest.approx(float(info["uav_reward"].mean()))
        for key in ("accuracy", "delay_penalty", "energy_penalty", "jitter_penalty", "flops", "delay_ms",
                    "energy_j", "position_error"):
            assert info[key].shape == (4,)
    assert (info["flops"] > 0).all() and (info["energy_j"] > 0).all()


def test_reset_seed_is_the_episode_seed_and_next_seeds_are_drawn():
    env = gym.make("swarmloc/NLOS-v0", duration=1.0).unwrapped
    a, _ = env.reset(seed=11)
    core = env.batch.core
    assert core.world.seeds[0] == 11
    env.reset()
    drawn = int(core.world.seeds[0])
    env.reset(seed=11)
    env.reset()
    assert int(core.world.seeds[0]) == drawn != 11


def test_bad_actions():
    env = gym.make("swarmloc/NLOS-v0", duration=1.0).unwrapped
    env.reset(seed=0)
    bad = np.ones((4, 11), np.float32)
    bad[2, 5] = np.nan
    with pytest.raises(ValueError, match=r"finite.*nan.*\(2, 5\)"):
        env.step(bad)
    bad[2, 5] = np.inf
    with pytest.raises(ValueError, match="finite"):
        env.step(bad)
    with pytest.raises(ValueError, match=r"\(N, L\) = \(4, 11\).*\(11, 4\)"):
        env.step(np.ones((11, 4)))
    with pytest.raises(ValueError, match="shape"):
        env.step("trust")
    with pytest.warns(RuntimeWarning, match="clipped"):
        obs_hi, *_ = env.step(np.full((4, 11), 1.5))
    assert np.all(obs_hi[..., 2] <= 1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # only once per env
        obs_lo, *_ = env.step(np.full((4, 11), -0.5))
    assert np.all(obs_lo[..., 2] == 0.0)  # previous trust feature = clipped value
    other = gym.make("swarmloc/NLOS-v0", duration=1.0).unwrapped
    other.reset(seed=0)
    with pytest.warns(RuntimeWarning, match="clipped"):
        other.step(np.full((4, 11), 2.0))


def test_step_before_reset_and_after_truncation_raise():
    env = gym.make("swarmloc/Ideal-v0", duration=0.1).unwrapped
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.ones((4, 9)))
    env.reset(seed=0)
    assert env.step(np.ones((4, 9)))[3] is True
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.ones((4, 9)))


def test_render_rgb_array_and_close_idempotent():
    env = gym.make("swarmloc/VisionLoss-v0", duration=1.0, render_mode="rgb_array")
    env.reset(seed=0)
    env.step(env.action_space.sample())
    frame = env.render()
    assert frame.shape == (480, 480, 3) and frame.dtype == np.uint8
    assert frame.std() > 0  # something was drawn
    env.close()
    env.close()
    with pytest.raises(ValueError, match="render_mode"):
        gym.make("swarmloc/NLOS-v0", render_mode="ansi")


def test_reward_kwargs_and_policy_flops():
    base = gym.make("swarmloc/NLOS-v0", duration=0.5)
    heavy = gym.make("swarmloc/NLOS-v0", duration=0.5, policy_flops=5e6,
                     reward_weights={"delay": 10.0, "energy": 0.0, "jitter": 0.0})
    base.reset(seed=1)
    heavy.reset(seed=1)
    action = np.ones((4, 11), np.float32)
    _, r0, _, _, i0 = base.step(action)
    _, r1, _, _, i1 = heavy.step(action)
    np.testing.assert_allclose(i1["flops"], i0["flops"] + 5e6)
    assert (i1["delay_ms"] > 100).all() and (i1["delay_penalty"] > 0).all() and r1 < r0
    np.testing.assert_array_equal(i1["accuracy"], i0["accuracy"])  # same physics


def test_overrides_reach_the_spec():
    env = gym.make("swarmloc/NLOS-v0", duration=2.0, sensors={"imu_sigma": 0.0}).unwrapped
    assert env.task_spec.n_steps == 20 and env.task_spec.sensors.imu_sigma == 0.0
    assert env.task_spec.sensors.anchor_sigma == get_spec("swarmloc/NLOS-v0").sensors.anchor_sigma
