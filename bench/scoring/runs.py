"""Several training runs of one method: its score over runs, with a CI over runs (rliable).

A learned method is trained several times, one run per training seed, and every run is
evaluated on the same suite (the same task and seed episodes). Following rliable (Agarwal et
al. 2021; ``docs/references.md`` [rliable]) the method is summarised by the **interquartile
mean over runs** of the runs' suite scores::

    S_runs = IQM_r S_r        (S_r: run r's suite score, score v1 or v2 as the suite says)

with ``IQM`` rliable's 25 % trimmed mean (:func:`swarmloc.bench.scoring.stats.iqm`: ⌊n/4⌋ runs
dropped from each end; with up to three runs it is their mean). The runs' suite scores, not the
pooled (run, task) scores that rliable's aggregate IQM trims, because S already weighs the tasks
(score v2: families weigh the same): pooling would trim whole tasks and undo that weighting.

Its 95 % CI is a bootstrap over runs on top of the suite's own: each resample draws the
families and seeds once (the scores' paired bootstrap, :func:`~swarmloc.bench.scoring.score.paired_resamples`,
the same draw for every run and every method), then n runs with replacement out of the n
(rliable's stratified bootstrap over runs, the suite one stratum), and takes the IQM of the
drawn runs' resampled S. With one run it is the suite's CI exactly. The run draws come from
their own generator, ``default_rng([seed, 2])``, and depend on the run count only, like every
draw of the package: the same runs give the same interval on any board.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from swarmloc.bench.scoring.bootstrap import DEFAULT_CONFIDENCE, DEFAULT_RESAMPLES, DEFAULT_SEED, percentile_interval
from swarmloc.bench.scoring.score import SuiteScore, paired_resamples, ranks_beyond_doubt
from swarmloc.bench.scoring.stats import iqm, iqm_along_last

#: the run draws' generator is ``default_rng([seed, _RUN_STREAM])`` (families use stream 1, seeds the bare seed)
_RUN_STREAM = 2


@dataclass(frozen=True)
class OverRuns:
    """A method's score over its training runs.

    Attributes:
        S: the interquartile mean over runs of the runs' suite scores (log2 units).
        ci_low, ci_high: its 95 % CI (bootstrap over runs, families and seeds).
        runs: each run's suite score S_r, in the order given.
    """

    S: float
    ci_low: float
    ci_high: float
    runs: tuple[float, ...]

    @property
    def n_runs(self) -> int:
        """How many runs."""
        return len(self.runs)


def run_mean_episodes(runs: Sequence[Sequence[Mapping[str, Any]]]) -> list[dict[str, Any]]:
    """The episodes of the runs' mean gain: each episode's RMSE the geometric mean over runs.

    A gain is a log ratio to the same episode's uniform RMSE, so the gain of the geometric mean is
    the mean of the runs' gains, ``log2(u / (Π_r e_r)^(1/n)) = mean_r log2(u / e_r)``: scored by
    :func:`~swarmloc.bench.scoring.score.suite_score`, these episodes give every task the mean over
    runs of its ``G_t`` (and the cooperation gain, and the gap closed, of the run-mean). An episode some
    run did not run (no RMSE) has none.

    Args:
        runs: per run, its results-file episodes (``{"task", "seed", "metrics"}``), the same (task, seed)
            pairs in every run; the other metrics (``uniform_rmse``, ``bound_rmse``) are the first run's.

    Raises:
        ValueError: no run, or runs of different episodes.
    """
    if not runs:
        raise ValueError("run_mean_episodes needs at least one run")
    keys = [[(str(ep["task"]), int(ep["seed"])) for ep in episodes] for episodes in runs]
    if any(sorted(k) != sorted(keys[0]) for k in keys[1:]):
        raise ValueError("the runs hold different (task, seed) episodes; only runs of the same episodes average")
    rmse = [{key: ep["metrics"].get("rmse") for key, ep in zip(k, episodes)} for k, episodes in zip(keys, runs)]
    out = []
    for key, ep in zip(keys[0], runs[0]):
        values = [r[key] for r in rmse]
        mean = None if any(v is None or v <= 0.0 for v in values) else float(np.exp(np.mean(np.log(values))))
        out.append({**ep, "metrics": {**ep["metrics"], "rmse": mean}})
    return out


def resampled_over_runs(methods: Sequence[Sequence[SuiteScore]], n_resamples: int = DEFAULT_RESAMPLES,
                        seed: int = DEFAULT_SEED) -> np.ndarray:
    """``(methods, R)``: each method's IQM over runs of its runs' resampled S, paired across methods.

    Args:
        methods: per method, the suite scores of its runs (at least one), every run of every method
            covering the same tasks with the same seeds.
        n_resamples: R.
        seed: of the draws.

    Raises:
        ValueError: a method without runs, or runs that cover different tasks or seeds.
    """
    if any(not runs for runs in methods):
        raise ValueError("every method needs at least one run")
    flat = [score for runs in methods for score in runs]
    _, resampled = paired_resamples(flat, n_resamples, seed)  # (runs of every method, R)
    rows, start = [], 0
    for runs in methods:
        own = resampled[start:start + len(runs)]  # (n, R)
        start += len(runs)
        if len(runs) == 1:
            rows.append(own[0])
            continue
        picks = np.random.default_rng([seed, _RUN_STREAM]).integers(0, len(runs), size=(n_resamples, len(runs)))
        drawn = own[picks, np.arange(n_resamples)[:, None]]  # (R, n): resample b's S of its drawn runs
        rows.append(iqm_along_last(drawn))
    return np.stack(rows)


def over_runs(runs: Sequence[SuiteScore], n_resamples: int = DEFAULT_RESAMPLES, seed: int = DEFAULT_SEED,
              confidence: float = DEFAULT_CONFIDENCE) -> OverRuns:
    """The IQM over runs of the runs' suite scores, with its bootstrap CI (see the module docstring).

    Args:
        runs: the suite scores of one method's runs (at least one), covering the same tasks and seeds.
        n_resamples, seed: of the bootstrap.
        confidence: of the CI, in (0, 1).

    Raises:
        ValueError: no run, or runs that cover different tasks or seeds.
    """
    if not runs:
        raise ValueError("over_runs needs at least one run")
    low, high = percentile_interval(resampled_over_runs([runs], n_resamples, seed)[0], confidence)
    per_run = tuple(float(score.S) for score in runs)
    return OverRuns(S=iqm(per_run), ci_low=float(low), ci_high=float(high), runs=per_run)


def separable_ranks_over_runs(methods: Sequence[Sequence[SuiteScore]], n_resamples: int = DEFAULT_RESAMPLES,
                              seed: int = DEFAULT_SEED, confidence: float = DEFAULT_CONFIDENCE) -> list[int]:
    """Each method's rank as 1 + the methods whose IQM over runs is higher beyond doubt.

    :func:`~swarmloc.bench.scoring.score.separable_ranks` for methods of several runs: the paired
    CI of the difference in the IQM over runs (:func:`resampled_over_runs`). Methods of one run each
    get exactly ``separable_ranks``' ranks.

    Args:
        methods: per method, the suite scores of its runs, all covering the same tasks and seeds.
        n_resamples, seed: of the bootstrap.
        confidence: of the CI, in (0, 1).
    """
    if not methods:
        return []
    return ranks_beyond_doubt(resampled_over_runs(methods, n_resamples, seed), confidence)


__all__ = ["OverRuns", "over_runs", "resampled_over_runs", "run_mean_episodes", "separable_ranks_over_runs"]
