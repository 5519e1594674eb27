"""Score v1 (bench/scoring/score.py): hand-computed cases for every quantity."""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarmloc.bench.scoring import score as S
from swarmloc.bench.scoring import profiles as P
def _ep(task, seed, rmse, uniform, bound=None):
    return {"task": task, "seed": seed, "metrics": {"rmse": rmse, "uniform_rmse": uniform, "bound_rmse": bound}}


def test_episode_gain_is_log2_of_the_error_ratio():
    assert S.episode_gain(2.0, 1.0) == 1.0
    assert S.episode_gain(1.0, 4.0) == -2.0
    assert S.episode_gain(3.0, 3.0) == 0.0
    assert S.episode_gain(None, 1.0) is None and S.episode_gain(1.0, None) is None
    assert S.episode_gain(1.0, 0.0) is None and S.episode_gain(float("inf"), 1.0) is None


def test_task_score_mean_achievable_and_gap_closed():
    # gains 1 and 2 → G = 1.5; bounds at a quarter and an eighth of uniform → A = (2 + 3) / 2 = 2.5
    t = S.task_score("T", [1.0, 2.0], [2.0, 3.0])
    assert t.mean == 1.5 and t.achievable == 2.5 and t.gap_closed == pytest.approx(0.6)
    # the bound within 25 % of uniform: no gap-closed ratio
    small = S.task_score("T", [0.1], [math.log2(1.2)])
    assert small.achievable == pytest.approx(math.log2(1.2)) and small.gap_closed is None
    assert S.task_score("T", [0.5], [None]).achievable is None
    with pytest.raises(ValueError, match="finite"):
        S.task_score("T", [float("nan")])


def test_suite_score_weighs_tasks_equally_and_counts_coverage():
    eps = [_ep("A", 0, 1.0, 2.0), _ep("A", 1, 1.0, 2.0),                      # G_A = 1
           _ep("B", 0, 4.0, 1.0), _ep("B", 1, 1.0, 1.0), _ep("B", 2, 1.0, 1.0),  # G_B = (−2 + 0 + 0) / 3
           _ep("C", 0, None, 1.0)]                                              # not covered
    s = S.suite_score(eps, ["A", "B", "C", "D"], n_resamples=200)
    assert s.S == pytest.approx((1.0 - 2.0 / 3.0) / 2.0)
    assert s.times == pytest.approx(2.0 ** s.S)
    assert s.coverage == (2, 4) and s.uncovered == ("C", "D")
    # IQM over the 5 covered episodes [−2, 0, 0, 1, 1]: drop one from each end → mean(0, 0, 1) = 1/3
    assert s.iqm == pytest.approx(1.0 / 3.0)
    assert s.ci_low <= s.S <= s.ci_high
    assert S.suite_score([_ep("C", 0, None, 1.0)]) is None


def test_suite_ci_resamples_within_tasks():
    # constant gains within each task: every resample gives the same S, so the CI collapses
    eps = [_ep("A", i, 1.0, 2.0) for i in range(5)] + [_ep("B", i, 1.0, 8.0) for i in range(3)]
    s = S.suite_score(eps, n_resamples=300)
    assert s.S == pytest.approx(2.0) and s.ci_low == pytest.approx(2.0) and s.ci_high == pytest.approx(2.0)
    # the CI is reproducible and covers the estimate
    rng = np.random.default_rng(1)
    noisy = [_ep("A", i, float(rng.uniform(0.5, 2.0)), 1.0) for i in range(16)]
    a, b = S.suite_score(noisy), S.suite_score(noisy)
    assert (a.ci_low, a.ci_high) == (b.ci_low, b.ci_high) and a.ci_low < a.S < a.ci_high


def test_gap_closed_of_the_suite_is_the_ratio_of_sums_over_tasks_with_a_gap():
    eps = [_ep("A", 0, 1.0, 2.0, bound=0.5),   # g = 1, a = 2 → 0.5
           _ep("B", 0, 1.0, 8.0, bound=1.0),   # g = 3, a = 3 → 1.0
           _ep("C", 0, 1.0, 1.0, bound=0.9),   # a = log2(1/0.9) < log2 1.25 → no ratio
           _ep("D", 0, 16.0, 1.0, bound=0.8)]  # g = −4, a = log2 1.25: ratio −12.4, yet only −4 in the sum
    s = S.suite_score(eps, n_resamples=10)
    assert s.tasks["A"].gap_closed == pytest.approx(0.5) and s.tasks["B"].gap_closed == pytest.approx(1.0)
    assert s.tasks["C"].gap_closed is None and s.tasks["D"].gap_closed == pytest.approx(-4 / math.log2(1.25))
    # (1 + 3 − 4) / (2 + 3 + log2 1.25): one task with a small achievable gain does not swamp the suite
    assert s.gap_closed == pytest.approx(0.0 / (5.0 + math.log2(1.25)))


