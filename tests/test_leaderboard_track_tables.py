"""Scores never mix tracks, in every view of a benchmark v2 suite: the site's tables, the terminal view, the
exports, ``swarmloc compare`` and the results file's score block. Synthetic stores and results only."""

from __future__ import annotations

import csv
import io
import json
import re
import sys
from pathlib import Path

import pytest
from rich.console import Console

from swarmloc.bench.evaluation.results import EpisodeMetrics, MethodInfo, SuiteInfo, make_results, parse_results
from swarmloc.bench.scoring import compare as C
from swarmloc.bench.scoring.profiles import probability_of_improvement
from swarmloc.leaderboard.site import ranking, views
from swarmloc.leaderboard.store.database import LeaderboardStore

sys.path.insert(0, str(Path(__file__).parent))
from test_leaderboard_tracks import COOPERATIVE, ROBUST, UNIFORM, v2_entries

TRACKS = ("cooperative", "robust-ranging")


@pytest.fixture
def store(tmp_path: Path):
    with LeaderboardStore(f"sqlite:///{tmp_path / 'lb.db'}") as s:
        for entry in v2_entries():
            s.add(entry)
        yield s


def _boards(store: LeaderboardStore) -> dict[str, ranking.SuiteBoard]:
    entries = store.entries()
    return ranking.track_boards(ranking.suite_board("tiny-v2", "1", entries), entries)


# -- the site ------------------------------------------------------------------------------------


def test_the_site_has_one_set_of_tables_per_track_with_its_own_score(store: LeaderboardStore, tmp_path: Path) -> None:
    page = views.render_html(store, tmp_path / "site", plots=False, explanations=False).read_text()
    boards = _boards(store)
    for track in TRACKS:
        section = re.search(rf'<section class="track" id="track-tiny-v2-1-{track}">(.*?)</section>', page,
                            re.DOTALL).group(1)
        ranked = re.search(rf'<table class="sortable" id="ranked-tiny-v2-1-{track}">(.*?)</table>', section,
                           re.DOTALL).group(1)
        for standing in boards[track].ranked:  # each row's 2^S is the track's score, not the suite's
            row = re.search(rf'<tr data-method-id="{standing.entry.id}">(.*?)</tr>', ranked).group(1)
            assert f'data-value="{standing.score.times!r}"' in row
        assert ("2^C [95% CI]" in ranked) == (track == "cooperative")  # the cooperation gain: cooperative track only
        assert f"/{len(boards[track].tasks)}<" in ranked and "hierarchical-bootstrap" in ranked
    # no-tdoa runs the whole cooperative track but not TDOA: ranked there, partial on robust-ranging only
    assert 'id="partial-tiny-v2-1-robust-ranging"' in page and 'id="partial-tiny-v2-1-cooperative"' not in page
    assert 'id="privileged-tiny-v2-1-cooperative"' in page and 'id="ranked-tiny-v2-1"' not in page
    trust_a = next(s for s in boards["cooperative"].ranked if s.entry.name == "trust-a")
    method = (tmp_path / "site" / "methods" / f"{trust_a.entry.id}.html").read_text()
    assert "Score, cooperative track" in method and "Score, robust-ranging track" in method
    assert f"S = {trust_a.score.S:.3f}" in method and ">Score<" not in method


def test_the_cooperation_gain_cell_is_the_tracks(store: LeaderboardStore, tmp_path: Path) -> None:
    page = views.render_html(store, tmp_path / "site", plots=False, explanations=False).read_text()
    gain = next(s for s in _boards(store)["cooperative"].ranked if s.entry.name == "trust-a").score.cooperation
    assert gain is not None and f'data-value="{2.0 ** gain.S!r}"' in page


# -- the terminal --------------------------------------------------------------------------------


