"""Gymnasium single environment of the link-trust track (Track A).

``SwarmLocEnv`` is one swarm of one task: observation ``(N, L, F)`` float32 in [0, 1],
action ``(N, L)`` trust in [0, 1], team reward (mean over UAVs of the standard reward).
The per-task subclasses in ``task_envs.py`` carry the task's documentation; this class
holds the behaviour they share. See ``trust_env.TrustEnvBatch`` for the numbers.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

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



class SwarmLocEnv(gym.Env[np.ndarray, np.ndarray]):
    """A swarmloc link-trust task as a Gymnasium environment (see the per-task classes).

    Args:
        task_id: registered task ID; per-task subclasses fix it (passing another raises).
        render_mode: ``None``, ``"rgb_array"`` or ``"human"``.
        reward_weights: λ and constants of the standard reward (``RewardWeights`` or a
            mapping of its fields); default: the standard v0.
        policy_flops: FLOPs the method spends per UAV per step, added to the filter's
            FLOPs in the delay and energy terms (default 0).
        processor: processor profile (``ProcessorProfile`` or mapping); default STM32F427 v0.
        **overrides: top-level task-spec fields to override (e.g. ``duration=5.0``).
    """

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 10}
    #: fixed by each per-task subclass
    task_id: str | None = None

    def __init__(self, task_id: str | None = None, *, render_mode: str | None = None,
                 reward_weights: RewardWeights | dict | None = None, policy_flops: float = 0.0,
                 processor: ProcessorProfile | dict | None = None, **overrides: Any):
        cls_task = type(self).task_id
        if cls_task is not None and task_id is not None and task_id.removeprefix("swarmloc/") != \
                cls_task.removeprefix("swarmloc/"):
            raise ValueError(f"{type(self).__name__} is task {cls_task!r}; got task_id={task_id!r}")
        task_id = task_id or cls_task
        if task_id is None:
            raise ValueError("task_id is required, e.g. SwarmLocEnv('swarmloc/NLOS-v0')")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        self.task_spec = build_spec(task_id, overrides)
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": max(1, int(round(1.0 / self.task_spec.dt)))}
        self._batch = TrustEnvBatch.for_adapter(self.task_spec, 1, reward_weights=reward_weights,
                                                policy_flops=policy_flops, processor=processor)
        n, n_l = self._batch.n_uav, self._batch.n_channels
        self.observation_space = spaces.Box(0.0, 1.0, (n, n_l, N_FEATURES), np.float32)
        self.action_space = spaces.Box(0.0, 1.0, (n, n_l), np.float32)
        self._check = ActionChecker((n, n_l), "(N, L)")
        self._started = False
        self._view = FirstEpisodeView(self._batch, self.task_spec.task_id, human=self.render_mode == "human")

    # ------------------------------------------------------------------ properties
    @property
    def n_uav(self) -> int:
        """N, the number of UAVs."""
        return self._batch.n_uav

    @property
    def n_channels(self) -> int:
        """L, the channels per UAV."""
        return self._batch.n_channels

    @property
    def batch(self) -> TrustEnvBatch:
        """The underlying batched environment (B = 1): core buffers, layout, reward settings."""
        return self._batch

    # ------------------------------------------------------------------ API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode.

        ``reset(seed=s)`` plays episode seed ``s`` (the episode the bench suites call seed
        ``s``) and seeds ``np_random`` with ``s``; ``reset()`` plays the next episode seed
        drawn from ``np_random``. ``options`` is accepted and ignored.
        """
        super().reset(seed=seed)
        if seed is not None:
            if not 0 <= seed < SEED_BOUND:
                raise ValueError(f"seed must be in [0, 2**63 - 1), got {seed}")
            episode_seed = int(seed)
        else:
            episode_seed = int(self.np_random.integers(0, SEED_BOUND))
        self._batch.reset(np.array([episode_seed], dtype=np.int64))
        self._started = True
        if self.render_mode == "human":
            self.render()
        return self._batch.observation()[0], {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Apply trust ``(N, L)`` in [0, 1] to the pending update and advance one step.

        Returns the observation of the next pending step, the team reward (mean over UAVs
        of the standard reward), ``terminated`` (always False), ``truncated`` (True after
        ``n_steps`` updates) and an info dict of per-UAV ``(N,)`` arrays: ``uav_reward``,
        every reward term, ``flops``, ``delay_ms``, ``energy_j`` and ``position_error`` [m].
        """
        if not self._started:
            raise RuntimeError("call reset() before step()")
        o, terms = self._batch.step(self._check(action)[None])
        truncated = bool(o.done[0])
        if truncated:
            self._started = False
        info = {key: value[0] for key, value in self._batch.info_arrays(terms).items()}
        if self.render_mode == "human":
            self.render()
        return self._batch.observation()[0], float(self._batch.team_reward(terms)[0]), False, truncated, info

    def render(self) -> np.ndarray | None:
        """``rgb_array``: the top-down frame ``(480, 480, 3)`` uint8; ``human``: draw it in a window."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array' or 'human'")
            return None
        frame = self._view.frame()
        return frame if self.render_mode == "rgb_array" else None

    def close(self) -> None:
        """Release the renderer; calling it again is harmless."""
        self._view.close()
