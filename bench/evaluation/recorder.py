"""Per-episode recording while B episodes of one task run: what the metrics need.

``EpisodeRecorder.record`` is called once per filter update with the batched estimate,
truth, channel validity, fault labels, applied trust and FLOPs; ``episode_metrics(b)``
then evaluates every metric of ``swarmloc.bench.scoring.metrics`` for episode b. Only
``(T, B, N)`` errors and streaming channel sums are kept, never ``(T, B, N, L)`` arrays.
``MetricsObserver`` feeds a recorder from the episode loop (``episode.fly_episodes``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from swarmloc.bench.evaluation import selection
from swarmloc.bench.evaluation.alignment import align_estimates
from swarmloc.bench.evaluation.episode import EpisodeBatch, StepRecord
from swarmloc.bench.evaluation.traces import Trace
from swarmloc.bench.scoring import metrics as M
from swarmloc.envs.tasks.specs import TaskSpec
from swarmloc.envs.world.reward import RewardTerms, team_reward
from swarmloc.envs.world.reward_kernel import standard_reward


class EpisodeRecorder:
    """Collects what the metrics need while B episodes of one task run.

    Args:
        spec: the task; seeds: ``(B,)``; schedule: the world's fault schedule (None for a
            world without one, e.g. a recorded flight).
        with_trust: the method exposes the trust it applied.
        with_flops: the method reports FLOPs.
        trace: keep a per-step record of episode 0.
    """

    def __init__(self, spec: TaskSpec, seeds: np.ndarray, schedule: Any, n_channels: int,
                 with_trust: bool, with_flops: bool, trace: bool) -> None:
        n_t, n_b, n = spec.n_steps, len(seeds), spec.n_uav
        self.spec, self.seeds, self.schedule = spec, seeds, schedule
        self.times = selection.step_times(spec)
        self.scored_steps = selection.scored_steps(spec)
        #: (B, N) the UAVs each episode scores (the same row in every episode unless the scored set is per episode)
        self.nodes = selection.scored_node_masks(spec, schedule, n_b)
        self.node_groups = M.node_groups(self.nodes)
        self.errors = np.zeros((n_t, n_b, n))
        # anchor-free tasks are scored after a yaw + translation alignment (bench/evaluation/alignment.py),
        # which needs the whole episode: keep the positions and align once at the end
        self.align = spec.scoring.align_first_seconds > 0
        self._positions = (np.zeros((n_t, n_b, n, 3)), np.zeros((n_t, n_b, n, 3))) if self.align else None
        self.team = np.zeros((n_t, n_b))
        self.delay_ms = np.zeros(n_b)
        self.energy_j = np.zeros(n_b)
        self.label_steps = np.zeros((n_t, n_b), dtype=bool)
        self.with_trust, self.with_flops = with_trust, with_flops
        self.stats = M.ChannelStats(n_b, self.nodes) if with_trust else None
        self.trace = None
        if trace:
            self.trace = {"estimate": np.zeros((n_t, n, 3)), "truth": np.zeros((n_t, n, 3)),
                          "applied": np.ones((n_t, n, n_channels), dtype=np.float32) if with_trust else None,
                          "valid": np.zeros((n_t, n, n_channels), dtype=bool),
                          "label": np.zeros((n_t, n, n_channels), dtype=bool)}

    def record(self, k: int, estimate: np.ndarray, truth: np.ndarray, valid: np.ndarray, label: np.ndarray,
               applied: np.ndarray | None, previous: np.ndarray | None, flops: np.ndarray | None,
               terms: RewardTerms | None = None) -> None:
        """Record update k (0-based) of every episode (``(B, N, ...)`` arrays).

        Args:
            k: the update's index.
            estimate, truth: ``(B, N, 3)`` positions.
            valid: ``(B, N, L)`` measurements present in this update.
            label: ``(B, N, L)`` their fault labels.
            applied, previous: ``(B, N, L)`` trust applied now and before (None: not exposed).
            flops: ``(B, N)`` total FLOPs of the step (None: not reported).
            terms: the reward terms of this update as the env scored it (Track A); None for
                an estimator (Track B), whose reward is computed here from the same
                ``standard_reward``.
        """
        s = self.spec
        self.errors[k] = M.position_errors(estimate, truth)
        if self._positions is not None:
            self._positions[0][k], self._positions[1][k] = estimate, truth
        self.label_steps[k] = (label & self.nodes[:, :, None]).any(axis=(1, 2))
        if terms is None:
            # the reward counts every valid channel as used when the method exposes no trust
            a = applied if applied is not None else np.ones(valid.shape)
            p = previous if previous is not None else a
            terms = standard_reward(estimate, truth, a, p, valid, s.filter.alpha_th,
                                    flops if flops is not None else np.zeros(estimate.shape[:2]))
        self.team[k] = team_reward(terms)
        if self.scored_steps[k]:
            if flops is not None:
                # a boolean-masked (B, nodes) copy is not C-contiguous for B > 1, and numpy would sum it in
                # another order than for B = 1: an episode's metrics must not depend on its batch
                for idx, nodes in self.node_groups:
                    rows = slice(None) if len(idx) == len(self.seeds) else idx
                    self.delay_ms[rows] += np.ascontiguousarray(terms.delay_ms[rows][:, nodes]).mean(axis=1)
                    self.energy_j[rows] += np.ascontiguousarray(terms.energy_j[rows][:, nodes]).mean(axis=1)
            if self.stats is not None and applied is not None and previous is not None:
                self.stats.add(applied, previous, valid, label)
        if self.trace is not None:
            tr = self.trace
            tr["estimate"][k], tr["truth"][k] = estimate[0], truth[0]
            tr["valid"][k], tr["label"][k] = valid[0], label[0]
            if tr["applied"] is not None and applied is not None:
                tr["applied"][k] = applied[0]

    def _recovery(self, b: int) -> tuple[float, float] | None:
        """``(recovery_s, recovered)`` of episode b, or None without an IMU fault that ends inside it.

        The threshold's healthy level is the RMSE of the UAVs without an IMU fault over the
        scored steps before the first fault starts: the accuracy the swarm had before the
        fault (during and after it the healthy UAVs may be dragged off too).
        """
        ends = selection.imu_fault_ends(self.schedule, b, self.spec.n_uav)
        if not np.isfinite(ends).any():
            return None
        healthy = ~np.isfinite(ends)
        before = self.scored_steps & (self.times < float(self.schedule.imu_fault_span()[b][0]) - 1e-9)
        level = M.rmse(self.errors[before, b][:, healthy]) if healthy.any() and before.any() else None
        return M.recovery(self.errors[:, b], self.times, ends, M.recovery_threshold(level))

    def _apply_alignment(self) -> None:
        """Replace the errors by those after the task's scoring alignment (once, at the end)."""
        if self._positions is not None:
            estimate, truth = self._positions
            self.errors = M.position_errors(align_estimates(self.spec, self.times, estimate, truth), truth)
            self._positions = None

    def episode_metrics(self, b: int) -> dict[str, float | None]:
        """Every metric of episode b except those against references (``uniform_rmse``, ``bound_rmse``:
        None here, filled in by the runner)."""
        self._apply_alignment()
        s = self.spec
        steps = self.scored_steps
        e = self.errors[steps][:, b][:, self.nodes[b]]
        if s.scoring.fault_window is not None:
            fault_steps = M.window_steps(self.times, s.scoring.fault_window)[steps]
        else:
            fault_steps = self.label_steps[steps, b]
        healthy = selection.healthy_selection(s, self.schedule, b)
        recovery = self._recovery(b)
        n_scored = max(int(steps.sum()), 1)
        out: dict[str, float | None] = {
            "rmse": M.rmse(e),
            "mean_error": M.mean_error(e),
            "median_error": M.median_error(e),
            "max_error": M.max_error(e),
            "cep90": M.cep90(e),
            "fault_rmse": M.fault_rmse(e, fault_steps),
            "healthy_rmse": None if healthy is None else M.healthy_rmse(self.errors[:, b], *healthy),
            "diverged": M.diverged(e),
            "delay_ms": float(self.delay_ms[b] / n_scored) if self.with_flops else None,
            "energy_j": float(self.energy_j[b]) if self.with_flops else None,
            "jitter": self.stats.jitter(b) if self.stats is not None else None,
            "weight_var": self.stats.weight_var(b) if self.stats is not None else None,
            "anomaly_detection_rate": self.stats.anomaly_detection_rate(b) if self.stats is not None else None,
            "team_return": M.team_return(self.team[:, b]),
            "uniform_rmse": None,
            "bound_rmse": None,
            "recovery_s": None if recovery is None else recovery[0],
            "recovered": None if recovery is None else recovery[1],
        }
        return out

    def make_trace(self, method: str, layout_kind: np.ndarray) -> Trace | None:
        """The trace of episode 0 (None if not kept)."""
        if self.trace is None:
            return None
        window = self.spec.scoring.fault_window
        if window is None and self.spec.faults.imu_cascade_random is not None and self.schedule is not None:
            window = tuple(self.schedule.imu_fault_span()[0])
        return Trace(method=method, task=self.spec.task_id, seed=int(self.seeds[0]), times=self.times.copy(),
                     kind=np.asarray(layout_kind), scored=self.nodes[0].copy(),
                     fault_window=np.array(window if window is not None else (np.nan, np.nan), dtype=float),
                     **self.trace)


