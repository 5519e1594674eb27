"""One Track A step: the Gymnasium env and the bench runner score an episode identically."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import swarmloc.envs  # noqa: F401  (registers the tasks)
from swarmloc.agents.protocols import TrustInput, episode_keys
from swarmloc.agents.registry import load_method
from swarmloc.bench.evaluation.runner import run_episodes
from swarmloc.envs.tasks.catalogue import get_spec
from swarmloc.envs.adapters.trust_env import TrustEnvBatch


def _gym_team_return(method: str, task: str, seed: int) -> float:
    """Play ``method`` through ``gym.make(task)`` as a user would, summing the team rewards."""
    env = gym.make(task)
    obs, _ = env.reset(seed=seed)
    batch = env.unwrapped._batch  # the policy's raw inputs (NIS, innovations) live beside the observation
    policy = load_method(method).method
    policy.reset(1, batch.layout, episode_keys(np.array([seed])))
    dt = get_spec(task).dt
    rewards, done, k = [], False, 0
    while not done:
        cs = batch.last
        inp = TrustInput.view(obs[None], cs.resid, cs.pred, cs.nis, cs.applied, cs.jerk, cs.valid, (k + 1) * dt, k + 1)
        obs, reward, terminated, truncated, _ = env.step(policy.act(inp)[0])
        rewards.append(reward)
        done, k = terminated or truncated, k + 1
    return float(np.sum(np.asarray(rewards, dtype=np.float64)))


@pytest.mark.parametrize("task", ["swarmloc/NLOS-v0", "swarmloc/CascadedFault-v0"])
@pytest.mark.parametrize("seed", [1_000_000, 1_000_001])
def test_gym_rewards_sum_to_the_runners_team_return(task, seed):
    runner = run_episodes("chi2-gate", [(task, seed)])[0]["metrics"]["team_return"]
    assert _gym_team_return("chi2-gate", task, seed) == runner


def test_energy_term_scores_the_validity_of_its_own_update():
    """A policy that trusts exactly the present channels spends energy 1 on every UAV with a measurement.

    VisionLoss-v0 switches landmarks in and out of view from step to step; scoring the
    update with the next step's validity (the former bug) gives energy < 1 there.
    """
    spec = get_spec("swarmloc/VisionLoss-v0", duration=20.0)
    env = TrustEnvBatch(spec, 2)
    cs = env.reset(np.array([1_000_000, 1_000_001]))
    changed = 0
    for _ in range(spec.n_steps):
        pending = cs.valid.copy()
        cs, terms = env.step(pending.astype(np.float64))
        assert np.array_equal(cs.update_valid, pending)
        has = pending.any(axis=-1)
        np.testing.assert_array_equal(terms.energy_penalty[has], 1.0)
        changed += int((cs.valid != pending).any())
    assert changed > 0, "the task must change channel validity between steps for this test to mean anything"


def test_policy_flops_count_per_present_channel():
    spec = get_spec("swarmloc/VisionLoss-v0", duration=2.0)
    plain, counted = TrustEnvBatch(spec, 1), TrustEnvBatch(spec, 1, policy_flops=5.0, policy_flops_per_channel=3.0)
    for env in (plain, counted):
        env.reset(np.array([7]))
    for _ in range(spec.n_steps):
        trust = np.ones((1, spec.n_uav, plain.n_channels))
        o, base = plain.step(trust)
        _, extra = counted.step(trust)
        np.testing.assert_array_equal(extra.flops - base.flops, 5.0 + 3.0 * o.update_valid.sum(axis=-1))
