"""Score v2 (benchmark v2): the hierarchical bootstrap, family weighting, the cooperation gain,
the choice of score by suite, and the split by track. Synthetic episode rows only."""

from __future__ import annotations

import math
from datetime import datetime, timedelta, timezone

import numpy as np
import pytest

from swarmloc.bench.evaluation.results import EpisodeMetrics, MethodInfo, SuiteInfo, dumps_results, make_results
from swarmloc.bench.scoring import bootstrap as B
from swarmloc.bench.scoring import score as S
from swarmloc.bench.scoring import tracks
from swarmloc.bench.scoring.compare import compare
from swarmloc.leaderboard.site import ranking
from swarmloc.leaderboard.store.database import LeaderboardEntry

# two families: Scale (two tasks) and NLOS (one task)
SCALE8, SCALE16, NLOS = "swarmloc/Scale8-v2", "swarmloc/Scale16-v2", "swarmloc/NLOS-v2"


def _ep(task: str, seed: int, rmse: float | None, uniform: float = 1.0) -> dict:
    return {"task": task, "seed": seed, "metrics": {"rmse": rmse, "uniform_rmse": uniform, "bound_rmse": None}}


def _episodes(gains: dict[str, list[float]]) -> list[dict]:
    """Episodes with these per-seed gains over uniform (uniform RMSE 1, RMSE 2^-g), seeds 0, 1, ..."""
    return [_ep(task, i, 2.0 ** -g) for task, gs in gains.items() for i, g in enumerate(gs)]


GAINS = {SCALE8: [1.0, 0.5, 1.5], SCALE16: [3.0, 2.0, 4.0], NLOS: [0.0, -1.0, 1.0, 0.5]}


# -- the hierarchical bootstrap -------------------------------------------------------------------


def test_one_family_is_the_stratified_bootstrap_exactly() -> None:
    rng = np.random.default_rng(5)
    tasks = [rng.normal(size=n) for n in (4, 7, 3)]
    stratified = sum(B.resampled_means(tasks, 500, 11)) / len(tasks)
    np.testing.assert_array_equal(B.hierarchical_means([tasks], 500, 11), stratified)
    # paired rows too: (M, n_t) per task, one draw for every row
    rows = [np.stack([x, 2 * x + 1]) for x in tasks]
    np.testing.assert_array_equal(B.hierarchical_means([rows], 500, 11), sum(B.resampled_means(rows, 500, 11)) / 3)


def test_the_draws_depend_on_the_structure_only_and_are_reproducible() -> None:
    structure = [[3, 2], [5], [1, 1, 4]]
    a, b = B.hierarchical_draws(structure, 300, 7), B._draw_hierarchical(((3, 2), (5,), (1, 1, 4)), 300, 7)
    np.testing.assert_array_equal(a.families, b.families)
    for fa, fb in zip(a.seeds, b.seeds, strict=True):
        for ta, tb in zip(fa, fb, strict=True):
            np.testing.assert_array_equal(ta, tb)
    assert not np.array_equal(B.hierarchical_draws(structure, 300, 8).families, a.families)
    # every draw of a family gets its own seed resample: K_f rows, K_f = how often f was drawn
    counts = np.bincount(a.families.ravel(), minlength=3)
    assert [t.shape for t in a.seeds[0]] == [(counts[0], 3), (counts[0], 2)] and counts.sum() == 300 * 3
    # the same draws whatever the values: doubling every value doubles every resample (exact in floating point)
    values = [[np.array([0.3, -1.1, 2.0]), np.array([0.7, 0.1])], [np.arange(5.0)], [np.ones(1), np.zeros(1),
                                                                                      np.array([4.0, 1, 2, 3])]]
    doubled = [[2 * x for x in tasks] for tasks in values]
    np.testing.assert_array_equal(B.hierarchical_means(doubled, 300, 7), 2 * B.hierarchical_means(values, 300, 7))


def test_the_resampled_spread_is_the_two_stage_closed_form() -> None:
    # F families of one task each: Var*(S) = (1/F) [ popvar_f(mean_f) + mean_f(popvar_f / n_f) ],
    # the family draw's variance plus the seed draw's within the drawn family; mean* = the plain mean
    tasks = [np.array([0.0, 2.0]), np.array([1.0, 1.0, 4.0]), np.array([-3.0, 1.0, 0.0, 2.0])]
    means = np.array([x.mean() for x in tasks])
    within = np.mean([x.var() / x.size for x in tasks])
    resampled = B.hierarchical_means([[x] for x in tasks], 60_000, 3)
    assert resampled.mean() == pytest.approx(means.mean(), abs=0.02)
    assert resampled.var() == pytest.approx((means.var() + within) / len(tasks), rel=0.03)


