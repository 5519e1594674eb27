"""Statistics used for aggregates: mean, IQM, stratified bootstrap CI."""

from __future__ import annotations

import numpy as np
import pytest

from swarmloc.bench.scoring import stats
from swarmloc.bench.evaluation.results import METRIC_NAMES, EpisodeMetrics


def test_bootstrap_ci_of_a_constant_is_that_constant() -> None:
    low, high = stats.bootstrap_ci([0.1] * 7)
    assert (low, high) == (0.1, 0.1)
    low, high = stats.bootstrap_ci([2.5] * 6, strata=["a", "a", "b", "b", "c", "c"], statistic="iqm")
    assert (low, high) == (2.5, 2.5)


def test_iqm_against_hand_computed_case() -> None:
    # n = 8: drop 2 from each end of sorted [1, 2, 3, 4, 5, 6, 100, 1000] -> mean(3, 4, 5, 6) = 4.5
    assert stats.iqm([1000, 3, 1, 6, 100, 5, 2, 4]) == 4.5
    # n = 5: drop 1 from each end of sorted [0, 1, 2, 3, 50] -> mean(1, 2, 3) = 2
    assert stats.iqm([50, 2, 0, 3, 1]) == 2.0
    # n < 4: nothing dropped
    assert stats.iqm([1.0, 2.0, 6.0]) == 3.0


def test_bootstrap_is_seeded_order_independent_and_covers_the_mean() -> None:
    rng = np.random.default_rng(3)
    x = rng.normal(1.0, 0.3, size=20)
    strata = ["t1"] * 10 + ["t2"] * 10
    a = stats.bootstrap_ci(x, strata)
    b = stats.bootstrap_ci(x, strata)
    assert a == b
    assert a[0] < float(np.mean(x)) < a[1]
    assert stats.bootstrap_ci(x, strata, seed=1) != a
    with pytest.raises(ValueError, match="strata has 3 labels for 20 values"):
        stats.bootstrap_ci(x, ["a", "b", "c"])
    with pytest.raises(ValueError, match="unknown statistic 'median'"):
        stats.bootstrap_ci(x, statistic="median")  # type: ignore[arg-type]


def test_stratified_bootstrap_keeps_each_task_in_every_resample() -> None:
    # Task means are far apart; a stratified resample always mixes them 50/50, so the
    # interval of the pooled mean is narrow around the midpoint.
    x = np.r_[np.zeros(5) + np.linspace(0, 0.01, 5), 100 + np.linspace(0, 0.01, 5)]
    low, high = stats.bootstrap_ci(x, ["a"] * 5 + ["b"] * 5)
    assert 49.9 < low <= high < 50.1


def _episode(task: str, seed: int, **metrics: float | None) -> dict:
    return {"task": task, "seed": seed, "metrics": EpisodeMetrics.of(**metrics).model_dump()}


def test_aggregate_shape_and_undefined_metrics() -> None:
    episodes = [_episode("T/a-v0", s, rmse=1.0 + s, jitter=0.5) for s in range(4)]
    episodes += [_episode("T/b-v0", s, rmse=2.0, fault_rmse=3.0 if s else None) for s in range(3)]
    agg = stats.aggregate(reversed(episodes))
    assert sorted(agg) == ["T/a-v0", "T/b-v0"]
    for per_metric in agg.values():
        assert list(per_metric) == list(METRIC_NAMES)
    a = agg["T/a-v0"]["rmse"]
    assert a is not None and a.mean == 2.5 and a.iqm == 2.5 and 1.0 <= a.ci_low <= a.ci_high <= 4.0
    assert agg["T/a-v0"]["fault_rmse"] is None
    b = agg["T/b-v0"]["fault_rmse"]
    assert b is not None and (b.mean, b.ci_low, b.ci_high) == (3.0, 3.0, 3.0)
    # Order of episodes does not change the result.
    assert stats.aggregate(episodes) == agg