def test_the_terminal_view_ranks_each_track_apart(store: LeaderboardStore) -> None:
    console = Console(width=views.TERMINAL_WIDTH, record=True, color_system=None)
    views.print_leaderboard(store, console=console)
    text = console.export_text()
    heads = [text.index(f"suite tiny-v2 v1, {track} track (ranked by 2^S") for track in TRACKS]
    assert heads[0] < heads[1]
    cooperative, robust = text[heads[0]:heads[1]], text[heads[1]:]
    assert "2^C" in cooperative and "2^C" not in robust.split("Scores never mix tracks")[0]
    assert "Partial coverage on tiny-v2 v1, robust-ranging track" in robust
    assert "Partial coverage on tiny-v2 v1, cooperative track" not in cooperative
    assert max(len(line) for line in text.splitlines()) <= views.TERMINAL_WIDTH
    # --family picks columns within the track that holds the family; the other shows its families
    console = Console(width=views.TERMINAL_WIDTH, record=True, color_system=None)
    views.print_leaderboard(store, console=console, family="Scale")
    assert "Scale8" in console.export_text()
    with pytest.raises(ValueError, match="unknown task family"):
        views.leaderboard_tables(store, family="Nope")


# -- the exports ---------------------------------------------------------------------------------


def test_the_exports_hold_one_row_per_method_and_track(store: LeaderboardStore) -> None:
    rows = json.loads(views.export(store, "json"))
    boards = _boards(store)
    for track in TRACKS:
        mine = [r for r in rows if r["suite_track"] == track]
        assert [r["name"] for r in mine] == [s.entry.name for s in boards[track].standings]
        for r, s in zip(mine, boards[track].standings):
            assert r["S"] == (s.score.S if s.score else None) and r["tasks_total"] == len(boards[track].tasks)
            assert r["separable_rank"] == s.separable_rank
            assert all(key.removeprefix("times[").rstrip("]") in boards[track].tasks
                       for key in r if key.startswith("times["))
    trust_a = next(r for r in rows if r["name"] == "trust-a" and r["suite_track"] == "cooperative")
    assert trust_a["C"] is not None and trust_a["cooperation_times"] == pytest.approx(2.0 ** trust_a["C"])
    table = list(csv.DictReader(io.StringIO(views.export(store, "csv"))))
    assert len(table) == len(rows) and {r["suite_track"] for r in table} == set(TRACKS)


# -- compare -------------------------------------------------------------------------------------


def _results(name: str, gain: float, robust_gain: float, suite: str = "tiny-v2"):
    episodes = [{"task": t, "seed": s, "metrics": EpisodeMetrics.of(
        rmse=u * 2.0 ** -(gain if t in COOPERATIVE else robust_gain), uniform_rmse=u)} for (t, s), u in UNIFORM.items()]
    method = MethodInfo(name=name, entry_point=name, privileged=False, track="A", deterministic=True)
    return make_results(method, SuiteInfo(name=suite, version="1", sha256="0" * 64), episodes)


def test_compare_gives_one_verdict_per_track_and_refuses_to_mix() -> None:
    a, b = _results("a", 0.0, 0.0), _results("b", 1.0, -0.5)  # B ahead on cooperative, behind on robust-ranging
    with pytest.raises(ValueError, match="span the tracks cooperative, robust-ranging.*never mix tracks"):
        C.compare(a, b)
    with pytest.raises(ValueError, match="track 'headline' is not among"):
        C.compare(a, b, track="headline")
    both = C.compare_tracks(a, b, n_resamples=200)
    assert list(both.comparisons) == list(TRACKS) and both.not_compared == ()
    cooperative, robust = both.comparisons["cooperative"], both.comparisons["robust-ranging"]
    assert cooperative.track == "cooperative" and {t.task for t in cooperative.tasks} == set(COOPERATIVE)
    assert cooperative.difference.mean == pytest.approx(1.0) and cooperative.b_ahead
    assert robust.difference.mean == pytest.approx(-0.5) and robust.difference.ci_high < 0
    as_json = C.track_comparisons_dict(both)
    assert list(as_json["tracks"]) == list(TRACKS) and as_json["tracks"]["cooperative"]["track"] == "cooperative"
    # a v1 suite: one comparison, its JSON as before (no track key)
    v1 = C.compare_tracks(_results("a", 0.0, 0.0, "tiny"), _results("b", 1.0, 1.0, "tiny"), n_resamples=50)
    assert list(v1.comparisons) == [None] and "track" not in C.track_comparisons_dict(v1)