class MetricsObserver:
    """The runner's observer of the episode loop: an ``EpisodeRecorder`` of the batch.

    The recorder is made at the first update, where an estimator's output tells whether
    it reports trust and FLOPs (a policy always does).

    Args:
        trace: keep a per-step record of episode 0.
    """

    def __init__(self, trace: bool = False) -> None:
        self.trace = trace
        self.batch: EpisodeBatch | None = None
        self.recorder: EpisodeRecorder | None = None

    def begin(self, batch: EpisodeBatch) -> None:
        """Start recording ``batch`` (a new recorder at its first update)."""
        self.batch, self.recorder = batch, None

    def observe(self, r: StepRecord) -> None:
        """Record update ``r.k`` (``EpisodeRecorder.record``)."""
        rec = self.recorder
        if rec is None:
            b = self.batch
            assert b is not None, "begin() comes first"
            rec = self.recorder = EpisodeRecorder(b.spec, b.seeds, b.schedule, b.layout.n_channels,
                                                  r.applied is not None, r.flops is not None, self.trace)
        rec.record(r.k, r.estimate, r.truth, r.valid, r.label, r.applied, r.previous, r.flops, r.terms)

    def episode_metrics(self) -> list[dict[str, float | None]]:
        """Every episode's metrics, in seed order (``EpisodeRecorder.episode_metrics``)."""
        assert self.recorder is not None and self.batch is not None, "no update recorded"
        return [self.recorder.episode_metrics(b) for b in range(len(self.batch.seeds))]

    def make_trace(self) -> Trace | None:
        """The trace of episode 0 (None if not kept)."""
        assert self.recorder is not None and self.batch is not None, "no update recorded"
        return self.recorder.make_trace(self.batch.method, self.batch.layout.kind)
