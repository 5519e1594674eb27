"""The batched link-trust environment (Track A) that every API adapter wraps.

``TrustEnvBatch`` joins the pieces that exist elsewhere — the core (``core.py``), the
observation (``observation.py``), the standard reward (``reward.py``) and the cost model
(``cost.py``) — into B environments stepped together, in numpy, with no API glue. The
Gymnasium, vector, PettingZoo and torchrl adapters differ only in how they name, shape
and wrap what this class returns. Also here, because every adapter needs them exactly
alike: building a spec from keyword overrides, validating actions, and turning seeds
into the core's integer episode seeds.

Batch shapes: B environments, N UAVs, L channels per UAV, F features per channel.
"""

from __future__ import annotations

import warnings
from typing import Any, Mapping, Sequence

import numpy as np
from gymnasium import logger
from gymnasium.utils import seeding

from swarmloc.envs.world.core import CoreStep, LinkTrustCore
from swarmloc.envs.world.cost import DEFAULT_PROFILE, ProcessorProfile
from swarmloc.envs.world.observation import (N_FEATURES, build_observation, build_observation_and_state,
                                             build_state, kind_one_hot)
from swarmloc.envs.world.reward import STANDARD_WEIGHTS, RewardTerms, RewardWeights, team_reward
from swarmloc.envs.world.reward_kernel import standard_reward
from swarmloc.envs.tasks.specs import TaskSpec
from swarmloc.envs.tasks.seeds import SEED_BOUND
from swarmloc.envs.tasks.catalogue import canonical_task_id, get_spec

#: reward terms reported per UAV in every adapter's info (names of ``RewardTerms`` fields)
REWARD_TERMS = ("accuracy", "delay_penalty", "energy_penalty", "jitter_penalty", "flops", "delay_ms", "energy_j")
#: every per-UAV info entry: the UAV's own reward, each term, and the position error [m]
INFO_KEYS = ("uav_reward",) + REWARD_TERMS + ("position_error",)
#: spec fields a task's identity is made of; overriding them would make another task
_IDENTITY_FIELDS = ("name", "version", "track")


def build_spec(task_id: str, overrides: Mapping[str, Any]) -> TaskSpec:
    """The spec of ``task_id`` with top-level field overrides, validated.

    Args:
        task_id: a registered ID (``swarmloc/`` prefix optional).
        overrides: TaskSpec fields to replace (e.g. ``duration=5.0``).

    Raises:
        UnknownTaskError: unknown task ID (the message lists the known ones).
        TypeError: an override is not a TaskSpec field (the message lists the allowed ones).
        pydantic.ValidationError: an override value is out of range.

    Warns:
        DeprecationWarning: a benchmark v1 task (frozen and deprecated: the v2 tasks measure cooperation on a
            consistent backbone), through Gymnasium's logger as its own out-of-date notice.
    """
    canonical_task_id(task_id)
    allowed = sorted(set(TaskSpec.model_fields) - set(_IDENTITY_FIELDS))
    unknown = sorted(set(overrides) - set(allowed))
    if unknown:
        raise TypeError(f"unknown argument(s) {unknown} for task {task_id!r}; spec fields that may be overridden: "
                        f"{allowed} (plus reward_weights, policy_flops, processor, render_mode)")
    spec = get_spec(task_id, **overrides)
    if spec.version == 1 and spec.trajectory.kind != "recorded":  # the version is the task's (not an override)
        logger.deprecation(f"{spec.task_id} is a benchmark v1 task, frozen and deprecated: v1's CEKF fuses a "
                           "neighbour's estimate as a known point and double counts. Use the -v2 tasks "
                           "(docs/benchmark-v2.md).")
    return spec


def as_reward_weights(value: RewardWeights | Mapping[str, float] | None) -> RewardWeights:
    """``None`` → the standard v0 weights; a mapping → validated ``RewardWeights``."""
    if value is None:
        return STANDARD_WEIGHTS
    if isinstance(value, RewardWeights):
        return value
    if isinstance(value, Mapping):
        return RewardWeights(**value)
    raise TypeError(f"reward_weights must be a RewardWeights, a mapping or None, got {type(value).__name__}")


