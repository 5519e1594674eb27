"""Benchmark v2 on the leaderboard site: rliable's plot data against closed forms, and a v2 board's
front page with one section per track (score with CIs, performance profiles, probability of
improvement, method × family heat map). Synthetic episodes only: no simulation."""

from __future__ import annotations

import re
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np
import pytest

from swarmloc.bench.evaluation.results import EpisodeMetrics, MethodInfo, SuiteInfo, dumps_results, make_results
from swarmloc.bench.scoring import profiles as P
from swarmloc.bench.scoring import score as S
from swarmloc.leaderboard.site import ranking, views
from swarmloc.leaderboard.store.database import LeaderboardStore
from swarmloc.leaderboard.store.records import LeaderboardEntry

# -- the plot data against closed forms ------------------------------------------------------------

GAINS = {"swarmloc/Scale8-v2": np.array([1.0, -0.5, 2.0]), "swarmloc/Scale16-v2": np.array([0.0, 3.0]),
         "swarmloc/TDOA-v2": np.array([-1.0, 0.5, 0.5, 4.0])}
FAMILIES = {"Scale": ("swarmloc/Scale8-v2", "swarmloc/Scale16-v2"), "TDOA": ("swarmloc/TDOA-v2",)}


def test_a_method_better_on_every_run_improves_with_probability_one() -> None:
    worse = {t: g - 10.0 for t, g in GAINS.items()}
    assert P.probability_of_improvement(GAINS, worse) == 1.0
    assert P.probability_of_improvement(worse, GAINS, families=FAMILIES) == 0.0
    assert P.probability_of_improvement(GAINS, GAINS) == 0.5  # identical: every tie counts half, P = ½ exactly
    matrix = P.improvement_matrix([GAINS, worse, GAINS], families=FAMILIES)
    np.testing.assert_array_equal(matrix, [[0.5, 1.0, 0.5], [0.0, 0.5, 0.0], [0.5, 1.0, 0.5]])
    everywhere = P.improvement_over_uniform({t: np.abs(g) + 0.1 for t, g in GAINS.items()}, families=FAMILIES)
    assert (everywhere.p, everywhere.ci_low, everywhere.ci_high) == (1.0, 1.0, 1.0)
    level = P.improvement_over_uniform({t: np.zeros_like(g) for t, g in GAINS.items()})  # uniform itself
    assert (level.p, level.ci_low, level.ci_high) == (0.5, 0.5, 0.5)


def test_probability_of_improvement_weighs_families_as_score_v2() -> None:
    y = {t: np.zeros(1) for t in GAINS}  # one run of gain 0: P_t = fraction above 0, ties half
    per_task = {"swarmloc/Scale8-v2": 2 / 3, "swarmloc/Scale16-v2": 0.75, "swarmloc/TDOA-v2": 0.75}
    assert P.probability_of_improvement(GAINS, y) == pytest.approx(np.mean(list(per_task.values())))
    by_family = np.mean([(2 / 3 + 0.75) / 2, 0.75])
    assert P.probability_of_improvement(GAINS, y, families=FAMILIES) == pytest.approx(by_family)
    # over uniform: the same number, with the score's own bootstrap around it
    found = P.improvement_over_uniform(GAINS, families=FAMILIES)
    assert found.p == pytest.approx(by_family) and 0.0 <= found.ci_low <= found.p <= found.ci_high <= 1.0
    with pytest.raises(ValueError, match="in no family"):
        P.probability_of_improvement(GAINS, y, families={"Scale": FAMILIES["Scale"]})


