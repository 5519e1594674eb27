"""The bootstrap: stratified and hierarchical resampling of seeds, and the percentile interval.

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

Score v2 weighs task families equally, so its suite CI is **hierarchical** (two-stage): a
resample draws F families with replacement out of the F, keeps every task of each drawn
family, and draws each of those tasks' seeds with replacement, afresh at every draw of the
family (a family drawn twice contributes two independent seed resamples). The family draws
come from their own generator, so with a single family the seed draws — and the resampled
statistic — are exactly the stratified bootstrap's. The same rule holds: the draws depend on
the seed, the resample count and the structure (tasks per family, seeds per task) only.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

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


#: the family draws' generator is ``default_rng([seed, _FAMILY_STREAM])``, apart from the seed draws'
_FAMILY_STREAM = 1

Structure = tuple[tuple[int, ...], ...]
"""Per family, the number of seeds of each of its tasks: ``((n_t for t in family) for family)``."""


@dataclass(frozen=True)
class HierarchicalDraws:
    """The indices of a hierarchical resample (:func:`hierarchical_draws`).

    Attributes:
        families: ``(R, F)``: the family drawn at each of the F slots of each resample.
        seeds: per family f, per task of f, a ``(K_f, n_t)`` table of seed indices, where K_f is
            the number of times f was drawn in all; row k serves f's k-th draw in row-major order
            of ``families`` (resample by resample, slot by slot).
    """

    families: NDArray[np.int64]
    seeds: tuple[tuple[NDArray[np.int64], ...], ...]


def _check_structure(structure: Sequence[Sequence[int]]) -> Structure:
    key = tuple(tuple(int(n) for n in family) for family in structure)
    if not key or any(not family for family in key) or min(n for family in key for n in family) < 1:
        raise ValueError(f"every family needs at least one task and every task at least one run; got {list(key)}")
    return key


def _draw_hierarchical(structure: Structure, n_resamples: int, seed: int) -> HierarchicalDraws:
    families = np.random.default_rng([seed, _FAMILY_STREAM]).integers(0, len(structure), size=(n_resamples,
                                                                                                 len(structure)))
    counts = np.bincount(families.ravel(), minlength=len(structure))
    rng = np.random.default_rng(seed)  # the stratified bootstrap's generator: one family reduces to it
    seeds = tuple(tuple(rng.integers(0, n, size=(int(k), n)) for n in sizes) for sizes, k in zip(structure, counts))
    return HierarchicalDraws(families, seeds)


@functools.lru_cache(maxsize=8)
def _cached_hierarchical(structure: Structure, n_resamples: int, seed: int) -> HierarchicalDraws:
    draws = _draw_hierarchical(structure, n_resamples, seed)
    draws.families.setflags(write=False)
    for tables in draws.seeds:
        for table in tables:
            table.setflags(write=False)
    return draws


def hierarchical_draws(structure: Sequence[Sequence[int]], n_resamples: int = DEFAULT_RESAMPLES,
                       seed: int = DEFAULT_SEED) -> HierarchicalDraws:
    """The indices of a two-stage resample: families with replacement, then seeds within their tasks.

    The families come from ``default_rng([seed, 1])`` as one ``(R, F)`` table; the seeds from
    ``default_rng(seed)``, family by family and within a family task by task, one
    ``(K_f, n_t)`` table each. Draw tables of up to 2²⁰ seed indices in all are cached (read-only).

    Args:
        structure: per family, the runs n_t of each of its tasks (each at least 1; no empty family).
        n_resamples: R, at least 1.
        seed: Seed of both generators.

    Returns:
        The ``HierarchicalDraws``.

    Raises:
        ValueError: no family, an empty family or task, or ``n_resamples < 1``.
    """
    key = _check_structure(structure)
    if n_resamples < 1:
        raise ValueError(f"n_resamples must be at least 1, got {n_resamples}")
    if n_resamples * sum(n for family in key for n in family) <= _CACHED_DRAWS:
        return _cached_hierarchical(key, n_resamples, seed)
    return _draw_hierarchical(key, n_resamples, seed)


def hierarchical_means(
    families: Sequence[Sequence[ArrayLike]], n_resamples: int = DEFAULT_RESAMPLES, seed: int = DEFAULT_SEED
) -> NDArray[np.float64]:
    """The mean over families of the mean over their tasks of the task means, per hierarchical resample.

    Resample r computes ``(1/F) Σ_slots (1/|f|) Σ_{t ∈ f} mean(x_t[seed draw])`` for the
    families f drawn at its F slots (:func:`hierarchical_draws`). A task may hold several rows
    of runs, ``(M, n_t)``, one per method on the same seeds: every row gets the same draws, so
    the methods stay paired.

    Args:
        families: per family, per task, ``(n_t,)`` or ``(M, n_t)`` values (the same M everywhere).
        n_resamples: R.
        seed: Seed of the draws.

    Returns:
        ``(R,)`` or ``(M, R)``: the resampled statistic.
    """
    values = [[np.asarray(x, dtype=np.float64) for x in tasks] for tasks in families]
    draws = hierarchical_draws([[x.shape[-1] for x in tasks] for tasks in values], n_resamples, seed)
    lead = values[0][0].shape[:-1]
    total = np.zeros((n_resamples, *lead))  # resample first, so that np.add.at indexes axis 0
    for f, (tasks, tables) in enumerate(zip(values, draws.seeds, strict=True)):
        if tables[0].shape[0] == 0:
            continue  # never drawn
        # (..., K_f): this family's mean over its tasks at each of its draws
        family_means = sum(x[..., picks].mean(axis=-1) for x, picks in zip(tasks, tables, strict=True)) / len(tasks)
        resample_of_draw = np.nonzero(draws.families == f)[0]  # row-major: the k-th draw of f is in this resample
        np.add.at(total, resample_of_draw, np.moveaxis(family_means, -1, 0))
    return np.moveaxis(total / len(values), 0, -1)


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
    "HierarchicalDraws",
    "hierarchical_draws",
    "hierarchical_means",
    "percentile_interval",
    "resampled_means",
    "stratified_draws",
]