def test_a_constant_score_has_a_zero_width_interval() -> None:
    resampled = B.hierarchical_means([[np.full(3, 0.75), np.full(2, 0.75)], [np.full(4, 0.75)]], 400, 0)
    low, high = B.percentile_interval(resampled)
    assert low == pytest.approx(0.75, abs=1e-15) and high == pytest.approx(0.75, abs=1e-15)


@pytest.mark.parametrize("structure, message", [([], "at least one task"), ([[2], []], "at least one task"),
                                                ([[2, 0]], "at least one run")])
def test_bad_structures_are_named(structure, message) -> None:
    with pytest.raises(ValueError, match=message):
        B.hierarchical_draws(structure, 10, 0)
    with pytest.raises(ValueError, match="n_resamples must be at least 1, got 0"):
        B.hierarchical_draws([[2]], 0, 0)


# -- which score: the suite decides -----------------------------------------------------------------


def test_score_version_by_suite_name() -> None:
    assert [S.score_version(s) for s in ("standard-v2", "quick-v2-subset", "real-v2", "standard-v3")] == [2, 2, 2, 2]
    assert [S.score_version(s) for s in ("standard-v1", "standard-v0", "quick", "dev", "", None, "v2")] == [1] * 7


def test_v1_suites_keep_score_v1_exactly() -> None:
    eps = _episodes(GAINS)
    plain = S.suite_score(eps)
    v1 = S.suite_score(eps, suite="standard-v1", non_cooperative={(t, s): 1.0 for t in GAINS for s in range(4)})
    assert (v1.S, v1.ci_low, v1.ci_high, v1.iqm) == (plain.S, plain.ci_low, plain.ci_high, plain.iqm)
    assert v1.version == 1 and v1.families == {} and v1.cooperation is None
    assert v1.S == pytest.approx(np.mean([np.mean(g) for g in GAINS.values()]))  # tasks weigh equally
    assert (v1.ci_low, v1.ci_high) == S.bootstrap_suite_ci([np.array(g) for g in GAINS.values()])


# -- score v2 -------------------------------------------------------------------------------------


def test_v2_weighs_families_equally_by_hand() -> None:
    s = S.suite_score(_episodes(GAINS), suite="standard-v2")
    # Scale: (1 + 3) / 2 = 2; NLOS: 0.125; S = (2 + 0.125) / 2 (v1 would weigh Scale twice: (1 + 3 + 0.125) / 3)
    assert s.version == 2 and s.families == {"NLOS": (NLOS,), "Scale": (SCALE8, SCALE16)}
    assert s.S == pytest.approx((2.0 + 0.125) / 2) and s.times == pytest.approx(2 ** ((2.0 + 0.125) / 2))
    assert s.tasks[SCALE16].mean == 3.0 and s.uncovered == ()
    # its CI: the hierarchical bootstrap of the gains, families in display order
    reference = B.hierarchical_means([[np.array(GAINS[NLOS])], [np.array(GAINS[SCALE8]), np.array(GAINS[SCALE16])]])
    assert list(s.families) == ["NLOS", "Scale"]
    assert (s.ci_low, s.ci_high) == pytest.approx(tuple(float(v) for v in B.percentile_interval(reference)), abs=1e-12)


def test_v2_partial_coverage_averages_a_family_over_its_covered_tasks() -> None:
    eps = _episodes(GAINS) + [_ep("swarmloc/Ideal-v2", 0, None)]
    s = S.suite_score(eps, [*GAINS, "swarmloc/Ideal-v2"], suite="standard-v2")
    assert s.uncovered == ("swarmloc/Ideal-v2",) and "Ideal" not in s.families
    dropped = S.suite_score([e for e in eps if e["task"] != SCALE16], suite="standard-v2")
    assert dropped.S == pytest.approx((1.0 + 0.125) / 2)


