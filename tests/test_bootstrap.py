"""The one bootstrap (bench/scoring/bootstrap.py): its draws, its paired means, its interval.

Every CI of the package (task aggregates, the suite score, the leaderboard's separable ranks,
``swarmloc compare``) goes through these three functions; the pinned CIs of the shipped
results rest on the draws being exactly the calls below.
"""

from __future__ import annotations

import numpy as np
import pytest

from swarmloc.bench.scoring import bootstrap, score, stats


def _reference_interval(strata: list[np.ndarray], n_resamples: int, seed: int, confidence: float) -> tuple[float, float]:
    """Readable reference: resample after resample, mean of the task means, then the percentiles."""
    rng = np.random.default_rng(seed)
    tables = [rng.integers(0, x.size, size=(n_resamples, x.size)) for x in strata]
    resampled = [np.mean([x[table[r]].mean() for x, table in zip(strata, tables)]) for r in range(n_resamples)]
    tail = 100.0 * (1.0 - confidence) / 2.0
    low, high = np.percentile(resampled, [tail, 100.0 - tail])
    return float(low), float(high)


def test_draws_are_one_generator_stratum_by_stratum() -> None:
    draws = bootstrap.stratified_draws([3, 1, 5], n_resamples=7, seed=11)
    rng = np.random.default_rng(11)
    expected = [rng.integers(0, n, size=(7, n)) for n in (3, 1, 5)]
    assert len(draws) == 3
    for table, want in zip(draws, expected):
        np.testing.assert_array_equal(table, want)
    assert bootstrap.stratified_draws([3, 1, 5], n_resamples=7, seed=11) is draws  # small tables are cached
    assert not draws[0].flags.writeable


def test_suite_interval_matches_the_readable_reference() -> None:
    rng = np.random.default_rng(5)
    strata = [rng.normal(size=n) for n in (4, 9, 2)]
    for confidence in (0.95, 0.8):
        got = score.bootstrap_suite_ci(strata, n_resamples=300, seed=2, confidence=confidence)
        assert got == pytest.approx(_reference_interval(strata, 300, 2, confidence), rel=1e-12, abs=1e-12)


def test_paired_rows_share_one_draw() -> None:
    rng = np.random.default_rng(8)
    a, b = rng.normal(size=6), rng.normal(size=6)
    (both,) = bootstrap.resampled_means([np.stack([a, b])], n_resamples=50, seed=4)
    (alone_a,) = bootstrap.resampled_means([a], n_resamples=50, seed=4)
    (alone_b,) = bootstrap.resampled_means([b], n_resamples=50, seed=4)
    np.testing.assert_array_equal(both, np.stack([alone_a, alone_b]))


def test_one_stratum_ci_is_the_stats_ci_before_clipping() -> None:
    x = np.random.default_rng(1).exponential(size=12)
    (means,) = bootstrap.resampled_means([x], n_resamples=400, seed=0)
    low, high = bootstrap.percentile_interval(means, 0.9)
    assert stats.bootstrap_ci(x, n_resamples=400, seed=0, confidence=0.9) == (float(low), float(high))


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: bootstrap.stratified_draws([3, 0]), r"every stratum needs at least one run; got sizes \[3, 0\]"),
        (lambda: bootstrap.stratified_draws([]), r"got sizes \[\]"),
        (lambda: bootstrap.stratified_draws([3], n_resamples=0), "n_resamples must be at least 1, got 0"),
        (lambda: bootstrap.percentile_interval([1.0, 2.0], confidence=1.0), r"confidence must be in \(0, 1\), got 1.0"),
    ],
)
def test_bad_arguments_name_the_value_and_the_range(call, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        call()
