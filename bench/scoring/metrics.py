"""Per-episode metrics (docs/scoring.md): small pure functions, one per metric.

Every metric is computed on the episode's *scored nodes* (``spec.scored_nodes``; with
``scoring.nodes_from_schedule="healthy"`` only those the episode's fault schedule leaves
without an IMU fault, ``swarmloc.bench.evaluation.selection``) and *scored interval* (steps
with ``t ≥ spec.scoring.start``), from the position error e = ‖p̂ − p‖ [m] of every scored
UAV at every filter update k = 1 … T (t = k·dt); ``healthy_rmse``, ``recovery_s`` and
``recovered`` select their own UAVs, as stated:

| metric | definition |
|---|---|
| ``rmse`` | √mean(e²) |
| ``mean_error`` / ``median_error`` / ``max_error`` | mean / median / max of e |
| ``cep90`` | 90th percentile of the 3-D error (spherical error probable, 90 %) |
| ``fault_rmse`` | RMSE inside ``scoring.fault_window``; if the task defines none, over the steps where any scored UAV has a labelled channel; null if there are none |
| ``healthy_rmse`` | RMSE of the healthy nodes during the fault: ``scoring.healthy_nodes`` inside the fault window, or, for a randomised IMU cascade, the UAVs the episode's schedule leaves healthy inside its fault span; null where the task defines neither |
| ``recovery_s`` | for the episode's faulty UAVs (whatever is scored): time [s] from the end of a UAV's IMU fault to the first step from which its error stays ≤ max(3 × RMSE of the UAVs without an IMU fault over the scored steps before the fault, 1 m) to the end of the episode; the slowest faulty UAV's. Never recovered: censored at the episode's end (t_last − fault end), so the mean is the restricted mean recovery time; null without an IMU fault (or one that ends with the episode) |
| ``recovered`` | 1.0 if every faulty UAV recovered (``recovery_s`` not censored), else 0.0 (the mean is the fraction recovered); null where ``recovery_s`` is |
| ``diverged`` | 1.0 if e > 10 m at any step, else 0.0 |
| ``delay_ms`` | mean compute time per UAV-step [ms] on the processor profile (filter + method FLOPs); the schema has one field, so the mean |
| ``energy_j`` | energy per UAV over the episode [J] (sum over steps, mean over UAVs) |
| ``jitter`` | mean \\|α(k) − α(k−1)\\| over valid channel-steps (α(0) = 1) |
| ``weight_var`` | variance of the applied α over valid channel-steps |
| ``anomaly_detection_rate`` | fraction of labelled channel-steps whose applied α < 0.5 (the method at least halved its trust: R inflated ≥ 2×; α ≤ α_th, skipping the channel, is included); dtvirm Table 6 "detected / abnormal"; null without labels |
| ``team_return`` | Σ over all steps of the team standard reward (mean over all UAVs) |

On a task with ``scoring.align_first_seconds > 0`` (anchor-free: absolute translation and
yaw are unobservable), e is measured after the yaw + translation that aligns the first
seconds of the scored interval with the truth (``swarmloc.bench.evaluation.alignment``), applied to
the whole episode.

Trust metrics need the trust the method applied; for a Track B estimator that reports no
``weights`` they are null. ``delay_ms``/``energy_j`` are null for an estimator that
reports no FLOPs.
"""

from __future__ import annotations

import numpy as np


#: an error above this at any time marks the episode diverged [m]
DIVERGENCE_M = 10.0
#: a labelled channel-step counts as detected when its applied trust is below this
DETECTION_TRUST = 0.5
#: percentile of the error reported as CEP90
CEP_PERCENTILE = 90.0
#: a faulty UAV has recovered once its error stays within this many times the healthy UAVs' RMSE …
RECOVERY_FACTOR = 3.0
#: … or within this floor [m], whichever is larger (a healthy swarm at centimetres is not the bar)
RECOVERY_FLOOR_M = 1.0


