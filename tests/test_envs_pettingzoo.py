"""PettingZoo Parallel / AEC API over every registered task: API tests, determinism, state, errors."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from pettingzoo.test import api_test, parallel_api_test

import swarmloc.envs
from swarmloc.envs.tasks.catalogue import CATALOGUE

from envs_helpers import assert_same, short, skip_without_data

TASKS = sorted(CATALOGUE)


@pytest.mark.parametrize("task_id", TASKS)
def test_parallel_api_test(task_id):
    skip_without_data(task_id)
    env = swarmloc.envs.parallel_env(task_id, **short(task_id, 25))
    parallel_api_test(env, num_cycles=60)
    obs, _ = env.reset(seed=0)
    assert env.state().shape == env.state_space.shape
    assert env.state() in env.state_space


def test_aec_api_test():
    api_test(swarmloc.envs.env("swarmloc/CascadedFault-v0", duration=2.0), num_cycles=30)


def rollout(env, seed: int, n_steps: int) -> list:
    for agent in env.possible_agents:
        env.action_space(agent).seed(seed + int(agent.split("_")[1]))
    out = [env.reset(seed=seed)]
    for _ in range(n_steps):
        if not env.agents:
            out.append(env.reset())
            continue
        step = env.step({a: env.action_space(a).sample() for a in env.agents})
        out.append(step + (env.state(),))
    return out


@pytest.mark.parametrize("task_id", ["swarmloc/NLOS-v0", "swarmloc/CascadedFaultRandom-v0",
                                     "swarmloc/HybridNoise50-v0", "swarmloc/GradualFault-v0"])
def test_same_seed_same_200_steps(task_id):
    first = rollout(swarmloc.envs.parallel_env(task_id), 4, 200)
    second = rollout(swarmloc.envs.parallel_env(task_id), 4, 200)
    assert_same(first, second)


def test_per_agent_rewards_and_gym_team_reward_agree():
    par = swarmloc.envs.parallel_env("swarmloc/NLOS-v0", duration=1.0)
    single = gym.make("swarmloc/NLOS-v0", duration=1.0)
    obs, _ = par.reset(seed=9)
    g_obs, _ = single.reset(seed=9)
    assert par.agents == [f"uav_{i}" for i in range(4)]
    for i, agent in enumerate(par.agents):
        np.testing.assert_array_equal(obs[agent], g_obs[i])
    action = np.random.default_rng(0).uniform(0, 1, (4, 11)).astype(np.float32)
    _, rewards, _, _, infos = par.step({f"uav_{i}": action[i] for i in range(4)})
    _, team, _, _, info = single.step(action)
    assert np.mean([rewards[a] for a in par.possible_agents]) == pytest.approx(team)
    for i, agent in enumerate(par.possible_agents):
        assert rewards[agent] == infos[agent]["uav_reward"] == info["uav_reward"][i]
        assert infos[agent]["position_error"] == info["position_error"][i]


def test_max_cycles_truncates_and_agents_leave():
    env = swarmloc.envs.parallel_env("swarmloc/Ideal-v0", max_cycles=3)
    env.reset(seed=0)
    act = {a: np.ones(9, np.float32) for a in env.possible_agents}
    for k in range(3):
        _, _, terms, truncs, _ = env.step(act)
        assert not any(terms.values()) and all(truncs.values()) == (k == 2)
    assert env.agents == []
    with pytest.raises(RuntimeError, match="reset"):
        env.step(act)


def test_spaces_are_cached_and_bad_actions_named():
    env = swarmloc.envs.parallel_env("swarmloc/NLOS-v0", duration=1.0)
    assert env.observation_space("uav_1") is env.observation_space("uav_1")
    assert env.action_space("uav_1") is env.action_space("uav_1")
    env.reset(seed=0)
    act = {a: np.ones(11, np.float32) for a in env.agents}
    with pytest.raises(ValueError, match="missing \\['uav_3'\\]"):
        env.step({a: v for a, v in act.items() if a != "uav_3"})
    with pytest.raises(ValueError, match=r"uav_0 must have shape \(L,\) = \(11,\)"):
        env.step({**act, "uav_0": np.ones(10)})
    with pytest.raises(ValueError, match="uav_2 must be finite"):
        env.step({**act, "uav_2": np.full(11, np.nan)})
    with pytest.warns(RuntimeWarning, match="clipped"):
        env.step({**act, "uav_2": np.full(11, 3.0)})
