"""Aggregate statistics over seeds: mean, IQM, stratified bootstrap CIs.

Following rliable's recommendation (Agarwal et al., 2021) we report the mean and the
interquartile mean (IQM) of each metric over seeds, with a 95 % percentile-bootstrap
confidence interval of the mean. Across several tasks the bootstrap is *stratified*:
each resample draws seeds with replacement inside every task separately, so each task
keeps its number of runs. The draws and the interval are the package's one bootstrap
(``bootstrap.py``); runs are sorted by (task, seed) first, so the same episodes give the same
interval in any order. The score across tasks (log2 gain over uniform) is in ``score.py``.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Hashable, Iterable, Mapping, Sequence
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from swarmloc.bench.evaluation.results import METRIC_NAMES, Aggregate, Episode
from swarmloc.bench.scoring.bootstrap import (
    DEFAULT_CONFIDENCE,
    DEFAULT_RESAMPLES,
    DEFAULT_SEED,
    percentile_interval,
    stratified_draws,
)

Statistic = Literal["mean", "iqm"]


def _as_1d(values: ArrayLike) -> NDArray[np.float64]:
    x = np.asarray(values, dtype=np.float64)
    if x.ndim != 1:
        raise ValueError(f"expected a 1-D sequence of values, got shape {x.shape}")
    if x.size == 0:
        raise ValueError("expected at least one value, got an empty sequence")
    return x


def mean(values: ArrayLike) -> float:
    """Arithmetic mean of a non-empty 1-D sequence."""
    return float(np.mean(_as_1d(values)))


def iqm_along_last(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """IQM over the last axis of ``(..., n)`` values: drop ⌊n/4⌋ values from each end, average the rest."""
    n = x.shape[-1]
    cut = n // 4
    ordered = np.sort(x, axis=-1)
    return np.mean(ordered[..., cut : n - cut], axis=-1)


def iqm(values: ArrayLike) -> float:
    """Interquartile mean: the mean of the middle 50 % of the values.

    ⌊n/4⌋ values are dropped from each end of the sorted sequence (a 25 % trimmed
    mean), so for n < 4 it is the plain mean.

    Args:
        values: Non-empty 1-D sequence.

    Returns:
        The interquartile mean.
    """
    return float(iqm_along_last(_as_1d(values)))


def _apply(statistic: Statistic, samples: NDArray[np.float64]) -> NDArray[np.float64]:
    if statistic == "mean":
        return np.mean(samples, axis=-1)
    if statistic == "iqm":
        return iqm_along_last(samples)
    raise ValueError(f"unknown statistic {statistic!r}; allowed: 'mean', 'iqm'")


def bootstrap_ci(
    values: ArrayLike,
    strata: Sequence[Hashable] | None = None,
    *,
    statistic: Statistic = "mean",
    confidence: float = DEFAULT_CONFIDENCE,
    n_resamples: int = DEFAULT_RESAMPLES,
    seed: int = DEFAULT_SEED,
) -> tuple[float, float]:
    """Percentile bootstrap confidence interval, stratified when ``strata`` is given.

    Each resample draws, inside every stratum (task), as many values with replacement
    as the stratum holds, pools the draws, and applies ``statistic``. The interval is
    the ``(1 − confidence)/2`` and ``(1 + confidence)/2`` quantiles of the resampled
    statistic, clipped to the range of the data (which contains every resampled mean
    or IQM; the clip only removes floating-point rounding, so a constant gives exactly
    that constant).

    Args:
        values: Non-empty 1-D values (one per run).
        strata: Stratum label per value (e.g. the task ID); ``None`` = one stratum.
        statistic: ``"mean"`` or ``"iqm"``.
        confidence: In (0, 1).
        n_resamples: At least 1.
        seed: Seed of the numpy generator.

    Returns:
        ``(low, high)``.
    """
    x = _as_1d(values)
    labels: Sequence[Hashable] = [0] * x.size if strata is None else strata
    if len(labels) != x.size:
        raise ValueError(f"strata has {len(labels)} labels for {x.size} values; they must match")
    groups: dict[Hashable, list[int]] = defaultdict(list)
    for index, label in enumerate(labels):
        groups[label].append(index)
    ordered = [x[groups[label]] for label in sorted(groups, key=repr)]
    draws = stratified_draws([len(members) for members in ordered], n_resamples, seed)
    # (R, n): every stratum's resampled runs side by side, pooled for the statistic
    samples = np.concatenate([members[picks] for members, picks in zip(ordered, draws, strict=True)], axis=1)
    low, high = percentile_interval(_apply(statistic, samples), confidence)
    lo_data, hi_data = float(np.min(x)), float(np.max(x))
    return float(np.clip(low, lo_data, hi_data)), float(np.clip(high, lo_data, hi_data))


def summarize(
    values: ArrayLike,
    strata: Sequence[Hashable] | None = None,
    *,
    n_resamples: int = DEFAULT_RESAMPLES,
    seed: int = DEFAULT_SEED,
) -> Aggregate:
    """Mean, IQM and the 95 % (stratified) bootstrap CI of the mean of some runs."""
    x = _as_1d(values)
    low, high = bootstrap_ci(x, strata, n_resamples=n_resamples, seed=seed)
    return Aggregate(mean=mean(x), iqm=iqm(x), ci_low=low, ci_high=high)


def _episode_parts(episode: Episode | Mapping[str, Any]) -> tuple[str, int, Mapping[str, Any]]:
    if isinstance(episode, Episode):
        return episode.task, episode.seed, episode.metrics.model_dump()
    metrics = episode["metrics"]
    if not isinstance(metrics, Mapping):
        metrics = metrics.model_dump()
    return str(episode["task"]), int(episode["seed"]), metrics


def aggregate(
    episodes: Iterable[Episode | Mapping[str, Any]],
    *,
    n_resamples: int = DEFAULT_RESAMPLES,
    seed: int = DEFAULT_SEED,
) -> dict[str, dict[str, Aggregate | None]]:
    """Per-task aggregates of every metric over seeds, in the results-file shape.

    Args:
        episodes: ``Episode`` objects or dicts ``{"task", "seed", "metrics"}``.
        n_resamples: Bootstrap resamples per interval.
        seed: Bootstrap seed.

    Returns:
        ``{task: {metric: Aggregate | None}}`` for every task and every name in
        ``METRIC_NAMES``; ``None`` where no seed of the task defines the metric.
        Seeds whose value is ``None`` are left out of that metric's statistics.
    """
    by_task: dict[str, list[tuple[int, Mapping[str, Any]]]] = defaultdict(list)
    for episode in episodes:
        task, episode_seed, metrics = _episode_parts(episode)
        by_task[task].append((episode_seed, metrics))
    out: dict[str, dict[str, Aggregate | None]] = {}
    for task in sorted(by_task):
        runs = sorted(by_task[task], key=lambda item: item[0])
        out[task] = {}
        for name in METRIC_NAMES:
            values = [m[name] for _, m in runs if m.get(name) is not None]
            out[task][name] = (
                summarize(values, n_resamples=n_resamples, seed=seed) if values else None
            )
    return out


__all__ = [
    "aggregate",
    "bootstrap_ci",
    "iqm",
    "iqm_along_last",
    "mean",
    "summarize",
]