def as_processor(value: ProcessorProfile | Mapping[str, Any] | None) -> ProcessorProfile:
    """``None`` → the default processor profile; a mapping → validated ``ProcessorProfile``."""
    if value is None:
        return DEFAULT_PROFILE
    if isinstance(value, ProcessorProfile):
        return value
    if isinstance(value, Mapping):
        return ProcessorProfile(**value)
    raise TypeError(f"processor must be a ProcessorProfile, a mapping or None, got {type(value).__name__}")


def as_policy_flops(value: float) -> float:
    """Validate the declared policy FLOPs per UAV per step (finite, >= 0)."""
    flops = float(value)
    if not np.isfinite(flops) or flops < 0.0:
        raise ValueError(f"policy_flops must be a finite number >= 0 (FLOPs per UAV per step), got {value!r}")
    return flops


class ActionChecker:
    """Validates trust actions of one adapter instance against its expected shape.

    NaN or ±inf raise ``ValueError`` (naming the first bad entry); a wrong shape raises
    ``ValueError`` naming the expected shape; values outside [0, 1] are clipped, with a
    warning the first time it happens on this instance.

    Args:
        shape: the action shape the adapter expects, e.g. ``(N, L)``.
        shape_doc: how the shape is named in messages, e.g. ``"(N, L)"``.
    """

    def __init__(self, shape: tuple[int, ...], shape_doc: str):
        self.shape = tuple(shape)
        self.shape_doc = shape_doc
        self.warned = False

    def __call__(self, action: Any) -> np.ndarray:
        """Return ``action`` as a float64 array of ``self.shape`` with values in [0, 1]."""
        try:
            arr = np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"action must be a numeric array of shape {self.shape_doc} = {self.shape}, "
                             f"got {type(action).__name__}") from exc
        if arr.shape != self.shape:
            raise ValueError(f"action must have shape {self.shape_doc} = {self.shape}, got {arr.shape}")
        lo, hi = arr.min(), arr.max()
        if lo >= 0.0 and hi <= 1.0:  # the common case: two reductions, no copy
            return arr
        bad = ~np.isfinite(arr)
        if bad.any():
            where = tuple(np.argwhere(bad)[0].tolist())
            raise ValueError(f"action must be finite trust values in [0, 1]; got {arr[where]} at index {where}")
        if not self.warned:
            self.warned = True
            warnings.warn(f"action values outside [0, 1] (min {lo:.4g}, max {hi:.4g}) were clipped to [0, 1]; "
                          "this warning is shown once per environment", RuntimeWarning, stacklevel=3)
        return np.clip(arr, 0.0, 1.0)


class EpisodeSeeder:
    """Turns user seeds into the core's integer episode seeds, per environment.

    ``seed(seeds)`` with an integer ``s`` for environment b plays episode seed ``s`` on its
    next reset (the same episode the bench suites call seed ``s``) and seeds b's generator
    with ``s`` (Gymnasium's ``np_random(s)``); later resets draw the next episode seed from
    that generator. ``None`` keeps the generator (creating an unpredictable one if none
    exists). This is exactly what a single Gymnasium env does in ``reset(seed=...)``, so B
    environments seeded ``s, s+1, …`` reproduce the single envs with those seeds.

    Args:
        batch_size: B.
    """

    def __init__(self, batch_size: int):
        self.batch_size = batch_size
        self._rngs: list[np.random.Generator | None] = [None] * batch_size
        self._pending: list[int | None] = [None] * batch_size

    def seed(self, seeds: int | Sequence[int | None] | None, mask: np.ndarray | None = None) -> None:
        """Seed the environments (those in ``mask`` only, if given).

        ``int`` s → environment b gets ``s + b``; a sequence → one seed (or None) per
        environment; ``None`` → keep the generators.
        """
        if seeds is None:
            seeds = [None] * self.batch_size
        elif isinstance(seeds, (int, np.integer)):
            seeds = [int(seeds) + b for b in range(self.batch_size)]
        seeds = list(seeds)
        if len(seeds) != self.batch_size:
            raise ValueError(f"expected {self.batch_size} seeds (one per environment), got {len(seeds)}")
        for b, s in enumerate(seeds):
            if s is None or (mask is not None and not mask[b]):
                continue
            if not isinstance(s, (int, np.integer)) or not 0 <= int(s) < SEED_BOUND:
                raise ValueError(f"seed for environment {b} must be an integer in [0, 2**63 - 1), got {s!r}")
            self._rngs[b], _ = seeding.np_random(int(s))
            self._pending[b] = int(s)

    def draw(self, index: np.ndarray | Sequence[int] | None = None) -> np.ndarray:
        """Episode seeds ``(B,)`` for the environments in ``index`` (others are 0, unused)."""
        out = np.zeros(self.batch_size, dtype=np.int64)
        for b in range(self.batch_size) if index is None else index:
            b = int(b)
            if self._pending[b] is not None:
                out[b], self._pending[b] = self._pending[b], None
                continue
            if self._rngs[b] is None:
                self._rngs[b], _ = seeding.np_random()
            out[b] = self._rngs[b].integers(0, SEED_BOUND)
        return out


