"""One recorded Track A episode: what the method saw and did at every step, and how it went.

``replay(method, spec, seeds)`` flies a Track A method through the episode loop
(``swarmloc.bench.evaluation.episode``: ``TrustEnvBatch``, the same batched environment
every adapter wraps) and keeps, as an observer of every step, the
``TrustInput`` the method was given, the trust it returned, the fault labels of the
measurements and the position errors of the update. An explainer re-reads the inputs
(:meth:`Episode.inputs`) to probe the method off the recorded path; labels and errors
are for the analysis only, never shown to a method.

Shapes: T steps, B episodes, N UAVs, L channels, F features.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from swarmloc.agents.protocols import TrustInput, episode_keys
from swarmloc.agents.registry import LoadedMethod, load_method
from swarmloc.bench.evaluation.episode import EpisodeBatch, StepRecord, fly_episodes
from swarmloc.bench.evaluation.selection import scored_node_masks
from swarmloc.envs.tasks.channels import ChannelLayout
from swarmloc.envs.tasks.specs import TaskSpec
from swarmloc.envs.world.observation import N_FEATURES


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


class _Recording:
    """The episode loop's observer behind :func:`replay`: every step's features, trust, labels and errors."""

    wants_features = True

    def begin(self, batch: EpisodeBatch) -> None:
        n_t, n_b = batch.spec.n_steps, len(batch.seeds)
        shape = (n_b, batch.spec.n_uav, batch.layout.n_channels)
        self.batch = batch
        self.arrays = {name: np.zeros((n_t, *shape)) for name in ("resid", "pred", "nis", "applied", "trust")}
        self.arrays.update(obs=np.zeros((n_t, *shape, N_FEATURES), dtype=np.float32),
                           jerk=np.zeros((n_t, n_b, batch.spec.n_uav)), valid=np.zeros((n_t, *shape), dtype=bool),
                           label=np.zeros((n_t, *shape), dtype=bool), error=np.zeros((n_t, n_b, batch.spec.n_uav)))

    def observe(self, r: StepRecord) -> None:
        a, inp, k = self.arrays, r.features, r.k
        assert inp is not None  # wants_features
        for name in ("obs", "resid", "pred", "nis", "applied", "jerk", "valid"):
            a[name][k] = getattr(inp, name)
        a["trust"][k], a["label"][k] = r.trust, r.label
        # ‖p̂ − p‖, as TrustEnvBatch.position_error
        d = r.estimate - r.truth
        a["error"][k] = np.sqrt((d * d).sum(axis=-1))

    def episode(self) -> Episode:
        b, a = self.batch, self.arrays
        return Episode(spec=b.spec, seeds=b.seeds, layout=b.layout, method=b.method,
                       times=(np.arange(b.spec.n_steps) + 1) * b.spec.dt,
                       scored=scored_node_masks(b.spec, b.schedule, len(b.seeds)), **a)


def replay(method: str | LoadedMethod, spec: TaskSpec, seeds: Sequence[int]) -> Episode:
    """Fly B episodes of ``spec`` with a Track A method and record them (the episode loop, ``fly_episodes``).

    Args:
        method: a registered name or entry point, or a fresh ``LoadedMethod`` (it is reset here).
        spec: the task.
        seeds: ``(B,)`` episode seeds.

    Returns:
        The recorded ``Episode``.
    """
    recording = _Recording()
    fly_episodes(as_loaded(method, spec.version), spec, seeds, [recording])
    return recording.episode()