def test_the_profile_is_the_family_weighted_fraction_and_its_area_the_clipped_mean() -> None:
    taus = np.linspace(-2.0, 5.0, 7001)
    profile = P.performance_profile(GAINS, taus, families=FAMILIES)
    # at τ = 0: Scale8 2/3, Scale16 1/2 (0 is not > 0), TDOA 3/4; Scale's two tasks share one family's weight
    assert P.performance_profile(GAINS, [0.0], families=FAMILIES)[0] == pytest.approx(((2 / 3 + 1 / 2) / 2 + 0.75) / 2)
    assert np.all(np.diff(profile) <= 0.0) and profile[0] == 1.0 and profile[-1] == 0.0
    # ∫_a^b profile(τ) dτ = E[clip(g, a, b)] − a under the same weights: the score of the clipped gains
    for a, b in ((-2.0, 5.0), (-0.75, 3.5)):  # the whole range, and one that clips both tails
        taus_ab = np.linspace(a, b, 9001)
        clipped = {t: np.clip(g, a, b) for t, g in GAINS.items()}
        expected = float(S.suite_statistic(FAMILIES, {t: g.mean() for t, g in clipped.items()})) - a
        area = np.trapezoid(P.performance_profile(GAINS, taus_ab, families=FAMILIES), taus_ab)
        assert area == pytest.approx(expected, abs=2e-3)
    # without families, tasks weigh equally (score v1's profile, as before)
    assert P.performance_profile(GAINS, [0.0])[0] == pytest.approx((2 / 3 + 1 / 2 + 3 / 4) / 3)


def test_the_profile_band_holds_the_profile_and_is_a_point_for_constant_runs() -> None:
    taus = np.linspace(-2.0, 5.0, 29)
    low, high = P.profile_interval(GAINS, taus, families=FAMILIES, n_resamples=500)
    profile = P.performance_profile(GAINS, taus, families=FAMILIES)
    assert low.shape == high.shape == taus.shape and np.all(low <= high)
    assert np.all(low <= profile + 1e-12) and np.all(profile <= high + 1e-12)
    constant = {t: np.full(3, 1.5) for t in GAINS}
    low, high = P.profile_interval(constant, taus, families=FAMILIES, n_resamples=200)
    np.testing.assert_array_equal(low, high)
    np.testing.assert_array_equal(low, (taus < 1.5).astype(float))


# -- a v2 board on the front page ------------------------------------------------------------------

COOPERATIVE = ("swarmloc/Scale8-v2", "swarmloc/Scale16-v2", "swarmloc/CascadedFault-v2")
ROBUST = ("swarmloc/AnchorNLOS-v2", "swarmloc/TDOA-v2")
SEEDS = (0, 1, 2)
UNIFORM = {(t, s): 1.0 + 0.1 * i + 0.01 * s for i, t in enumerate(COOPERATIVE + ROBUST) for s in SEEDS}
T0 = datetime(2026, 1, 1, tzinfo=timezone.utc)


def _entry(name: str, gain: dict[tuple[str, int], float | None], *, i: int, suite: str = "tiny-v2",
           privileged: bool = False) -> LeaderboardEntry:
    """An entry with these per-episode gains over uniform (RMSE = uniform's · 2^-g; None: not run)."""
    episodes = [{"task": t, "seed": s, "metrics": EpisodeMetrics.of(
        rmse=None if g is None else UNIFORM[t, s] * 2.0 ** -g, uniform_rmse=UNIFORM[t, s], delay_ms=1.0)}
        for (t, s), g in gain.items()]
    results = make_results(MethodInfo(name=name, entry_point=name, privileged=privileged, track="A",
                                      deterministic=True), SuiteInfo(name=suite, version="1", sha256="0" * 64), episodes)
    return LeaderboardEntry(
        name=name, authors="t", url=None, description="", track="A", privileged=privileged, deterministic=True,
        entry_point=name, method_hash=f"{i:064x}", weights_sha256=None, suite_name=suite, suite_version="1",
        suite_sha256="0" * 64, verified=False, trusted=True, verification_seed=None, verified_episodes=0, score=None,
        delay_ms=1.0, energy_j=None, jitter=None, package_version="0", git_commit=None,
        results_json=dumps_results(results), created_utc=T0 + timedelta(minutes=i))