def test_the_cooperation_gain_beside_the_score() -> None:
    eps = _episodes(GAINS)
    # non-cooperative at twice uniform's RMSE everywhere: the cooperation gain is the score plus 1
    alone = {(e["task"], e["seed"]): 2.0 for e in eps}
    s = S.suite_score(eps, suite="standard-v2", non_cooperative=alone)
    c = s.cooperation
    assert c is not None and c.S == pytest.approx(s.S + 1.0)
    assert (c.ci_low, c.ci_high) == pytest.approx((s.ci_low + 1.0, s.ci_high + 1.0))  # the same draws
    assert c.tasks[NLOS].gains == pytest.approx(np.array(GAINS[NLOS]) + 1.0)
    # non-cooperative itself: exactly 0, with a zero-width interval
    own = [_ep(t, seed, rmse) for (t, seed), rmse in alone.items()]
    zero = S.suite_score(own, suite="standard-v2", non_cooperative=S.rmse_by_episode(own)).cooperation
    assert (zero.S, zero.ci_low, zero.ci_high) == (0.0, 0.0, 0.0)
    # a covered episode without the reference: no cooperation gain (rather than one over part of the suite)
    del alone[(NLOS, 3)]
    assert S.suite_score(eps, suite="standard-v2", non_cooperative=alone).cooperation is None
    assert S.suite_score(eps, suite="standard-v2").cooperation is None


def test_rmse_by_episode_keys_by_task_and_seed() -> None:
    assert S.rmse_by_episode([_ep(NLOS, 3, 0.5), _ep(SCALE8, 1, None)]) == {(NLOS, 3): 0.5, (SCALE8, 1): None}


# -- the paired comparison and ranks under score v2 ----------------------------------------------


def _v2(gains: dict[str, list[float]]) -> S.SuiteScore:
    return S.suite_score(_episodes(gains), suite="standard-v2")


def test_identical_methods_differ_by_exactly_zero() -> None:
    suite, per_task = S.paired_difference(_v2(GAINS), _v2(GAINS))
    assert (suite.mean, suite.ci_low, suite.ci_high) == (0.0, 0.0, 0.0)
    assert all((d.mean, d.ci_low, d.ci_high) == (0.0, 0.0, 0.0) for d in per_task.values())
    assert S.separable_ranks([_v2(GAINS), _v2(GAINS)]) == [1, 1]


def test_the_paired_difference_resamples_families_then_seeds() -> None:
    other = {t: [g + (0.3 if t == NLOS else -0.2) + 0.1 * i for i, g in enumerate(gs)] for t, gs in GAINS.items()}
    a, b = _v2(GAINS), _v2(other)
    suite, per_task = S.paired_difference(a, b)
    assert suite.mean == pytest.approx(b.S - a.S) and (suite.ahead, suite.count) == (1, 3)
    # the statistic is linear: the paired CI is the hierarchical bootstrap of the per-episode differences
    diff = {t: np.array(other[t]) - np.array(GAINS[t]) for t in GAINS}
    reference = B.percentile_interval(B.hierarchical_means([[diff[NLOS]], [diff[SCALE8], diff[SCALE16]]]))
    assert (suite.ci_low, suite.ci_high) == pytest.approx(tuple(float(v) for v in reference), abs=1e-12)
    # a task's CI resamples its own seeds, as under score v1
    v1_suite, v1_tasks = S.paired_difference(S.suite_score(_episodes(GAINS)), S.suite_score(_episodes(other)))
    assert per_task == v1_tasks and (v1_suite.ci_low, v1_suite.ci_high) != (suite.ci_low, suite.ci_high)


def test_scores_of_different_versions_do_not_pair() -> None:
    with pytest.raises(ValueError, match=r"different score versions \[1, 2\]"):
        S.separable_ranks([_v2(GAINS), S.suite_score(_episodes(GAINS))])


def _results(name: str, suite: str, factor: dict[str, float]):
    episodes = [{"task": t, "seed": i, "metrics": EpisodeMetrics.of(rmse=factor[t] * 2.0 ** -g, uniform_rmse=1.0)}
                for t, gs in GAINS.items() for i, g in enumerate(gs)]
    method = MethodInfo(name=name, entry_point=name, privileged=False, track="A", deterministic=True)
    return make_results(method, SuiteInfo(name=suite, version="1", sha256="0" * 64), episodes)


