"""One recorded Track A episode: what the method saw and did at every step, and how it went.

``replay(method, spec, seeds)`` steps ``swarmloc.envs.adapters.trust_env.TrustEnvBatch`` (the same
batched environment every adapter wraps) with a Track A method and keeps, per step, the
``TrustInput`` the method was given, the trust it returned, the fault labels of the
measurements and the position errors of the update. An explainer re-reads the inputs
(:meth:`Episode.inputs`) to probe the method off the recorded path; labels and errors
are for the analysis only, never shown to a method.

Shapes: T steps, B episodes, N UAVs, L channels, F features.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from swarmloc.agents.protocols import TrustInput, episode_keys
from swarmloc.agents.registry import LoadedMethod, load_method
from swarmloc.bench.evaluation.selection import scored_node_masks
from swarmloc.envs.tasks.channels import ChannelLayout
from swarmloc.envs.world.observation import N_FEATURES
from swarmloc.envs.tasks.specs import TaskSpec
from swarmloc.envs.adapters.trust_env import TrustEnvBatch
from swarmloc.envs.world.sim import validate_seeds


@dataclass(frozen=True)
class Episode:
    """A recorded batch of Track A episodes of one task.

    Attributes:
        spec: the task (with any overrides, e.g. a shorter duration).
        seeds: ``(B,)`` episode seeds.
        layout: the task's channel layout.
        method: name of the method that flew it.
        times: ``(T,)`` time of each update [s] (k·dt, k = 1 … T).
        obs: ``(T, B, N, L, F)`` float32 features the method saw.
        resid, pred, nis, applied: ``(T, B, N, L)`` raw fields of its ``TrustInput``.
        jerk: ``(T, B, N)`` IMU jerk [m/s²].
        valid: ``(T, B, N, L)`` measurement present.
        trust: ``(T, B, N, L)`` trust the method returned (clipped to [0, 1], as applied).
        label: ``(T, B, N, L)`` fault labels of the measurements (analysis only).
        error: ``(T, B, N)`` position error ‖p̂ − p‖ after each update [m].
        scored: ``(B, N)`` the UAVs each episode scores (per episode where the task scores
            each episode's healthy UAVs; ``swarmloc.bench.evaluation.selection``).
    """

    spec: TaskSpec
    seeds: np.ndarray
    layout: ChannelLayout
    method: str
    times: np.ndarray
    obs: np.ndarray
    resid: np.ndarray
    pred: np.ndarray
    nis: np.ndarray
    applied: np.ndarray
    jerk: np.ndarray
    valid: np.ndarray
    trust: np.ndarray
    label: np.ndarray
    error: np.ndarray
    scored: np.ndarray

    @property
    def n_steps(self) -> int:
        """T."""
        return int(self.times.shape[0])

    @property
    def keys(self) -> np.ndarray:
        """``(B,)`` the per-episode method keys (``episode_keys(seeds)``)."""
        return episode_keys(self.seeds)

    def input(self, k: int) -> TrustInput:
        """The ``TrustInput`` of step index ``k`` (0-based; the update at t = (k + 1)·dt)."""
        return TrustInput.view(self.obs[k], self.resid[k], self.pred[k], self.nis[k], self.applied[k],
                               self.jerk[k], self.valid[k], float(self.times[k]), k + 1)

    def inputs(self) -> Iterator[TrustInput]:
        """The ``TrustInput`` of every step, in order."""
        for k in range(self.n_steps):
            yield self.input(k)


def as_loaded(method: str | LoadedMethod, version: int | None = None) -> LoadedMethod:
    """A ``LoadedMethod`` from a name (``load_method``, the shipped weights of benchmark ``version``) or as
    given; refuses what cannot be explained.

    Raises:
        ValueError: a Track B estimator (it sets no per-channel trust from features) or a
            privileged method (its trust follows the fault labels, not the features).
    """
    loaded = load_method(method, version=version) if isinstance(method, str) else method
    if loaded.track != "A":
        raise ValueError(f"{loaded.name} is a Track B estimator; explanations attribute the trust of "
                         f"Track A (link-trust) methods to their observation features")
    if loaded.privileged:
        raise ValueError(f"{loaded.name} is privileged: its trust follows the fault labels, not the "
                         f"observation features, so there is nothing to attribute")
    return loaded


def _checked_trust(alpha: Any, shape: tuple[int, ...], name: str) -> np.ndarray:
    alpha = np.asarray(alpha, dtype=np.float64)
    if alpha.shape != shape:
        raise ValueError(f"{name} returned trust of shape {alpha.shape}; expected (B, N, L) = {shape}")
    if not np.isfinite(alpha).all():
        bad = tuple(np.argwhere(~np.isfinite(alpha))[0].tolist())
        raise ValueError(f"{name} returned a non-finite trust {alpha[bad]} at index {bad}")
    return np.clip(alpha, 0.0, 1.0)


def replay(method: str | LoadedMethod, spec: TaskSpec, seeds: Sequence[int]) -> Episode:
    """Fly B episodes of ``spec`` with a Track A method and record them.

    Args:
        method: a registered name or entry point, or a fresh ``LoadedMethod`` (it is reset here).
        spec: the task.
        seeds: ``(B,)`` episode seeds.

    Returns:
        The recorded ``Episode``.
    """
    loaded = as_loaded(method, spec.version)
    seeds_arr = np.asarray(validate_seeds(list(seeds)), dtype=np.int64)
    n_b, n_t = len(seeds_arr), spec.n_steps
    env = TrustEnvBatch(spec, n_b)
    cs = env.reset(seeds_arr)
    layout = env.layout
    policy = loaded.method
    policy.reset(n_b, layout, episode_keys(seeds_arr))
    shape = (n_b, env.n_uav, env.n_channels)
    rec = {name: np.zeros((n_t, *shape)) for name in ("resid", "pred", "nis", "applied", "trust")}
    obs = np.zeros((n_t, *shape, N_FEATURES), dtype=np.float32)
    jerk = np.zeros((n_t, n_b, env.n_uav))
    valid = np.zeros((n_t, *shape), dtype=bool)
    label = np.zeros((n_t, *shape), dtype=bool)
    error = np.zeros((n_t, n_b, env.n_uav))
    times = (np.arange(n_t) + 1) * spec.dt
    for k in range(n_t):
        env.observation(out=obs[k])
        for name in ("resid", "pred", "nis", "applied"):
            rec[name][k] = getattr(cs, name)
        jerk[k], valid[k] = cs.jerk, cs.valid
        alpha = _checked_trust(policy.act(TrustInput.view(obs[k], rec["resid"][k], rec["pred"][k], rec["nis"][k],
                                                          rec["applied"][k], jerk[k], valid[k], times[k], k + 1)),
                               shape, loaded.name)
        rec["trust"][k] = alpha
        cs, _ = env.step(alpha)
        label[k] = cs.label
        error[k] = env.position_error()
    return Episode(spec=spec, seeds=seeds_arr, layout=layout, method=loaded.name, times=times, obs=obs,
                   resid=rec["resid"], pred=rec["pred"], nis=rec["nis"], applied=rec["applied"], jerk=jerk,
                   valid=valid, trust=rec["trust"], label=label, error=error,
                   scored=scored_node_masks(spec, getattr(env.core.world, "schedule", None), n_b))