def test_performance_profile_by_hand():
    gains = {"A": np.array([-1.0, 0.5, 2.0, 3.0]), "B": np.array([0.0, 1.0])}
    # τ = 0: A 3/4, B 1/2 → 0.625; τ = 1: A 2/4, B 0 → 0.25; τ = −2: everything
    np.testing.assert_allclose(P.performance_profile(gains, [-2.0, 0.0, 1.0]), [1.0, 0.625, 0.25])


def test_probability_of_improvement_by_hand():
    x = {"A": np.array([1.0, 3.0]), "B": np.array([0.0])}
    y = {"A": np.array([2.0, 2.0]), "B": np.array([0.0]), "C": np.array([5.0])}
    # A: pairs (1>2? 0)(1>2? 0)(3>2 1)(3>2 1) → 0.5; B: a tie → 0.5; C is not shared
    assert P.probability_of_improvement(x, y) == 0.5
    assert P.probability_of_improvement({"A": np.array([3.0])}, {"A": np.zeros(4)}) == 1.0
    with pytest.raises(ValueError, match="share no task"):
        P.probability_of_improvement({"A": np.ones(1)}, {"B": np.ones(1)})


def _suite(gains_by_task: dict[str, list[float]], seeds: list[int] | None = None) -> S.SuiteScore:
    """A method's suite score from its per-seed gains (uniform RMSE 1, RMSE 2^-g)."""
    eps = [_ep(task, (seeds or list(range(len(g))))[i], 2.0 ** -x, 1.0)
           for task, g in gains_by_task.items() for i, x in enumerate(g)]
    return S.suite_score(eps)


def test_separable_ranks_pair_the_episodes():
    common = {"A": [-3.0, 0.0, 3.0, -1.0, 1.0, 2.0], "B": [2.0, -2.0, 0.5, -0.5, 1.5, -1.5]}
    shift = lambda d: {t: [x + d for x in g] for t, g in common.items()}  # noqa: E731
    # a lead of 0.05 on every episode is beyond doubt although each method's own CI spans ±1
    lead, base = _suite(shift(0.05)), _suite(shift(0.0))
    assert lead.ci_low < base.S < lead.S < base.ci_high
    assert S.separable_ranks([lead, base]) == [1, 2]
    assert S.separable_ranks([base, lead]) == [2, 1]
    # the same gains: nobody is ahead
    assert S.separable_ranks([base, _suite(shift(0.0)), _suite(shift(0.0))]) == [1, 1, 1]
    # A ahead of B on every episode; C level with both (its own noise swamps a 0.1 lead either way): 1, 2, 1
    noise = {t: [x + (3.0 if i % 2 else -3.0) for i, x in enumerate(g)] for t, g in shift(0.1).items()}
    assert S.separable_ranks([_suite(shift(0.2)), base, _suite(noise)]) == [1, 2, 1]


def test_separable_ranks_refuse_what_does_not_pair():
    a = _suite({"A": [1.0, 2.0]}, seeds=[1, 2])
    with pytest.raises(ValueError, match="different seeds"):
        S.separable_ranks([a, _suite({"A": [1.0, 2.0]}, seeds=[1, 3])])
    with pytest.raises(ValueError, match="cover B"):
        S.separable_ranks([_suite({"A": [1.0, 2.0], "B": [0.0, 0.0]}), _suite({"A": [1.0, 2.0]})])
    # seed order does not matter: the episodes are matched by seed
    assert S.separable_ranks([_suite({"A": [1.0, 2.0, 3.0]}, seeds=[5, 6, 7]),
                              _suite({"A": [2.5, 1.5, 0.5]}, seeds=[7, 6, 5])]) == [1, 2]


def test_the_bootstrap_seed_is_not_the_episode_seed():
    # the CI depends on the gains and the bootstrap's own seed, never on which seeds the episodes ran
    gains = {"A": [0.3, -1.2, 2.0, 0.1], "B": [1.0, 0.0, -0.5, 4.0]}
    a, b = _suite(gains, seeds=[0, 1, 2, 3]), _suite(gains, seeds=[9000, 9001, 9002, 9003])
    assert (a.ci_low, a.ci_high) == (b.ci_low, b.ci_high)
    assert (a.ci_low, a.ci_high) == pytest.approx(S.bootstrap_suite_ci([np.array(g) for g in gains.values()]))
