"""The bootstrap: stratified resampling of seeds and the percentile interval.

Every confidence interval of the package comes from here: a task's aggregates
(``stats.bootstrap_ci``), the suite score's CI, the paired differences that rank the
leaderboard and compare two results files (``score``). Following rliable (Agarwal et al.,
2021; ``docs/references.md`` [rliable]) the bootstrap is *stratified*: a resample draws, in
every stratum (task) separately, as many runs with replacement as the stratum holds, so
every task keeps its number of runs. The statistic of each resample is the caller's (pooled
mean or IQM, mean of task means, a paired difference); the interval is the percentile one.

The draws depend only on the seed, the resample count and the strata sizes, never on the
values: one seeded numpy generator draws ``(n_resamples, n_t)`` indices for each stratum in
turn. Every metric of a task and every method of a suite therefore resamples the same rows
(what pairs two methods), and the same episodes give the same interval in any run.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

DEFAULT_RESAMPLES: int = 2000
"""Bootstrap resamples per interval."""

DEFAULT_CONFIDENCE: float = 0.95
"""Two-sided confidence level of the intervals."""

DEFAULT_SEED: int = 0
"""Seed of the bootstrap generator (fixed so that intervals are reproducible)."""

#: draw tables up to this many indices are kept for reuse (8 tables of at most 8 MB)
_CACHED_DRAWS = 2**20


def _draw(sizes: tuple[int, ...], n_resamples: int, seed: int) -> tuple[NDArray[np.int64], ...]:
    rng = np.random.default_rng(seed)
    return tuple(rng.integers(0, size, size=(n_resamples, size)) for size in sizes)


@functools.lru_cache(maxsize=8)
def _cached_draws(sizes: tuple[int, ...], n_resamples: int, seed: int) -> tuple[NDArray[np.int64], ...]:
    draws = _draw(sizes, n_resamples, seed)
    for table in draws:
        table.setflags(write=False)
    return draws


def stratified_draws(
    sizes: Sequence[int], n_resamples: int = DEFAULT_RESAMPLES, seed: int = DEFAULT_SEED
) -> tuple[NDArray[np.int64], ...]:
    """The resample indices of every stratum, in stratum order.

    Stratum t gets ``rng.integers(0, n_t, size=(n_resamples, n_t))`` from one generator
    seeded with ``seed``, strata drawn in the order given. Tables of up to 2²⁰ indices in all
    are cached (read-only): every metric of a task, and every method of a suite, draws them
    once.

    Args:
        sizes: ``(S,)`` the number of runs n_t of each stratum, each at least 1.
        n_resamples: R, at least 1.
        seed: Seed of the numpy generator.

    Returns:
        One ``(R, n_t)`` integer table per stratum.

    Raises:
        ValueError: no stratum, an empty stratum, or ``n_resamples < 1``.
    """
    key = tuple(int(size) for size in sizes)
    if not key or min(key) < 1:
        raise ValueError(f"every stratum needs at least one run; got sizes {list(key)}")
    if n_resamples < 1:
        raise ValueError(f"n_resamples must be at least 1, got {n_resamples}")
    if n_resamples * sum(key) <= _CACHED_DRAWS:
        return _cached_draws(key, n_resamples, seed)
    return _draw(key, n_resamples, seed)


def resampled_means(
    strata: Sequence[ArrayLike], n_resamples: int = DEFAULT_RESAMPLES, seed: int = DEFAULT_SEED
) -> list[NDArray[np.float64]]:
    """The mean of every resample of every stratum (the draws of :func:`stratified_draws`).

    A stratum may hold several rows of runs, ``(M, n_t)``: one row per method on the same
    seeds. The same draw applies to every row, so the methods stay paired episode by episode.

    Args:
        strata: per stratum, ``(n_t,)`` or ``(M, n_t)`` values.
        n_resamples: R.
        seed: Seed of the draws.

    Returns:
        Per stratum, ``(R,)`` or ``(M, R)`` resampled means.
    """
    values = [np.asarray(x, dtype=np.float64) for x in strata]
    draws = stratified_draws([x.shape[-1] for x in values], n_resamples, seed)
    return [x[..., picks].mean(axis=-1) for x, picks in zip(values, draws, strict=True)]


def percentile_interval(
    resampled: ArrayLike, confidence: float = DEFAULT_CONFIDENCE
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The percentile bootstrap interval: the ``(1 ∓ confidence)/2`` quantiles of the resamples.

    Args:
        resampled: ``(..., R)`` statistic of each resample (the quantiles are over the last axis).
        confidence: In (0, 1).

    Returns:
        ``(low, high)``, each of shape ``(...)`` (0-d for a single row).

    Raises:
        ValueError: ``confidence`` outside (0, 1).
    """
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}")
    tail = (1.0 - confidence) / 2.0
    low, high = np.quantile(np.asarray(resampled, dtype=np.float64), [tail, 1.0 - tail], axis=-1)
    return low, high


__all__ = [
    "DEFAULT_CONFIDENCE",
    "DEFAULT_RESAMPLES",
    "DEFAULT_SEED",
    "percentile_interval",
    "resampled_means",
    "stratified_draws",
]