def position_errors(estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Euclidean position error ‖p̂ − p‖ over the last axis.

    Args:
        estimate, truth: ``(..., 3)`` positions [m].

    Returns:
        ``(...)`` errors [m].
    """
    return np.sqrt(np.sum((np.asarray(estimate) - np.asarray(truth)) ** 2, axis=-1))


def _values(errors: np.ndarray) -> np.ndarray:
    e = np.asarray(errors, dtype=np.float64).ravel()
    if e.size == 0:
        raise ValueError("no error samples: the scored nodes and interval select nothing")
    return e


def rmse(errors: np.ndarray) -> float:
    """Root mean square of the errors (any shape, at least one element)."""
    e = _values(errors)
    return float(np.sqrt(np.mean(e * e)))


def mean_error(errors: np.ndarray) -> float:
    """Mean of the errors."""
    return float(np.mean(_values(errors)))


def median_error(errors: np.ndarray) -> float:
    """Median of the errors."""
    return float(np.median(_values(errors)))


def max_error(errors: np.ndarray) -> float:
    """Largest error."""
    return float(np.max(_values(errors)))


def cep90(errors: np.ndarray) -> float:
    """90th percentile of the 3-D errors (numpy's linear interpolation)."""
    return float(np.percentile(_values(errors), CEP_PERCENTILE))


def window_steps(times: np.ndarray, window: tuple[float, float] | None) -> np.ndarray:
    """Steps inside a half-open time window ``start ≤ t < end``.

    Args:
        times: ``(T,)`` step times [s].
        window: ``(start, end)``, or None (no step).

    Returns:
        ``(T,)`` bool.
    """
    times = np.asarray(times, dtype=np.float64)
    if window is None or not np.all(np.isfinite(window)):
        return np.zeros(times.shape, dtype=bool)
    # a tolerance of a micro-step keeps k·dt == start inside despite rounding
    eps = 1e-9
    return (times >= window[0] - eps) & (times < window[1] - eps)


def fault_rmse(errors: np.ndarray, fault_steps: np.ndarray) -> float | None:
    """RMSE over the fault steps.

    Args:
        errors: ``(T, N)`` errors of the scored nodes over the scored interval.
        fault_steps: ``(T,)`` bool, the steps that count as "during the fault".

    Returns:
        The RMSE, or None when no step is a fault step.
    """
    fault_steps = np.asarray(fault_steps, dtype=bool)
    if not fault_steps.any():
        return None
    return rmse(np.asarray(errors)[fault_steps])


def healthy_rmse(errors: np.ndarray, healthy: np.ndarray, steps: np.ndarray) -> float | None:
    """RMSE of the healthy nodes over some steps.

    Args:
        errors: ``(T, N)`` errors of all UAVs.
        healthy: ``(N,)`` bool, the healthy UAVs.
        steps: ``(T,)`` bool, the steps to score.

    Returns:
        The RMSE, or None when no node or no step is selected.
    """
    healthy = np.asarray(healthy, dtype=bool)
    steps = np.asarray(steps, dtype=bool)
    if not healthy.any() or not steps.any():
        return None
    return rmse(np.asarray(errors)[steps][:, healthy])


def recovery_threshold(healthy_level: float | None, factor: float = RECOVERY_FACTOR,
                       floor: float = RECOVERY_FLOOR_M) -> float:
    """The error [m] a faulty UAV must get back within: max(factor × healthy_level, floor).

    Args:
        healthy_level: RMSE of the episode's healthy UAVs [m] (None or not finite: the floor alone).
        factor, floor: the rule's constants.
    """
    if healthy_level is None or not np.isfinite(healthy_level):
        return float(floor)
    return float(max(factor * healthy_level, floor))


def recovery_time(errors: np.ndarray, times: np.ndarray, fault_end: float,
                  threshold: float) -> tuple[float, bool] | None:
    """Time from a UAV's fault end until its error is within ``threshold`` for good.

    Over the steps at or after the fault end (t ≥ ``fault_end``), the recovery step is the
    first one from which every error is ≤ ``threshold`` to the end of the episode; the
    time is its t − ``fault_end``. A UAV whose last error is above the threshold (or not
    finite) never recovered: its time is censored at the episode's end, t_last − fault_end.

    Args:
        errors: ``(T,)`` one UAV's errors [m]; times: ``(T,)`` their step times [s].
        fault_end: end of the UAV's IMU fault [s].
        threshold: the recovery threshold [m].

    Returns:
        ``(seconds, recovered)``, or None when no step is at or after the fault end.
    """
    times = np.asarray(times, dtype=np.float64)
    after = times >= fault_end - 1e-9  # the same micro-step tolerance as window_steps
    if not after.any():
        return None
    t, e = times[after], np.asarray(errors, dtype=np.float64)[after]
    # "not within" rather than "above", so a NaN error counts as not recovered
    out = np.flatnonzero(~(e <= threshold))
    if out.size == 0:
        return float(t[0] - fault_end), True
    if out[-1] == e.size - 1:
        return float(t[-1] - fault_end), False
    return float(t[out[-1] + 1] - fault_end), True


def recovery(errors: np.ndarray, times: np.ndarray, fault_ends: np.ndarray,
             threshold: float) -> tuple[float, float] | None:
    """``recovery_s`` and ``recovered`` of one episode: the slowest of its faulty UAVs.

    Args:
        errors: ``(T, N)`` errors of every UAV; times: ``(T,)`` step times [s].
        fault_ends: ``(N,)`` end of each UAV's IMU fault [s], NaN for a UAV without one.
        threshold: the recovery threshold [m] (:func:`recovery_threshold`).

    Returns:
        ``(max over faulty UAVs of their recovery time, 1.0 if all recovered else 0.0)``, or
        None when no UAV has an IMU fault that ends before the episode does.
    """
    errors = np.asarray(errors)
    found = [recovery_time(errors[:, i], times, float(end), threshold)
             for i, end in enumerate(np.asarray(fault_ends, dtype=np.float64)) if np.isfinite(end)]
    found = [r for r in found if r is not None]
    if not found:
        return None
    return max(r[0] for r in found), float(all(r[1] for r in found))


def diverged(errors: np.ndarray, threshold: float = DIVERGENCE_M) -> float:
    """1.0 if any error exceeds ``threshold`` [m] (or is not finite), else 0.0."""
    e = _values(errors)
    return float(bool(np.any(~np.isfinite(e)) or np.any(e > threshold)))


def jitter(applied: np.ndarray, previous: np.ndarray, valid: np.ndarray) -> float | None:
    """Mean |α(k) − α(k−1)| over the valid channel-steps.

    Args:
        applied: ``(..., L)`` trust applied at each step.
        previous: same shape, trust applied at the step before.
        valid: same shape, measurement present.

    Returns:
        The mean, or None without valid channel-steps.
    """
    valid = np.asarray(valid, dtype=bool)
    if not valid.any():
        return None
    return float(np.abs(np.asarray(applied) - np.asarray(previous))[valid].mean())


def weight_var(applied: np.ndarray, valid: np.ndarray) -> float | None:
    """Population variance of the applied trust over the valid channel-steps (None if none)."""
    valid = np.asarray(valid, dtype=bool)
    if not valid.any():
        return None
    return float(np.var(np.asarray(applied)[valid]))


def anomaly_detection_rate(applied: np.ndarray, label: np.ndarray,
                           threshold: float = DETECTION_TRUST) -> float | None:
    """Fraction of labelled channel-steps whose applied trust is below ``threshold``.

    Args:
        applied: ``(..., L)`` trust applied.
        label: same shape, ground-truth fault label (only valid channels are labelled).
        threshold: detection threshold on α.

    Returns:
        The rate in [0, 1], or None without labelled channel-steps.
    """
    label = np.asarray(label, dtype=bool)
    if not label.any():
        return None
    return float(np.mean(np.asarray(applied)[label] < threshold))


def team_return(team_rewards: np.ndarray) -> float:
    """Sum over steps of the team reward ``(T,)``."""
    return float(np.sum(np.asarray(team_rewards, dtype=np.float64)))


def node_groups(nodes: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Episodes that score the same UAVs, to be reduced together.

    Args:
        nodes: ``(B, N)`` bool, each episode's scored UAVs.

    Returns:
        ``[(episode indices, (N,) mask)]``, one entry per distinct row of ``nodes``.
    """
    masks, which = np.unique(np.asarray(nodes, dtype=bool), axis=0, return_inverse=True)
    return [(np.flatnonzero(which.ravel() == g), mask) for g, mask in enumerate(masks)]


class ChannelStats:
    """Streaming sums behind ``jitter``, ``weight_var`` and ``anomaly_detection_rate``.

    The runner cannot keep ``(T, B, N, L)`` trust arrays for large swarms, so it adds each
    step's sums per episode; :meth:`jitter`, :meth:`weight_var` and
    :meth:`anomaly_detection_rate` then equal the pure functions above on the stacked
    arrays (tested).

    Steps are buffered (at most ``BUFFER_VALUES`` values per array) and reduced a block at a
    time: each step's per-episode sum is still taken along the contiguous last axis of that
    step's ``(N_scored·L)`` values and added to the running sums in step order, so the
    numbers are those of adding the steps one by one, bit for bit, at a fraction of the
    per-step cost.

    Args:
        batch_size: B.
        nodes: ``(N,)`` bool, the scored UAVs, or ``(B, N)``, each episode's own
            (``scoring.nodes_from_schedule="healthy"``).
    """

    #: values per buffered array (8 MB of float64)
    BUFFER_VALUES = 2**20

    def __init__(self, batch_size: int, nodes: np.ndarray) -> None:
        nodes = np.asarray(nodes, dtype=bool)
        self.nodes = np.broadcast_to(nodes, (batch_size, nodes.shape[-1]))
        self.groups = node_groups(self.nodes)
        z = lambda: np.zeros(batch_size)  # noqa: E731
        self.n_valid, self.abs_delta, self.alpha_sum, self.alpha_sq = z(), z(), z(), z()
        self.n_label, self.n_detected = z(), z()
        # variance sums are taken around a per-episode shift (the first step's mean trust),
        # so a constant trust gives exactly 0 and no cancellation creeps in
        self.shift = np.full(batch_size, np.nan)
        self._pending: list[list[tuple[np.ndarray, ...]]] = [[] for _ in self.groups]

    def add(self, applied: np.ndarray, previous: np.ndarray, valid: np.ndarray, label: np.ndarray) -> None:
        """Add one step (``(B, N, L)`` arrays) of the scored interval."""
        n_b = applied.shape[0]
        for g, (idx, nodes) in enumerate(self.groups):
            rows = slice(None) if len(idx) == n_b else idx
            # boolean indexing copies: the caller's arrays may change in place from step to step
            step = tuple(np.asarray(x[rows][:, nodes]).reshape(len(idx), -1) for x in (applied, previous, valid, label))
            self._pending[g].append(step)
            if len(self._pending[g]) * step[0].size >= self.BUFFER_VALUES:
                self._flush_group(g)

    def _flush(self) -> None:
        for g in range(len(self.groups)):
            self._flush_group(g)

    def _flush_group(self, g: int) -> None:
        """Reduce group g's buffered steps into the running sums."""
        steps = self._pending[g]
        if not steps:
            return
        self._pending[g] = []
        idx = self.groups[g][0]
        rows = slice(None) if len(idx) == len(self.shift) else idx
        # (C, B_rows, N_scored·L) blocks; every reduction below runs along the contiguous last axis
        a, p, m, label = (np.stack(x) for x in zip(*steps))
        lab = label & m
        count = m.sum(axis=2)
        shift = self.shift[rows]
        # an episode's shift is its mean trust at its first step with a valid channel (0 before that step,
        # where every term below is 0 anyway)
        starts = np.isnan(shift) & (count > 0).any(axis=0)
        first = np.argmax(count > 0, axis=0)
        mean_trust = (a * m).sum(axis=2)
        cols = np.flatnonzero(starts)
        shift[cols] = mean_trust[first[cols], cols] / count[first[cols], cols]
        self.shift[rows] = shift
        shifts = np.where(np.isnan(shift)[None, :] | (np.arange(len(steps))[:, None] < np.where(starts, first, 0)),
                          0.0, np.nan_to_num(shift)[None, :])
        d = a - shifts[:, :, None]
        per_step = {
            "n_valid": count,
            "abs_delta": (np.abs(a - p) * m).sum(axis=2),
            "alpha_sum": (d * m).sum(axis=2),
            "alpha_sq": (d * d * m).sum(axis=2),
            "n_label": lab.sum(axis=2),
            "n_detected": ((a < DETECTION_TRUST) & lab).sum(axis=2),
        }
        for name, values in per_step.items():
            total = getattr(self, name)
            # the running sum first, then each step in order: the same additions as one step at a time
            total[rows] = np.cumsum(np.vstack([total[rows][None, :], values]), axis=0)[-1]

    def jitter(self, b: int) -> float | None:
        """Episode b's jitter (None without valid channel-steps)."""
        self._flush()
        return float(self.abs_delta[b] / self.n_valid[b]) if self.n_valid[b] > 0 else None

    def weight_var(self, b: int) -> float | None:
        """Episode b's trust variance (None without valid channel-steps)."""
        self._flush()
        n = self.n_valid[b]
        if n <= 0:
            return None
        mean = self.alpha_sum[b] / n
        # Var = E[d²] − E[d]² with d = α − shift (shift-invariant)
        return float(max(self.alpha_sq[b] / n - mean * mean, 0.0))

    def anomaly_detection_rate(self, b: int) -> float | None:
        """Episode b's detection rate (None without labelled channel-steps)."""
        self._flush()
        return float(self.n_detected[b] / self.n_label[b]) if self.n_label[b] > 0 else None