def v2_entries(suite: str = "tiny-v2") -> list[LeaderboardEntry]:
    """uniform, non-cooperative, two methods, one partial (no TDOA), a privileged oracle."""
    rng = np.random.default_rng(3)
    keys = list(UNIFORM)

    def drawn(centre: float, spread: float) -> dict[tuple[str, int], float | None]:
        return {k: float(centre + spread * rng.standard_normal()) for k in keys}

    return [
        _entry("uniform", dict.fromkeys(keys, 0.0), i=0, suite=suite),
        _entry("non-cooperative", {k: -0.6 if k[0] in COOPERATIVE else 0.0 for k in keys}, i=1, suite=suite),
        _entry("trust-a", drawn(0.6, 0.3), i=2, suite=suite),
        _entry("trust-b", drawn(0.2, 0.6), i=3, suite=suite),
        _entry("no-tdoa", {k: None if k[0] == "swarmloc/TDOA-v2" else 0.4 for k in keys}, i=4, suite=suite),
        _entry("oracle", drawn(1.5, 0.2), i=5, suite=suite, privileged=True),
    ]


def test_a_v2_suite_has_one_board_per_track_and_a_v1_suite_none() -> None:
    entries = v2_entries()
    board = ranking.suite_board("tiny-v2", "1", entries)
    boards = ranking.track_boards(board, entries)
    assert list(boards) == ["cooperative", "robust-ranging"]
    assert boards["cooperative"].tasks == COOPERATIVE and boards["robust-ranging"].tasks == ROBUST
    trust_a = next(s for s in boards["cooperative"].ranked if s.entry.name == "trust-a").score
    assert trust_a.version == 2 and set(trust_a.families) == {"Scale", "Cascaded"}
    assert trust_a.cooperation is not None and trust_a.cooperation.S == pytest.approx(trust_a.S + 0.6)
    # no-tdoa covers the cooperative track in full and the robust-ranging one in part
    assert "no-tdoa" in [s.entry.name for s in boards["cooperative"].ranked]
    assert [s.entry.name for s in boards["robust-ranging"].partial] == ["no-tdoa"]
    v1 = [_entry(e.name, {k: 0.0 for k in UNIFORM}, i=n, suite="tiny-v1") for n, e in enumerate(entries[:2])]
    assert ranking.track_boards(ranking.suite_board("tiny-v1", "1", v1), v1) == {}


FIGURES = ("score.svg", "profiles.svg", "improvement.svg", "improvement_pairs.svg", "family_heatmap.svg")


def test_the_front_page_shows_each_track_with_its_figures(tmp_path: Path) -> None:
    with LeaderboardStore(f"sqlite:///{tmp_path / 'lb.db'}") as store:
        for entry in v2_entries():
            store.add(entry)
        page = views.render_html(store, tmp_path / "site", plots=False, explanations=False).read_text()
    site = tmp_path / "site"
    positions = []
    for track in ("cooperative", "robust-ranging"):
        section = re.search(rf'<section class="track" id="track-tiny-v2-1-{track}">(.*?)</section>', page, re.DOTALL)
        assert section is not None, track
        positions.append(section.start())
        for name in FIGURES:
            src = f"plots/suite-tiny-v2-1/{track}/{name}"
            assert f'src="{src}"' in section.group(1)
            svg = (site / src).read_text()
            assert svg.lstrip().startswith("<?xml") and "<svg" in svg and "<dc:date>" not in svg
    assert positions[0] < positions[1]  # the headline track first
    assert "Cooperative track (the headline)" in page and "3 tasks in 2 families: Scale (2), Cascaded (1)." in page
    assert "Probability of improvement (rliable)" in page and "Performance profiles (rliable)" in page
    assert "score.png" not in page  # no suite-wide plot mixes the tracks
    # the tables are per track too: no table spans both tracks
    assert 'id="ranked-tiny-v2-1"' not in page
    assert 'id="ranked-tiny-v2-1-cooperative"' in page and 'id="ranked-tiny-v2-1-robust-ranging"' in page


def test_track_figures_are_the_same_bytes_on_every_draw(tmp_path: Path) -> None:
    from swarmloc.leaderboard.site.track_plots import plot_improvement, plot_track_scores

    entries = v2_entries()
    board = ranking.track_boards(ranking.suite_board("tiny-v2", "1", entries), entries)["cooperative"]
    for draw in (plot_track_scores, plot_improvement):
        first = draw(board, "cooperative", tmp_path / "a.svg").read_bytes()
        assert draw(board, "cooperative", tmp_path / "b.svg").read_bytes() == first