def test_compare_and_the_results_score_use_the_suites_score() -> None:
    worse = {NLOS: 1.0, SCALE8: 2.0, SCALE16: 2.0}  # B loses 1 on both Scale tasks, nothing on NLOS
    v2 = compare(_results("a", "tiny-v2", dict.fromkeys(GAINS, 1.0)), _results("b", "tiny-v2-subset", worse))
    v1 = compare(_results("a", "tiny", dict.fromkeys(GAINS, 1.0)), _results("b", "tiny", worse))
    assert v2.score_a.version == 2 and v1.score_a.version == 1
    assert v2.difference.mean == pytest.approx(-0.5) and v1.difference.mean == pytest.approx(-2 / 3)
    assert v2.score_a.S == pytest.approx(_v2(GAINS).S)
    # the score block of a v2 results file is score v2
    assert _results("a", "tiny-v2", dict.fromkeys(GAINS, 1.0)).score.S == pytest.approx(_v2(GAINS).S)


def _entry(name: str, rmse: dict[tuple[str, int], float], suite: str, i: int) -> LeaderboardEntry:
    episodes = [{"task": t, "seed": s, "metrics": EpisodeMetrics.of(rmse=r, uniform_rmse=1.0)}
                for (t, s), r in rmse.items()]
    results = make_results(MethodInfo(name=name, entry_point=name, privileged=False, track="A", deterministic=True),
                           SuiteInfo(name=suite, version="1", sha256="0" * 64), episodes)
    return LeaderboardEntry(
        name=name, authors="t", url=None, description="", track="A", privileged=False, deterministic=True,
        entry_point=name, method_hash=f"{i:064x}", weights_sha256=None, suite_name=suite, suite_version="1",
        suite_sha256="0" * 64, verified=False, trusted=True, verification_seed=None, verified_episodes=0, score=None,
        delay_ms=1.0, energy_j=None, jitter=None, package_version="0", git_commit=None,
        results_json=dumps_results(results), created_utc=datetime(2025, 1, 1, tzinfo=timezone.utc) + timedelta(i))


def test_a_v2_board_ranks_by_score_v2_with_the_cooperation_gain() -> None:
    keys = [(t, i) for t, gs in GAINS.items() for i in range(len(gs))]
    method = {k: 2.0 ** -GAINS[k[0]][k[1]] for k in keys}
    entries = [_entry("mine", method, "tiny-v2", 1), _entry("non-cooperative", dict.fromkeys(keys, 2.0), "tiny-v2", 2)]
    board = ranking.suite_board("tiny-v2", "1", entries)
    mine = next(s for s in board.standings if s.entry.name == "mine").score
    assert mine.version == 2 and mine.S == pytest.approx(_v2(GAINS).S)
    assert mine.cooperation.S == pytest.approx(mine.S + 1.0)
    # a v1 board stays score v1, without a cooperation gain
    v1 = ranking.suite_board("tiny", "1", [_entry("mine", method, "tiny", 1)]).standings[0].score
    assert v1.version == 1 and v1.cooperation is None and v1.S == pytest.approx(S.suite_score(_episodes(GAINS)).S)


# -- tracks ---------------------------------------------------------------------------------------

TRACK_OF = {SCALE8: "cooperative", SCALE16: "cooperative", NLOS: "robust-ranging", "swarmloc/Ideal-v1": None}


def test_tasks_split_by_track_headline_first_v1_last() -> None:
    got = tracks.tasks_by_track(["swarmloc/Ideal-v1", NLOS, SCALE8, SCALE16], TRACK_OF.get)
    assert got == {"cooperative": [SCALE8, SCALE16], "robust-ranging": [NLOS], None: ["swarmloc/Ideal-v1"]}
    with pytest.raises(ValueError, match="unknown track 'headline'"):
        tracks.tasks_by_track([SCALE8], lambda task: "headline")


def test_registered_tasks_name_their_track_v1_none() -> None:
    assert tracks.task_track("swarmloc/Scale8-v1") is None
    assert tracks.task_track("swarmloc/Scale8-v2") == "cooperative"
    assert tracks.task_track("swarmloc/AnchorNLOS-v2") == "robust-ranging"


def test_one_score_per_track() -> None:
    eps = _episodes(GAINS)
    alone = {(e["task"], e["seed"]): 1.0 for e in eps}
    by_track = tracks.track_scores(eps, list(GAINS), suite="standard-v2", non_cooperative=alone,
                                   track_of=TRACK_OF.get)
    assert list(by_track) == ["cooperative", "robust-ranging"]
    assert by_track["cooperative"].S == pytest.approx(2.0) and set(by_track["cooperative"].tasks) == {SCALE8, SCALE16}
    assert by_track["robust-ranging"].S == pytest.approx(0.125)
    assert by_track["robust-ranging"].cooperation.S == pytest.approx(0.125)
    assert all(math.isfinite(s.ci_low) for s in by_track.values())
