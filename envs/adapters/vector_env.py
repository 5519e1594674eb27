"""Gymnasium vector environment on the batched core (no per-env Python loop per step).

``SwarmLocVectorEnv`` steps B environments of one task in one call of the core. It is
the ``vector_entry_point`` of every registered task (``gym.make_vec(id, num_envs=B)``).
Autoreset is ``AutoresetMode.NEXT_STEP``: the step after an environment truncates resets
it (its action is ignored, its reward is 0, ``terminated``/``truncated`` are False, and its
info entries are masked out). ``reset(seed=s)`` gives environment b the seed ``s + b``,
like ``SyncVectorEnv``, so the vector env reproduces the single envs seeded ``s, s+1, …``.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from swarmloc.envs.world.cost import ProcessorProfile
from swarmloc.envs.world.observation import N_FEATURES
from swarmloc.envs.world.reward import RewardWeights
from swarmloc.envs.adapters.trust_env import (
    INFO_KEYS,
    ActionChecker,
    EpisodeSeeder,
    TrustEnvBatch,
    build_spec,
)


class SwarmLocVectorEnv(VectorEnv):
    """B environments of one swarmloc task stepped together.

    Args:
        task_id: registered task ID.
        num_envs: B.
        max_episode_steps: truncate after this many steps (default and upper limit: the
            task's ``n_steps``; ``gym.make_vec`` passes the registered value).
        copy: return new observation arrays every call (default); ``False`` returns the
            env's own buffer, overwritten by the next call (faster, like ``SyncVectorEnv``).
        render_mode: ``None`` or ``"rgb_array"`` (one frame per environment; slow for big B).
        reward_weights, policy_flops, processor: as for ``SwarmLocEnv``.
        **overrides: task-spec field overrides.
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, task_id: str, num_envs: int = 1, *, max_episode_steps: int | None = None, copy: bool = True,
                 render_mode: str | None = None, reward_weights: RewardWeights | dict | None = None,
                 policy_flops: float = 0.0, processor: ProcessorProfile | dict | None = None, **overrides: Any):
        if not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array' for the vector env, got {render_mode!r}")
        spec = build_spec(task_id, overrides)
        horizon = spec.n_steps if max_episode_steps is None else int(max_episode_steps)
        if horizon < 1:
            raise ValueError(f"max_episode_steps must be >= 1, got {max_episode_steps}")
        self.task_spec = spec
        self.num_envs = int(num_envs)
        self.horizon = min(horizon, spec.n_steps)
        self.copy = copy
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": max(1, int(round(1.0 / spec.dt)))}
        self._batch = TrustEnvBatch.for_adapter(spec, self.num_envs, reward_weights=reward_weights,
                                                policy_flops=policy_flops, processor=processor)
        n, n_l, n_b = self._batch.n_uav, self._batch.n_channels, self.num_envs
        self.single_observation_space = spaces.Box(0.0, 1.0, (n, n_l, N_FEATURES), np.float32)
        self.single_action_space = spaces.Box(0.0, 1.0, (n, n_l), np.float32)
        self.observation_space = batch_space(self.single_observation_space, n_b)
        self.action_space = batch_space(self.single_action_space, n_b)
        self._check = ActionChecker((n_b, n, n_l), "(B, N, L)")
        self._seeder = EpisodeSeeder(n_b)
        self._obs = np.empty((n_b, n, n_l, N_FEATURES), dtype=np.float32)
        self._autoreset = np.zeros(n_b, dtype=bool)
        self._started = False
        self._renderers: list | None = None

    @property
    def batch(self) -> TrustEnvBatch:
        """The underlying batched environment (core buffers, layout, reward settings)."""
        return self._batch

    def _observation(self) -> np.ndarray:
        return self._batch.observation() if self.copy else self._batch.observation(self._obs)

    def reset(self, *, seed: int | Sequence[int | None] | None = None, options: dict[str, Any] | None = None
              ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset every environment (or those in ``options["reset_mask"]``, a ``(B,)`` bool array).

        Args:
            seed: ``int`` s → environment b plays seed ``s + b``; a list gives one seed (or
                None) per environment; None draws the next seeds from each env's generator.
            options: ``{"reset_mask": np.ndarray}`` resets only the masked environments.
        """
        super().reset(seed=seed if isinstance(seed, (int, np.integer)) else None)
        mask = None
        if options is not None and "reset_mask" in options:
            mask = np.asarray(options["reset_mask"])
            if mask.shape != (self.num_envs,) or mask.dtype != np.bool_ or not mask.any():
                raise ValueError(f"options['reset_mask'] must be a bool array of shape ({self.num_envs},) with at "
                                 f"least one True, got dtype {mask.dtype} shape {mask.shape}")
        self._seeder.seed(seed, mask)
        index = None if mask is None else np.nonzero(mask)[0]
        self._batch.reset(self._seeder.draw(index), mask)
        if mask is None:
            self._autoreset[:] = False
        else:
            self._autoreset[mask] = False
        self._started = True
        return self._observation(), {}

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every environment with trust ``(B, N, L)``; next-step autoreset.

        Returns observations ``(B, N, L, F)``, team rewards ``(B,)``, terminations and
        truncations ``(B,)`` and infos: per-UAV ``(B, N)`` arrays (see ``SwarmLocEnv.step``)
        with a ``_<key>`` bool mask ``(B,)`` that is False for environments that were reset
        in this call.
        """
        if not self._started:
            raise RuntimeError("call reset() before step()")
        trust = self._check(actions)
        resetting = self._autoreset
        n_b = self.num_envs
        rewards = np.zeros(n_b)
        if resetting.all():
            self._batch.reset(self._seeder.draw(), None)
            infos: dict[str, Any] = {}
        else:
            o, terms = self._batch.step(trust)
            rewards = self._batch.team_reward(terms)
            infos = self._batch.info_arrays(terms)
            has = ~resetting
            if resetting.any():
                index = np.nonzero(resetting)[0]
                self._batch.reset(self._seeder.draw(index), resetting)
                rewards[resetting] = 0.0
                for key in INFO_KEYS:
                    infos[key][resetting] = 0.0
            for key in INFO_KEYS:
                infos["_" + key] = has.copy()
        steps = self._batch.last.steps
        truncated = steps >= self.horizon
        self._autoreset = truncated.copy()
        return self._observation(), rewards, np.zeros(n_b, dtype=bool), truncated, infos

    def render(self) -> tuple[np.ndarray, ...] | None:
        """One ``(480, 480, 3)`` frame per environment in ``rgb_array`` mode."""
        if self.render_mode is None:
            return None
        from swarmloc.envs.adapters.render import TopDownRenderer

        w, o, s = self._batch.core.world, self._batch.last, self.task_spec
        if self._renderers is None:
            self._renderers = [TopDownRenderer(self._batch.layout, w.anchors, w.landmarks, s.task_id)
                               for _ in range(self.num_envs)]
        return tuple(r.draw(o.truth[b], o.estimate[b], o.applied[b], o.valid[b], float(o.steps[b]) * s.dt)
                     for b, r in enumerate(self._renderers))

    def close_extras(self, **kwargs: Any) -> None:
        """Release renderers."""
        for r in self._renderers or ():
            r.close()
        self._renderers = None
