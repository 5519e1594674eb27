"""PettingZoo Parallel (and AEC) API of the link-trust track: one agent per UAV.

Agents ``uav_0 … uav_{N-1}``; agent i observes its own channels ``(L, F)``, acts on
them ``(L,)`` and receives its own standard reward. ``state()`` is the swarm's global
state for centralized critics (see ``TrustEnvBatch.state``). Episodes truncate after
``min(max_cycles, spec.n_steps)`` steps; every agent leaves together.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from pettingzoo import AECEnv, ParallelEnv
from pettingzoo.utils.conversions import parallel_to_aec

from swarmloc.envs.world.cost import ProcessorProfile
from swarmloc.envs.tasks.seeds import SEED_BOUND
from swarmloc.envs.world.observation import N_FEATURES
from swarmloc.envs.adapters.render import FirstEpisodeView
from swarmloc.envs.world.reward import RewardWeights
from swarmloc.envs.adapters.trust_env import (
    ActionChecker,
    TrustEnvBatch,
    build_spec,
)



class SwarmLocParallelEnv(ParallelEnv):
    """A swarmloc task with one PettingZoo agent per UAV.

    Args:
        task_id: registered task ID (e.g. ``"swarmloc/NLOS-v0"``).
        max_cycles: truncate after this many steps (default: the task's ``n_steps``; larger
            values are capped there, since the episode ends then).
        render_mode: ``None``, ``"rgb_array"`` or ``"human"``.
        reward_weights, policy_flops, processor: as for ``SwarmLocEnv``.
        **overrides: task-spec field overrides.
    """

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 10, "is_parallelizable": True,
                "name": "swarmloc"}

    def __init__(self, task_id: str, *, max_cycles: int | None = None, render_mode: str | None = None,
                 reward_weights: RewardWeights | dict | None = None, policy_flops: float = 0.0,
                 processor: ProcessorProfile | dict | None = None, **overrides: Any):
        if render_mode not in (None, "rgb_array", "human"):
            raise ValueError(f"render_mode must be None, 'rgb_array' or 'human', got {render_mode!r}")
        self.task_spec = spec = build_spec(task_id, overrides)
        self.max_cycles = spec.n_steps if max_cycles is None else int(max_cycles)
        if self.max_cycles < 1:
            raise ValueError(f"max_cycles must be >= 1, got {max_cycles}")
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "name": spec.task_id, "render_fps": max(1, int(round(1.0 / spec.dt)))}
        self._batch = TrustEnvBatch.for_adapter(spec, 1, reward_weights=reward_weights,
                                                policy_flops=policy_flops, processor=processor)
        n, n_l = self._batch.n_uav, self._batch.n_channels
        self.possible_agents = [f"uav_{i}" for i in range(n)]
        self.agents: list[str] = []
        self._index = {agent: i for i, agent in enumerate(self.possible_agents)}
        self.observation_spaces = {a: spaces.Box(0.0, 1.0, (n_l, N_FEATURES), np.float32)
                                   for a in self.possible_agents}
        self.action_spaces = {a: spaces.Box(0.0, 1.0, (n_l,), np.float32) for a in self.possible_agents}
        low, high = self._batch.state_bounds()
        self.state_space = spaces.Box(low, high, dtype=np.float32)
        self._check = ActionChecker((1, n, n_l), "(L,) per agent")
        self._trust = np.empty((1, n, n_l))
        self._np_random: np.random.Generator | None = None
        self._obs: np.ndarray | None = None
        self._view = FirstEpisodeView(self._batch, self.task_spec.task_id, human=self.render_mode == "human")

    # ------------------------------------------------------------------ spaces
    def observation_space(self, agent: str) -> spaces.Box:
        """``Box(0, 1, (L, F), float32)`` (the same object on every call)."""
        return self.observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Box:
        """``Box(0, 1, (L,), float32)`` trust per channel (the same object on every call)."""
        return self.action_spaces[agent]

    @property
    def batch(self) -> TrustEnvBatch:
        """The underlying batched environment (B = 1)."""
        return self._batch

    # ------------------------------------------------------------------ API
    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[dict[str, np.ndarray], dict[str, dict]]:
        """Start an episode: ``seed=s`` plays episode seed ``s``; otherwise the next seed is drawn."""
        if seed is not None:
            if not 0 <= int(seed) < SEED_BOUND:
                raise ValueError(f"seed must be in [0, 2**63 - 1), got {seed}")
            self._np_random, _ = seeding.np_random(int(seed))
            episode_seed = int(seed)
        else:
            if self._np_random is None:
                self._np_random, _ = seeding.np_random()
            episode_seed = int(self._np_random.integers(0, SEED_BOUND))
        self._batch.reset(np.array([episode_seed], dtype=np.int64))
        self.agents = list(self.possible_agents)
        self._obs = self._batch.observation()
        if self.render_mode == "human":
            self.render()
        return {a: self._obs[0, i] for i, a in enumerate(self.agents)}, {a: {} for a in self.agents}

    def step(self, actions: dict[str, np.ndarray]) -> tuple[dict, dict, dict, dict, dict]:
        """Apply every live agent's trust ``(L,)``; all agents must act."""
        if not self.agents:
            raise RuntimeError("the episode is over (no live agents); call reset()")
        missing = [a for a in self.agents if a not in actions]
        extra = [a for a in actions if a not in self._index]
        if missing or extra:
            raise ValueError(f"actions must hold one (L,) trust array for every live agent; missing {missing}, "
                             f"unknown {extra}")
        n_l = self._batch.n_channels
        for agent, action in actions.items():
            arr = np.asarray(action)
            if arr.shape != (n_l,):
                raise ValueError(f"action of {agent} must have shape (L,) = ({n_l},), got {arr.shape}")
            self._trust[0, self._index[agent]] = arr
        bad = ~np.isfinite(self._trust[0])
        if bad.any():
            i, l = np.argwhere(bad)[0]
            raise ValueError(f"action of {self.possible_agents[i]} must be finite trust values in [0, 1]; "
                             f"got {self._trust[0, i, l]} at channel {l}")
        o, terms = self._batch.step(self._check(self._trust))
        truncated = bool(o.done[0]) or int(o.steps[0]) >= self.max_cycles
        self._obs = obs = self._batch.observation()
        info = self._batch.info_arrays(terms)
        agents = self.agents
        observations = {a: obs[0, i] for i, a in enumerate(agents)}
        rewards = {a: float(terms.reward[0, i]) for i, a in enumerate(agents)}
        terminations = dict.fromkeys(agents, False)
        truncations = dict.fromkeys(agents, truncated)
        infos = {a: {key: float(value[0, i]) for key, value in info.items()} for i, a in enumerate(agents)}
        if truncated:
            self.agents = []
        if self.render_mode == "human":
            self.render()
        return observations, rewards, terminations, truncations, infos

    def state(self) -> np.ndarray:
        """Global state ``(S,)`` float32: flattened swarm observation, prior positions and
        velocities, prior position std (see ``TrustEnvBatch.state``)."""
        if self._obs is None:
            raise RuntimeError("call reset() before state()")
        return self._batch.state(self._obs)[0]

    def render(self) -> np.ndarray | None:
        """``rgb_array``: a ``(480, 480, 3)`` uint8 top-down frame; ``human``: draw it in a window."""
        if self.render_mode is None:
            return None
        frame = self._view.frame()
        return frame if self.render_mode == "rgb_array" else None

    def close(self) -> None:
        """Release the renderer (idempotent)."""
        self._view.close()


def parallel_env(task_id: str, **kwargs: Any) -> SwarmLocParallelEnv:
    """PettingZoo Parallel env of ``task_id`` (kwargs as for ``SwarmLocParallelEnv``)."""
    return SwarmLocParallelEnv(task_id, **kwargs)


def env(task_id: str, **kwargs: Any) -> AECEnv:
    """PettingZoo AEC env of ``task_id``: the parallel env through ``parallel_to_aec`` (order-enforced)."""
    return parallel_to_aec(parallel_env(task_id, **kwargs))