class TrustEnvBatch:
    """B link-trust environments of one task: observation, standard reward, state.

    Args:
        spec: the task.
        batch_size: B.
        reward_weights: λ and constants of the standard reward (default: standard v0).
        policy_flops: FLOPs the method spends per UAV per step; added to the filter's
            FLOPs in the delay and energy terms (default 0).
        policy_flops_per_channel: FLOPs the method spends per present channel of the
            update (a method's declared ``flops_per_channel``; default 0).
        processor: processor profile converting FLOPs to seconds and joules.

    This is the one place where a Track A step is scored: every adapter and the bench's
    runner call :meth:`step`, so observation, reward, FLOPs and delay cannot drift apart.
    """

    def __init__(self, spec: TaskSpec, batch_size: int, *, reward_weights: RewardWeights = STANDARD_WEIGHTS,
                 policy_flops: float = 0.0, policy_flops_per_channel: float = 0.0,
                 processor: ProcessorProfile = DEFAULT_PROFILE):
        self.spec = spec
        self.batch_size = batch_size
        self.core = LinkTrustCore(spec, batch_size)
        self.layout = self.core.layout
        self.n_uav, self.n_channels = self.core.n_uav, self.core.n_channels
        self.reward_weights = reward_weights
        self.policy_flops = as_policy_flops(policy_flops)
        self.policy_flops_per_channel = as_policy_flops(policy_flops_per_channel)
        self.processor = processor
        self._one_hot = kind_one_hot(self.layout.kind)
        #: validates a batch of trust ``(B, N, L)`` (for callers without an adapter of their own)
        self.check = ActionChecker((batch_size, self.n_uav, self.n_channels), "(B, N, L)")
        self._last: CoreStep | None = None

    @classmethod
    def for_adapter(cls, spec: TaskSpec, batch_size: int, *,
                    reward_weights: RewardWeights | Mapping[str, float] | None = None, policy_flops: float = 0.0,
                    processor: ProcessorProfile | Mapping[str, Any] | None = None) -> TrustEnvBatch:
        """The batch an adapter wraps, from the adapter's own arguments: reward weights and processor as
        objects, mappings of their fields or None (the defaults), the policy FLOPs as a number; all validated
        (``as_reward_weights``, ``as_policy_flops``, ``as_processor``) before the core is built."""
        return cls(spec, batch_size, reward_weights=as_reward_weights(reward_weights),
                   policy_flops=as_policy_flops(policy_flops), processor=as_processor(processor))

    # ------------------------------------------------------------------ shapes
    @property
    def obs_shape(self) -> tuple[int, int, int]:
        """``(N, L, F)`` of one environment."""
        return self.n_uav, self.n_channels, N_FEATURES

    @property
    def state_size(self) -> int:
        """S: length of the global state (see ``state``)."""
        return self.n_uav * self.n_channels * N_FEATURES + 7 * self.n_uav

    def state_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """``(S,)`` lower and upper bounds of the global state (float32)."""
        n_obs = self.n_uav * self.n_channels * N_FEATURES
        low = np.full(self.state_size, -np.inf, dtype=np.float32)
        high = np.full(self.state_size, np.inf, dtype=np.float32)
        low[:n_obs], high[:n_obs] = 0.0, 1.0
        low[n_obs + 6 * self.n_uav:] = 0.0  # position std
        return low, high

    # ------------------------------------------------------------------ dynamics
    def reset(self, seeds: np.ndarray, mask: np.ndarray | None = None) -> CoreStep:
        """Start the episodes in ``mask`` (all if None) with integer ``seeds`` ``(B,)``."""
        self._last = self.core.reset(seeds, mask)
        return self._last

    def step(self, trust: np.ndarray) -> tuple[CoreStep, RewardTerms]:
        """Apply validated trust ``(B, N, L)`` in [0, 1] and score the update it made.

        Args:
            trust: trust already validated once (by :attr:`check` or an adapter's checker).

        Returns:
            The core step and the reward terms ``(B, N)`` of the update just done: its
            channels' validity, its applied and previous trust, its FLOPs (filter +
            policy, per UAV plus per present channel).
        """
        o = self.core.step(trust)
        terms = standard_reward(o.estimate, o.truth, o.applied, o.prev_trust, o.update_valid,
                                self.spec.filter.alpha_th, o.flops, self.policy_flops, self.reward_weights, self.processor,
                                self.policy_flops_per_channel)
        self._last = o
        return o, terms

    # ------------------------------------------------------------------ outputs
    @property
    def last(self) -> CoreStep:
        """The ``CoreStep`` of the last ``reset``/``step`` (pending features, last update's results)."""
        if self._last is None:
            raise RuntimeError("call reset() before reading the environments' state")
        return self._last

    def pending_labels(self) -> np.ndarray:
        """``(B, N, L)`` injected-fault labels of the pending measurements (privileged: the detection metrics')."""
        return self.core.world.buffers.label

    def pending_error_labels(self) -> np.ndarray:
        """``(B, N, L)`` error labels of the pending measurements (``labels.py``; privileged: the oracle's)."""
        return self.core.pending_error_label

    def pending_systematic_sigmas(self) -> np.ndarray:
        """``(B, N, L)`` the pending measurements' systematic error in units of σ_eff (privileged)."""
        return self.core.pending_systematic_sigmas

    def observation(self, out: np.ndarray | None = None) -> np.ndarray:
        """Observation ``(B, N, L, F)`` float32 in [0, 1] of the pending step (a new array unless ``out``)."""
        return build_observation(self.last, self._one_hot, out)

    def position_error(self) -> np.ndarray:
        """``(B, N)`` ‖p̂ − p‖ of the last update [m] (the prior mean after reset)."""
        o = self.last
        d = o.estimate - o.truth
        return np.sqrt((d * d).sum(axis=-1))

    def state(self, obs: np.ndarray) -> np.ndarray:
        """Global state ``(B, S)`` float32 for centralized critics.

        Layout: the whole swarm's observation ``obs`` flattened (N·L·F, in [0, 1]), then
        every UAV's prior mean position (N·3) [m] and velocity (N·3) [m/s] at the pending
        step, then every UAV's prior position std √tr(P_pp) (N) [m]. No truth and no fault
        labels: everything here is known to the swarm's filters.
        """
        return build_state(obs, self.core.x, self.core.P, np.empty((self.batch_size, self.state_size), dtype=np.float32))

    def observation_and_state(self) -> tuple[np.ndarray, np.ndarray]:
        """``observation()`` and its ``state`` in one pass (new arrays)."""
        return build_observation_and_state(self.last, self._one_hot, self.core.x, self.core.P, self.state_size)

    def team_reward(self, terms: RewardTerms) -> np.ndarray:
        """``(B,)`` team reward: the mean over UAVs of the standard reward."""
        return team_reward(terms)

    def info_arrays(self, terms: RewardTerms) -> dict[str, np.ndarray]:
        """Per-UAV info ``(B, N)`` arrays (new arrays): ``INFO_KEYS``."""
        info = {"uav_reward": terms.reward}
        for name in REWARD_TERMS:
            info[name] = getattr(terms, name)
        info["position_error"] = self.position_error()
        return info
