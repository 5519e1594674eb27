"""Native batched torchrl environment of the link-trust track (group ``uav``).

``SwarmLocTorchRLEnv`` is an ``EnvBase`` with ``batch_size=[B]`` over the batched core; torch
appears only here, at the edge: numpy outputs (new arrays every step) are wrapped with
``torch.from_numpy`` without copying, actions are read with ``.numpy()``.

Keys (the layout of torchrl's VMAS wrapper: agent data under the group, done at the root):

| key | shape | dtype | |
|-----|-------|-------|-|
| ``("uav", "observation")`` | ``(B, N, L, F)`` | float32 | in [0, 1] |
| ``("uav", "action")`` | ``(B, N, L)`` | float32 | trust, bounded [0, 1] |
| ``("uav", "reward")`` | ``(B, N, 1)`` | float32 | each UAV's standard reward |
| ``("uav", "info", <term>)`` | ``(B, N, 1)`` | float32 | every reward term and ``position_error`` |
| ``"state"`` | ``(B, S)`` | float32 | global state for centralized critics |
| ``"done"``, ``"terminated"``, ``"truncated"`` | ``(B, 1)`` | bool | truncation after ``n_steps`` |

Partial reset: ``reset`` with a ``"_reset"`` ``(B, 1)`` mask restarts only those envs.
Seeding: ``set_seed(s)`` makes env b play seed ``s + b`` on its next reset, then draw its
following seeds from a generator seeded ``s + b`` (as the Gymnasium envs do).

The factory users call is ``swarmloc.envs.torchrl_env(task_id, batch_size, ...)``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from swarmloc.envs.world.cost import ProcessorProfile
from swarmloc.envs.world.observation import N_FEATURES
from swarmloc.envs.world.reward import RewardWeights
from swarmloc.envs.adapters.trust_env import (
    REWARD_TERMS,
    ActionChecker,
    EpisodeSeeder,
    TrustEnvBatch,
    build_spec,
)

GROUP = "uav"
#: per-UAV info entries under ("uav", "info") (the reward itself is ("uav", "reward"))
INFO_KEYS = REWARD_TERMS + ("position_error",)


class SwarmLocTorchRLEnv(EnvBase):
    """B environments of one swarmloc task as a torchrl ``EnvBase``.

    Args:
        task_id: registered task ID.
        batch_size: B (an int, or a 1-element shape).
        device: where output tensors live (the simulation runs on the CPU).
        reward_weights, policy_flops, processor: as for ``SwarmLocEnv``.
        **overrides: task-spec field overrides.
    """

    def __init__(self, task_id: str, batch_size: int | tuple[int] | torch.Size = 1, device: str | torch.device = "cpu",
                 *, reward_weights: RewardWeights | dict | None = None, policy_flops: float = 0.0,
                 processor: ProcessorProfile | dict | None = None, **overrides: Any):
        shape = torch.Size([batch_size] if isinstance(batch_size, int) else batch_size)
        if len(shape) != 1 or shape[0] < 1:
            raise ValueError(f"batch_size must be a positive int or a 1-D shape [B], got {batch_size!r}")
        super().__init__(device=device, batch_size=shape)
        spec = build_spec(task_id, overrides)
        self.task_spec = spec
        n_b = shape[0]
        self._batch = TrustEnvBatch.for_adapter(spec, n_b, reward_weights=reward_weights,
                                                policy_flops=policy_flops, processor=processor)
        n, n_l = self._batch.n_uav, self._batch.n_channels
        self._check = ActionChecker((n_b, n, n_l), "(B, N, L)")
        self._seeder = EpisodeSeeder(n_b)
        self._make_specs(n_b, n, n_l)

    def _make_specs(self, n_b: int, n: int, n_l: int) -> None:
        dev = self.device
        info = Composite({key: Unbounded((n_b, n, 1), dtype=torch.float32, device=dev) for key in INFO_KEYS},
                         shape=(n_b, n), device=dev)
        self.full_observation_spec = Composite(
            {GROUP: Composite({"observation": Bounded(0.0, 1.0, (n_b, n, n_l, N_FEATURES), dtype=torch.float32,
                                                      device=dev),
                               "info": info}, shape=(n_b, n), device=dev),
             "state": Unbounded((n_b, self._batch.state_size), dtype=torch.float32, device=dev)},
            shape=(n_b,), device=dev)
        self.full_action_spec = Composite(
            {GROUP: Composite({"action": Bounded(0.0, 1.0, (n_b, n, n_l), dtype=torch.float32, device=dev)},
                              shape=(n_b, n), device=dev)}, shape=(n_b,), device=dev)
        self.full_reward_spec = Composite(
            {GROUP: Composite({"reward": Unbounded((n_b, n, 1), dtype=torch.float32, device=dev)},
                              shape=(n_b, n), device=dev)}, shape=(n_b,), device=dev)
        self.full_done_spec = Composite(
            {key: Categorical(2, (n_b, 1), dtype=torch.bool, device=dev) for key in ("done", "terminated", "truncated")},
            shape=(n_b,), device=dev)

    @property
    def batch(self) -> TrustEnvBatch:
        """The underlying batched numpy environment."""
        return self._batch

    # ------------------------------------------------------------------ helpers
    def _tensor(self, array: np.ndarray) -> torch.Tensor:
        t = torch.from_numpy(array)
        return t if self.device is None or self.device.type == "cpu" else t.to(self.device, non_blocking=True)

    def _output(self, info: dict[str, np.ndarray] | None, reward: np.ndarray | None, done: np.ndarray
                ) -> TensorDictBase:
        n_b, n = self._batch.batch_size, self._batch.n_uav
        obs, state = self._batch.observation_and_state()
        if info is None:
            info_arr = np.zeros((len(INFO_KEYS), n_b, n, 1), dtype=np.float32)
        else:
            info_arr = np.stack([info[key] for key in INFO_KEYS]).astype(np.float32)[..., None]
        group = {"observation": self._tensor(obs),
                 "info": TensorDict({key: self._tensor(info_arr[k]) for k, key in enumerate(INFO_KEYS)},
                                    batch_size=(n_b, n))}
        if reward is not None:
            group["reward"] = self._tensor(reward.astype(np.float32)[..., None])
        done_t = self._tensor(done.reshape(n_b, 1))
        return TensorDict({GROUP: TensorDict(group, batch_size=(n_b, n)),
                           "state": self._tensor(state),
                           "done": done_t, "truncated": done_t.clone(),
                           "terminated": torch.zeros((n_b, 1), dtype=torch.bool)},
                          batch_size=self.batch_size, device=self.device)

    # ------------------------------------------------------------------ EnvBase hooks
    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs: Any) -> TensorDictBase:
        mask = None
        if tensordict is not None and "_reset" in tensordict.keys():
            reset = tensordict.get("_reset").reshape(self._batch.batch_size).cpu().numpy()
            if not reset.any():  # nothing to restart
                return self._output(None, None, self._batch.last.done.copy())
            mask = None if reset.all() else reset
        index = None if mask is None else np.nonzero(mask)[0]
        self._batch.reset(self._seeder.draw(index), mask)
        return self._output(None, None, np.zeros(self._batch.batch_size, dtype=bool))

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        action = tensordict.get((GROUP, "action")).detach().cpu().numpy()
        o, terms = self._batch.step(self._check(action))
        return self._output(self._batch.info_arrays(terms), terms.reward, o.done.copy())

    def _set_seed(self, seed: int | None) -> None:
        if seed is not None:
            self._seeder.seed(int(seed))


def make_torchrl_env(task_id: str, batch_size: int, device: str | torch.device = "cpu",
                     **kwargs: Any) -> SwarmLocTorchRLEnv:
    """torchrl env of ``task_id`` with ``batch_size`` environments (kwargs as for ``SwarmLocTorchRLEnv``)."""
    return SwarmLocTorchRLEnv(task_id, batch_size, device, **kwargs)