def test_compare_weighs_families_in_the_probability_of_improvement() -> None:
    # B wins Scale8 and Scale16 (one family), loses CascadedFault (another): tasks give 2/3, families 1/2
    a = _results("a", 0.0, 0.0)
    episodes = [{"task": t, "seed": s, "metrics": EpisodeMetrics.of(
        rmse=u * 2.0 ** (1.0 if t == "swarmloc/CascadedFault-v2" else -1.0), uniform_rmse=u)}
        for (t, s), u in UNIFORM.items() if t in COOPERATIVE]
    b = make_results(MethodInfo(name="b", entry_point="b", privileged=False, track="A", deterministic=True),
                     SuiteInfo(name="tiny-v2", version="1", sha256="0" * 64), episodes)
    c = C.compare(a, b, track="cooperative", n_resamples=50)
    assert c.p_improvement == pytest.approx(0.5)
    gains = ({t: s.gains for t, s in score.tasks.items()} for score in (c.score_b, c.score_a))
    assert probability_of_improvement(*gains) == pytest.approx(2 / 3)


def test_the_cli_prints_one_verdict_per_track(tmp_path: Path) -> None:
    from swarmloc.bench.evaluation.results import write_results
    from swarmloc.cli import compare as cli

    paths = [write_results(tmp_path / f"{n}.json", _results(n, g, r)) for n, g, r in (("a", 0, 0), ("b", 1, -0.5))]
    console = Console(width=120, record=True, color_system=None)
    out = tmp_path / "c.json"
    assert cli.run(cli.Options(str(paths[0]), str(paths[1]), resamples=100, json=out), console) == 0
    text = console.export_text()
    verdicts = re.findall(r"verdict \(([a-z-]+) track\): (.*)", text)
    assert verdicts == [("cooperative", "B is ahead beyond doubt"), ("robust-ranging", "A is ahead beyond doubt")]
    assert list(json.loads(out.read_text())["tracks"]) == list(TRACKS)


# -- the results file ----------------------------------------------------------------------------


def test_the_score_block_of_a_v2_file_holds_each_tracks_score() -> None:
    from swarmloc.bench.scoring.tracks import track_scores

    results = _results("b", 1.0, -0.5)
    block = results.score
    assert results.schema_version >= 5 and list(block.tracks) == list(TRACKS)
    expected = track_scores([e.model_dump() for e in results.episodes], list(results.aggregates), suite="tiny-v2")
    for track in TRACKS:
        assert block.tracks[track].S == pytest.approx(expected[track].S)
        assert (block.tracks[track].ci_low, block.tracks[track].ci_high) == (expected[track].ci_low,
                                                                             expected[track].ci_high)
    assert block.tracks["cooperative"].S == pytest.approx(1.0) and block.tracks["robust-ranging"].S == pytest.approx(-0.5)
    assert (block.tracks["robust-ranging"].covered, block.tracks["robust-ranging"].total) == (len(ROBUST), len(ROBUST))
    assert parse_results(results.model_dump_json()).score == block
    # a v1 suite's block has none; a schema-4 file (no tracks) still loads
    assert _results("b", 1.0, 1.0, "tiny").score.tracks is None
    raw = json.loads(results.model_dump_json())
    raw["schema_version"] = 4
    del raw["score"]["tracks"]
    assert parse_results(json.dumps(raw)).score.tracks is None
