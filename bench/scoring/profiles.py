"""rliable's plots, as data: performance profiles and the probability of improvement, with their CIs.

Agarwal et al. (2021; ``docs/references.md`` [rliable]) recommend showing, beside an aggregate
score with its interval, the whole distribution of run scores and how often one method beats
another. Here a run is one episode (task, seed) and its score the gain over uniform,
``g = log2(RMSE_uniform / RMSE)`` (:mod:`swarmloc.bench.scoring.score`):

* the **performance profile** of a method is ``profile(τ) = mean_t mean_i [g_{t,i} > τ]``, the
  fraction of its runs whose gain exceeds τ (rliable's run-score distribution);
* the **probability of improvement** of X over Y is ``P(X > Y) = mean_t P(X_t > Y_t)`` with
  ``P(X_t > Y_t) = (1 / n m) Σ_i Σ_j S(x_i, y_j)``, S = 1 if x > y, ½ if equal, 0 otherwise (the
  Mann–Whitney statistic of the task). Over uniform, whose gain is 0 on every run by definition,
  it is the fraction of runs with g > 0, ties counting half.

Both weigh tasks as the suite's score does: equally under score v1, and under score v2
(``families`` given) each family equally, its tasks equally within it, so that a family with
five variants counts no more than one with two. Their CIs come from the score's own bootstrap
(:func:`~swarmloc.bench.scoring.score.resampled_suite`: stratified for v1, hierarchical for v2)
applied to the per-run indicators: the same draws as the score's interval.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from swarmloc.bench.scoring.bootstrap import DEFAULT_CONFIDENCE, DEFAULT_RESAMPLES, DEFAULT_SEED, percentile_interval
from swarmloc.bench.scoring.score import resampled_suite, suite_statistic

Families = Mapping[str, Sequence[str]]
"""family → its tasks (score v2), or empty / None (score v1: tasks weigh equally)."""


@dataclass(frozen=True)
class Improvement:
    """``P(X > Y)`` with its bootstrap 95 % CI.

    Attributes:
        p: the probability of improvement, in [0, 1] (0.5: neither is ahead).
        ci_low, ci_high: its percentile-bootstrap CI (the score's draws).
    """

    p: float
    ci_low: float
    ci_high: float


def _present(families: Families | None, tasks: Sequence[str]) -> dict[str, tuple[str, ...]]:
    """``families`` restricted to ``tasks`` (families without one dropped); empty for score v1.

    Raises:
        ValueError: a task in no family.
    """
    if not families:
        return {}
    kept = {f: tuple(t for t in members if t in tasks) for f, members in families.items()}
    kept = {f: members for f, members in kept.items() if members}
    placed = {t for members in kept.values() for t in members}
    missing = [t for t in tasks if t not in placed]
    if missing:
        raise ValueError(f"tasks {missing} are in no family of {sorted(families)}; every task needs one")
    return kept


def _exceeds(gains: np.ndarray, taus: np.ndarray) -> np.ndarray:
    """``(len(taus), n)``: ``[g_i > τ]`` of every run at every threshold."""
    return (np.asarray(gains, dtype=np.float64)[None, :] > taus[:, None]).astype(np.float64)


def performance_profile(gains_by_task: Mapping[str, np.ndarray], taus: Sequence[float], *,
                        families: Families | None = None) -> np.ndarray:
    """Fraction of runs with gain above each threshold τ, tasks (or families) weighing as the score does.

    ``profile(τ) = mean_t mean_i [g_{t,i} > τ]``; with ``families``, the mean over families of the
    mean over their tasks.

    Args:
        gains_by_task: per task, the ``(n_t,)`` gains.
        taus: ``(K,)`` thresholds.
        families: family → tasks (score v2); None: tasks weigh equally (score v1).

    Returns:
        ``(K,)`` fractions in [0, 1], non-increasing in τ.
    """
    if not gains_by_task:
        raise ValueError("need at least one task")
    tau = np.asarray(taus, dtype=np.float64)
    per_task = {t: _exceeds(g, tau).mean(axis=1) for t, g in gains_by_task.items()}
    return np.asarray(suite_statistic(_present(families, list(gains_by_task)), per_task), dtype=np.float64)


def profile_interval(gains_by_task: Mapping[str, np.ndarray], taus: Sequence[float], *,
                     families: Families | None = None, n_resamples: int = DEFAULT_RESAMPLES,
                     seed: int = DEFAULT_SEED, confidence: float = DEFAULT_CONFIDENCE) -> tuple[np.ndarray, np.ndarray]:
    """The pointwise bootstrap CI of :func:`performance_profile`: the band drawn around the curve.

    Every threshold's indicators are resampled with one draw (the score's bootstrap), so the band
    is the profile of the same resampled runs at every τ.

    Args:
        gains_by_task, taus, families: as :func:`performance_profile`.
        n_resamples, seed, confidence: of the bootstrap.

    Returns:
        ``(low, high)``, each ``(K,)``.
    """
    if not gains_by_task:
        raise ValueError("need at least one task")
    tau = np.asarray(taus, dtype=np.float64)
    values = {t: _exceeds(g, tau) for t, g in gains_by_task.items()}  # (K, n_t): K rows on one draw
    resampled = resampled_suite(_present(families, list(gains_by_task)), values, n_resamples, seed)  # (K, R)
    low, high = percentile_interval(resampled, confidence)
    return np.asarray(low), np.asarray(high)


def _beats(x: np.ndarray, y: np.ndarray) -> float:
    """``(1 / n m) Σ_i Σ_j S(x_i, y_j)``: S = 1 if x > y, ½ if equal, 0 otherwise."""
    x, y = np.asarray(x, dtype=np.float64)[:, None], np.asarray(y, dtype=np.float64)[None, :]
    return float(((x > y) + 0.5 * (x == y)).mean())


def probability_of_improvement(x_by_task: Mapping[str, np.ndarray], y_by_task: Mapping[str, np.ndarray], *,
                               families: Families | None = None) -> float:
    """P(X > Y): the chance that a run of X beats a run of Y on a random task (rliable).

    Per task, the Mann–Whitney statistic ``(1 / n m) Σ_i Σ_j S(x_i, y_j)`` with S = 1 if
    x > y, ½ if equal, 0 otherwise; averaged over the tasks both cover (over families of them,
    then their tasks, when ``families`` is given).

    Args:
        x_by_task, y_by_task: per task, per-seed scores of X and Y (e.g. gains).
        families: family → tasks (score v2); None: tasks weigh equally.

    Raises:
        ValueError: no task in common.
    """
    common = [t for t in x_by_task if t in y_by_task]
    if not common:
        raise ValueError("X and Y share no task")
    per_task = {t: _beats(x_by_task[t], y_by_task[t]) for t in common}
    return float(suite_statistic(_present(families, common), per_task))


def improvement_over_uniform(gains_by_task: Mapping[str, np.ndarray], *, families: Families | None = None,
                             n_resamples: int = DEFAULT_RESAMPLES, seed: int = DEFAULT_SEED,
                             confidence: float = DEFAULT_CONFIDENCE) -> Improvement:
    """P(method > uniform) with its bootstrap CI.

    Uniform's gain over itself is 0 on every run, so ``P_t`` is the mean over the method's runs of
    ``[g > 0] + ½ [g = 0]``: a mean of per-run values, resampled by the score's bootstrap
    (stratified, or hierarchical with ``families``) like the score itself.

    Args:
        gains_by_task: per task, the method's ``(n_t,)`` gains over uniform.
        families: family → tasks (score v2); None: tasks weigh equally.
        n_resamples, seed, confidence: of the bootstrap.
    """
    if not gains_by_task:
        raise ValueError("need at least one task")
    wins = {t: (np.asarray(g) > 0.0) + 0.5 * (np.asarray(g) == 0.0) for t, g in gains_by_task.items()}
    present = _present(families, list(gains_by_task))
    p = float(suite_statistic(present, {t: w.mean() for t, w in wins.items()}))
    low, high = percentile_interval(resampled_suite(present, wins, n_resamples, seed), confidence)
    return Improvement(p, float(low), float(high))


def improvement_matrix(gains: Sequence[Mapping[str, np.ndarray]], *, families: Families | None = None) -> np.ndarray:
    """``(M, M)``: ``P(method_i > method_j)`` of every pair, over the tasks each pair shares (NaN: none shared).

    ``P(i > j) + P(j > i) = 1`` and the diagonal is ½.

    Args:
        gains: per method, task → its per-seed gains.
        families: family → tasks (score v2); None: tasks weigh equally.
    """
    out = np.full((len(gains), len(gains)), np.nan)
    for i, x in enumerate(gains):
        for j, y in enumerate(gains):
            if any(t in y for t in x):
                out[i, j] = probability_of_improvement(x, y, families=families)
    return out


__all__ = [
    "Families",
    "Improvement",
    "improvement_matrix",
    "improvement_over_uniform",
    "performance_profile",
    "probability_of_improvement",
    "profile_interval",
]
