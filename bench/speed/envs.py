"""Environment-API throughput: swarmloc's adapters, and VMAS / MPE2 measured in the same run.

``measure_env_rows(quick)`` returns one row per (implementation, batch size) with
``env_steps_per_s`` (B × steps / s) and ``uav_steps_per_s`` (× N agents). Every rollout
uses random actions drawn beforehand (the sampler is not timed), resets when episodes
end (timed, as in training), and is preceded by an untimed warm-up (numba / torch
caches). The steps are timed in ``REPEATS`` blocks and the fastest block counts (as
``timeit`` does): on a shared machine the slower blocks measure the neighbours.
``bench/speed/kernels.py`` prints ratios; run this file directly for the table alone.

Rows: ``gymnasium`` (``gym.make`` Scale6-v0, the ``world`` rows' task, with its wrappers, B=1), ``pettingzoo`` (parallel
API, B=1), ``gym-vector`` and ``torchrl`` (B = 1024, 4096), and when importable
(``pip install -e .[bench]``) ``mpe2-simple-spread`` (PettingZoo parallel, B=1, 3 agents)
and ``vmas-navigation`` (CPU, 4 agents, same B's).
"""

from __future__ import annotations

import time
from typing import Callable

import numpy as np

#: the task of the ``world`` rows (``bench/speed/world.py``), so that an adapter's row reads beside the world step
#: it wraps
TASK = "swarmloc/Scale6-v0"
BATCHES = (1024, 4096)
REPEATS = 5


def _timed(step: Callable[[int], None], n_steps: int, warmup: int) -> float:
    """Seconds per ``n_steps`` calls of ``step(k)``: the fastest of ``REPEATS`` blocks, after a warm-up."""
    for k in range(warmup):
        step(k)
    block = max(1, n_steps // REPEATS)
    best, k = float("inf"), 0
    for _ in range(REPEATS):
        start = time.perf_counter()
        for _ in range(block):
            step(k)
            k += 1
        best = min(best, time.perf_counter() - start)
    return best * n_steps / block


def _row(impl: str, n_b: int, n_agents: int, n_steps: int, seconds: float) -> dict:
    rate = n_b * n_steps / seconds
    return {"impl": impl, "B": n_b, "env_steps_per_s": rate, "uav_steps_per_s": rate * n_agents}


def gymnasium_row(n_steps: int) -> dict:
    import gymnasium as gym

    import swarmloc.envs  # noqa: F401

    env = gym.make(TASK)
    env.reset(seed=0)
    actions = np.random.default_rng(0).uniform(0, 1, (256, *env.action_space.shape)).astype(np.float32)

    def step(k: int) -> None:
        if env.step(actions[k % 256])[3]:
            env.reset()

    seconds = _timed(step, n_steps, 200)
    return _row("gymnasium", 1, env.unwrapped.n_uav, n_steps, seconds)


def _parallel_env_row(impl: str, env, n_steps: int) -> dict:
    """Time ``n_steps`` random-action steps of a PettingZoo parallel env (resets included)."""
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    pool = [{a: rng.uniform(0, 1, env.action_space(a).shape).astype(np.float32) for a in env.possible_agents}
            for _ in range(64)]

    def step(k: int) -> None:
        env.step(pool[k % 64])
        if not env.agents:
            env.reset()

    seconds = _timed(step, n_steps, 100)
    return _row(impl, 1, len(env.possible_agents), n_steps, seconds)


def pettingzoo_row(n_steps: int) -> dict:
    import swarmloc.envs

    env = swarmloc.envs.parallel_env(TASK)
    return _parallel_env_row("pettingzoo", env, n_steps)


def vector_row(n_b: int, n_steps: int) -> dict:
    import gymnasium as gym

    import swarmloc.envs  # noqa: F401

    env = gym.make_vec(TASK, num_envs=n_b)
    env.reset(seed=0)
    actions = np.random.default_rng(0).uniform(0, 1, (4, *env.action_space.shape)).astype(np.float32)
    seconds = _timed(lambda k: env.step(actions[k % 4]), n_steps, 3)
    return _row("gym-vector", n_b, env.unwrapped.batch.n_uav, n_steps, seconds)


def torchrl_row(n_b: int, n_steps: int) -> dict:
    import torch

    import swarmloc.envs

    env = swarmloc.envs.torchrl_env(TASK, n_b)
    td = env.reset()
    shape = env.full_action_spec["uav", "action"].shape
    actions = torch.rand((4, *shape), generator=torch.Generator().manual_seed(0))
    state = {"td": td}

    def step(k: int) -> None:
        td = state["td"]
        td.set(("uav", "action"), actions[k % 4])
        _, state["td"] = env.step_and_maybe_reset(td)

    seconds = _timed(step, n_steps, 3)
    return _row("torchrl", n_b, env.batch.n_uav, n_steps, seconds)


def mpe2_row(n_steps: int) -> dict | None:
    try:
        from mpe2 import simple_spread_v3
    except ImportError:
        return None
    env = simple_spread_v3.parallel_env(continuous_actions=True)
    return _parallel_env_row("mpe2-simple-spread", env, n_steps)


def vmas_row(n_b: int, n_steps: int) -> dict | None:
    try:
        import torch
        import vmas
    except ImportError:
        return None
    env = vmas.make_env("navigation", num_envs=n_b, device="cpu", continuous_actions=True, seed=0)
    env.reset()
    gen = torch.Generator().manual_seed(0)
    pool = [[torch.rand((n_b, 2), generator=gen) * 2 - 1 for _ in env.agents] for _ in range(4)]

    def step(k: int) -> None:
        env.step(pool[k % 4])

    seconds = _timed(step, n_steps, 3)
    return _row("vmas-navigation", n_b, env.n_agents, n_steps, seconds)


def measure_env_rows(quick: bool = False) -> list[dict]:
    """Throughput rows of every environment API (and VMAS / MPE2 when installed).

    Args:
        quick: fewer steps (a smoke run; numbers are noisier).

    Returns:
        Rows ``{"impl", "B", "env_steps_per_s", "uav_steps_per_s"}``.
    """
    single, batched = (2_000, 10) if quick else (20_000, 50)
    rows = [gymnasium_row(single), pettingzoo_row(single // 2)]
    for n_b in BATCHES:
        rows += [vector_row(n_b, batched), torchrl_row(n_b, batched)]
    rows.append(mpe2_row(single // 2))
    for n_b in BATCHES:
        rows.append(vmas_row(n_b, batched))
    return [row for row in rows if row is not None]
