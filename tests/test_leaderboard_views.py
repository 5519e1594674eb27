"""Leaderboard views: ranking by the score, partial coverage, the 100-column terminal table,
the exports, the HTML site's plots, task families and method styles.

Entries go straight into a SQLite store (``LeaderboardStore.add``): validation and
verification are tested in ``test_leaderboard.py``; here only what the views make of entries.
"""

from __future__ import annotations

import io
import json
import math
from datetime import datetime, timedelta, timezone
from pathlib import Path

import pytest
from rich.console import Console

from swarmloc.cli import leaderboard_show
from swarmloc.bench.scoring.families import FAMILY_ORDER, group_by_family, task_base, task_family
from swarmloc.bench.reports.method_style import KNOWN_METHODS, method_style, method_styles
from swarmloc.bench.evaluation.results import (
    EpisodeMetrics,
    MethodInfo,
    SuiteInfo,
    dumps_results,
    make_results,
    suite_sha256,
)
from swarmloc.leaderboard.site import views
from swarmloc.leaderboard.site.ranking import suite_boards
from swarmloc.leaderboard.store.records import LeaderboardEntry
from swarmloc.leaderboard.store.database import LeaderboardStore

RESULTS_DIR = Path(__file__).resolve().parents[1] / "bench" / "results" / "standard-v0"
T0 = datetime(2026, 1, 1, tzinfo=timezone.utc)


def _entry(name: str, rmse: dict[tuple[str, int], float | None], *, i: int, entry_point: str | None = None,
           privileged: bool = False, uniform: dict | None = None, bound: dict | None = None,
           track: str = "A") -> LeaderboardEntry:
    """An entry whose results file has these per-episode RMSEs (and uniform/bound RMSEs if given)."""
    episodes = [{"task": t, "seed": s, "metrics": EpisodeMetrics.of(
        rmse=r, delay_ms=1.0,
        uniform_rmse=None if uniform is None else uniform[t, s],
        bound_rmse=None if bound is None else bound[t, s])} for (t, s), r in rmse.items()]
    results = make_results(
        MethodInfo(name=name, entry_point=entry_point or name, privileged=privileged, track=track, deterministic=True),
        SuiteInfo(name="tiny", version="1", sha256=suite_sha256(rmse)), episodes)
    return LeaderboardEntry(
        name=name, authors="t", url=None, description="", track=track, privileged=privileged, deterministic=True,
        entry_point=entry_point or name, method_hash=f"{i:064x}", weights_sha256=None, suite_name="tiny",
        suite_version="1", suite_sha256=results.suite.sha256, verified=False, trusted=True, verification_seed=None,
        verified_episodes=0, score=None, delay_ms=1.0, energy_j=None, jitter=None, package_version="0",
        git_commit=None, results_json=dumps_results(results), created_utc=T0 + timedelta(minutes=i))


TASKS = ("swarmloc/Ideal-v0", "swarmloc/NLOS-v0", "swarmloc/NLOSStep-v0")
KEYS = [(t, s) for t in TASKS for s in (1, 2)]
BASE = {k: 1.0 + 0.1 * n for n, k in enumerate(KEYS)}


def _scaled(factor: float, skip: tuple[str, ...] = ()) -> dict[tuple[str, int], float | None]:
    return {k: None if k[0] in skip else v * factor for k, v in BASE.items()}


@pytest.fixture
def store(tmp_path: Path) -> LeaderboardStore:
    """uniform, three public methods (one partial), an oracle; schema-1-like files (no uniform_rmse)."""
    s = LeaderboardStore(f"sqlite:///{tmp_path / 'lb.db'}")
    for i, entry in enumerate([
        _entry("uniform", _scaled(1.0), i=0),
        _entry("half", _scaled(0.5), i=1),                         # g = 1 everywhere: S = 1
        _entry("double", _scaled(2.0), i=2),                       # S = −1
        _entry("quarter-no-step", _scaled(0.25, ("swarmloc/NLOSStep-v0",)), i=3, track="B"),  # S = 2 on 2/3
        _entry("oracle", _scaled(0.125), i=4, privileged=True),
    ]):
        s.add(entry)
    yield s
    s.close()


# -- ranking -------------------------------------------------------------------------


def test_ranks_by_the_score_with_partial_coverage_apart(store: LeaderboardStore) -> None:
    (board,) = suite_boards(store.entries())
    assert board.tasks == TASKS
    assert [(s.rank, s.entry.name) for s in board.ranked] == [(1, "half"), (2, "uniform"), (3, "double")]
    assert [s.score.S for s in board.ranked] == pytest.approx([1.0, 0.0, -1.0])
    (partial,) = board.partial
    assert partial.entry.name == "quarter-no-step" and partial.rank == 1
    assert partial.score.S == pytest.approx(2.0) and partial.coverage(3) == (2, 3)
    assert partial.score.uncovered == ("swarmloc/NLOSStep-v0",)
    (oracle,) = board.privileged
    assert oracle.rank is None and oracle.score.S == pytest.approx(3.0)
    # every scored episode's uniform_rmse came from the uniform entry (the files predate schema 2);
    # the two NLOSStep episodes quarter-no-step did not run have no gain and are not counted
    assert board.reference.name == "uniform" and board.filled == 5 * len(KEYS) - 2
    assert partial.filled == len(KEYS) - 2
    assert views.split_ranked(store.entries()) == (
        [s.entry for s in board.ranked + board.partial], [oracle.entry])


def test_uniform_rmse_in_the_file_wins_over_the_fallback(tmp_path: Path) -> None:
    # the file's own uniform_rmse (here 4× its RMSE: g = 2) is used, not the stored uniform entry's
    own = _entry("own", _scaled(1.0), i=1, uniform=_scaled(4.0))
    board = suite_boards([_entry("uniform", _scaled(1.0), i=0), own])[0]
    assert board.ranked[0].entry.name == "own" and board.ranked[0].score.S == pytest.approx(2.0)
    assert board.ranked[0].filled == 0


def test_without_a_uniform_reference_nothing_is_guessed() -> None:
    entries = [_entry("a", _scaled(1.0), i=0), _entry("b", _scaled(0.5), i=1)]
    (board,) = suite_boards(entries)
    assert board.ranked == () and board.reference is None
    assert [s.score for s in board.partial] == [None, None] and [s.entry.name for s in board.partial] == ["a", "b"]


def test_gap_closed_where_the_bound_defines_one() -> None:
    bound = {k: v / 8.0 for k, v in BASE.items()}  # A_t = 3 everywhere
    half = _entry("half", _scaled(0.5), i=1, uniform=_scaled(1.0), bound=bound)
    (board,) = suite_boards([half])
    assert board.ranked[0].score.gap_closed == pytest.approx(1.0 / 3.0)


# -- terminal ------------------------------------------------------------------------


def _render(parts, width: int = views.TERMINAL_WIDTH) -> str:
    console = Console(width=width, record=True, file=io.StringIO())
    for part in parts:
        console.print(part)
    return console.export_text()


def test_terminal_view_columns_and_legend(store: LeaderboardStore) -> None:
    text = _render(views.leaderboard_tables(store))
    for header in ("#", "Method", "Trk", "2^S", "95% CI", "Gap", "Tasks", "Ideal", "NLOS"):
        assert header in text
    assert "Partial coverage on tiny v1" in text and text.index("Partial coverage") < text.index("quarter-no-step")
    assert text.index("Privileged methods") < text.index("oracle")
    assert "2/3" in text and "3/3" in text
    # the ranked table holds full coverage only, so it has no k/T column; the partial one does
    ranked_header = next(line for line in text.splitlines() if line.lstrip().startswith("# Method"))
    assert "Tasks" not in ranked_header and "covering all 3 tasks" in text
    assert "4.00" in text  # quarter-no-step covers NLOS-v0 only of its family: 2^2 with a star
    assert "4.00*" in text
    assert "taken from the stored uniform entry" in " ".join(text.split())  # the legend wraps
    per_task = _render(views.leaderboard_tables(store, family="nlos"))
    assert "Step" in per_task and "Ideal" not in per_task  # the NLOS tasks only
    with pytest.raises(ValueError, match=r"unknown task family 'Optics'; this suite's families: Ideal, NLOS"):
        views.leaderboard_tables(store, family="Optics")
    with pytest.raises(ValueError, match=r"task 'Scale2' is not in this suite; its tasks: Ideal, NLOS, NLOSStep"):
        views.leaderboard_tables(store, tasks="Ideal,Scale2")


def test_terminal_view_of_the_shipped_results_fits_100_columns(tmp_path: Path) -> None:
    """The standard-v0 results as shipped: 17 tasks, 7 families, names up to 19 characters."""
    with LeaderboardStore(f"sqlite:///{tmp_path / 'lb.db'}") as store:
        for i, path in enumerate(sorted(RESULTS_DIR.glob("*.json"))):
            raw = json.loads(path.read_text())
            m = raw["method"]
            store.add(LeaderboardEntry(
                name=m["name"], authors="t", url=None, description="", track=m["track"], privileged=m["privileged"],
                deterministic=True, entry_point=m["entry_point"], method_hash=f"{i:064x}", weights_sha256=None,
                suite_name=raw["suite"]["name"], suite_version=raw["suite"]["version"],
                suite_sha256=raw["suite"]["sha256"], verified=False, trusted=True, verification_seed=None,
                verified_episodes=0, score=None, delay_ms=None, energy_j=None, jitter=None, package_version="0",
                git_commit=None, results_json=path.read_text(), created_utc=T0 + timedelta(minutes=i)))
        (board,) = suite_boards(store.entries())
        names = [s.entry.name for s in board.ranked]
        # the acceptance: methods that beat uniform on most tasks above random, fixed and uniform
        for better in ("mappo", "mappo-no-smoothing", "mappo-accuracy-only", "chi2-soft", "chi2-gate", "huber"):
            assert all(names.index(better) < names.index(worse) for worse in ("random", "fixed", "uniform"))
        assert names[-1] == "dead-reckoning"
        for family, tasks in [(None, None), ("Scale", None), (None, "CascadedFaultRandom,CascadedFault,NLOSStep")]:
            parts = views.board_tables(board, family=family, tasks=tasks)
            for part in parts:
                if isinstance(part, views.Table):
                    # natural width within the terminal: rich never had to squeeze a column
                    assert Console(width=500).measure(part).maximum <= views.TERMINAL_WIDTH
            text = _render(parts)
            assert max(map(len, text.splitlines())) <= views.TERMINAL_WIDTH
            assert all(f" {name} " in text for name in names)  # every name whole, on one line
        with pytest.raises(ValueError, match="7 task columns do not fit a 100-column terminal"):
            views.board_tables(board, tasks="Scale2,Scale4,Scale6,Scale8,Scale16,Scale32,Ideal")


def test_show_command_options(store: LeaderboardStore) -> None:
    console = Console(record=True, width=100, file=io.StringIO())
    assert leaderboard_show.run(leaderboard_show.Options(db_url=store.url, tasks="NLOSStep"), console) == 0
    assert "Step" in console.export_text()
    assert leaderboard_show.run(leaderboard_show.Options(db_url=store.url, family="Nope"), console) == 2
    assert "unknown task family 'Nope'" in console.export_text()


# -- exports -------------------------------------------------------------------------


def test_exports_carry_the_score(store: LeaderboardStore) -> None:
    rows = json.loads(views.export(store, "json"))
    assert [(r["name"], r["table"], r["rank"], r["partial_rank"]) for r in rows] == [
        ("half", "ranked", 1, None), ("uniform", "ranked", 2, None), ("double", "ranked", 3, None),
        ("quarter-no-step", "partial", None, 1), ("oracle", "privileged", None, None)]
    half = rows[0]
    assert half["times_uniform"] == pytest.approx(2.0) and half["S"] == pytest.approx(1.0)
    assert (half["tasks_covered"], half["tasks_total"], half["uniform_rmse_filled"]) == (3, 3, 6)
    assert half["times[swarmloc/NLOS-v0]"] == pytest.approx(2.0) and half["gap_closed"] is None
    assert rows[3]["times[swarmloc/NLOSStep-v0]"] is None
    header = views.export(store, "csv").splitlines()[0]
    assert header.startswith("id,suite,suite_version,rank,name,") and "times_ci_low" in header
    assert "v0_score" not in header and "normalized" not in header  # the retired score is gone


# -- HTML ----------------------------------------------------------------------------


def test_site_has_the_tables_and_suite_plots(store: LeaderboardStore, tmp_path: Path) -> None:
    site = tmp_path / "site"
    index = views.render_html(store, site, plots=False)
    page = index.read_text()
    assert "v0 score" not in page and "normalized" not in page.lower()  # the retired score is gone
    for table in ("ranked-tiny-1", "partial-tiny-1", "privileged-tiny-1"):
        assert f'id="{table}"' in page
    assert "worst task: swarmloc/NLOS-v0" in page  # family cells name their worst task on hover
    # a partial-coverage method is compared with the ranked ones on its own tasks
    assert "over its 2 of 3 tasks only; on those tasks the best ranked method, half, has 2^S = 2.00" in page
    for name in ("score.png", "gain_heatmap.png", "profiles.png"):
        assert f'src="plots/suite-tiny-1/{name}"' in page
        assert (site / "plots" / "suite-tiny-1" / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "gap_heatmap.png" not in page  # no bound in these results: the heatmap shows G_t, and says so
    assert "Gap closed is undefined on every task of this suite" in page
    method = (site / "methods" / "2.html").read_text()
    assert "2.00 [2.00–2.00]× lower error than uniform" in method


def test_site_draws_the_gap_heatmap_when_a_bound_exists_and_names_are_plain_text(tmp_path: Path) -> None:
    bound = {k: v / 8.0 for k, v in BASE.items()}
    with LeaderboardStore(f"sqlite:///{tmp_path / 'lb.db'}") as store:
        store.add(_entry("$\\frac{a}{b}$ <b>x</b>", _scaled(0.5), i=1, uniform=_scaled(1.0), bound=bound))
        page = views.render_html(store, tmp_path / "site", plots=False).read_text()
    assert 'src="plots/suite-tiny-1/gap_heatmap.png"' in page and "Gap closed per method and task" in page
    assert "&lt;b&gt;x&lt;/b&gt;" in page and "<b>x</b>" not in page


# -- families and styles -------------------------------------------------------------


def test_every_registered_task_has_a_named_family() -> None:
    from swarmloc.envs.tasks.catalogue import CATALOGUE

    families = {task: task_family(task) for task in CATALOGUE}
    assert set(families.values()) <= set(FAMILY_ORDER)
    assert families["swarmloc/NLOSStep-v0"] == "NLOS" and families["swarmloc/Scale32-v0"] == "Scale"
    assert families["swarmloc/CascadedFaultRandom-v0"] == "Cascaded" and families["swarmloc/Indoor-v0"] == "Vision"
    assert families["swarmloc/HybridNoise50-v0"] == "Hybrid" and families["swarmloc/UTILFlight-v0"] == "Real"
    assert task_base("swarmloc/ScaleRandom-v1") == "Scale" and task_family("swarmloc/Optics3-v1") == "Optics"
    grouped = group_by_family(["swarmloc/Optics-v1", "swarmloc/Scale2-v0", "swarmloc/Ideal-v0", "swarmloc/Scale4-v0"])
    assert list(grouped) == ["Ideal", "Scale", "Optics"] and grouped["Scale"] == ["swarmloc/Scale2-v0", "swarmloc/Scale4-v0"]


def test_method_styles_are_stable_and_distinct() -> None:
    shipped = method_styles(KNOWN_METHODS)
    assert len({s.colour for s in shipped.values()}) == len(KNOWN_METHODS)  # 24 colours for 24 methods
    assert shipped["uniform"] != shipped["oracle"]
    assert (shipped["uniform"].colour, shipped["uniform"].linestyle) == ("#000000", "-")
    assert shipped["uniform"].linestyle != shipped["oracle"].linestyle
    # a method drawn alone or with others looks the same (unless its look is taken)
    assert method_styles(["oracle"])["oracle"] == method_style("oracle") == shipped["oracle"]
    assert method_styles(["my method", "uniform"]) == method_styles(["uniform", "my method"])
    many = method_styles([f"m{i}" for i in range(60)] + list(KNOWN_METHODS))
    assert len(set(many.values())) == 84  # never two alike
    assert many["uniform"] == shipped["uniform"]  # hashed names never push a shipped method away
    assert math.isclose(len({s.colour for s in method_styles([f"x{i}" for i in range(20)]).values()}), 20)


def test_methods_the_seeds_cannot_tell_apart_share_their_rank(tmp_path: Path) -> None:
    """The rank shown is 1 + the methods ahead beyond doubt (paired CI): a copy of uniform ties with it."""
    with LeaderboardStore(f"sqlite:///{tmp_path / 'lb.db'}") as s:
        for i, (name, factor) in enumerate([("uniform", 1.0), ("uniform-copy", 1.0), ("half", 0.5), ("double", 2.0)]):
            s.add(_entry(name, _scaled(factor), i=i))
        (board,) = suite_boards(s.entries())
        assert [(st.rank, st.separable_rank, st.entry.name) for st in board.ranked] == [
            (1, 1, "half"), (2, 2, "uniform"), (3, 2, "uniform-copy"), (4, 4, "double")]
        text = _render(views.leaderboard_tables(s))
        rows = [line.split()[:2] for line in text.splitlines() if line.split()[1:2] in (["uniform"], ["uniform-copy"])]
        assert rows == [["2", "uniform"], ["2", "uniform-copy"]]
        assert "methods that share a # are not told apart by the seeds" in " ".join(text.split())
        exported = json.loads(views.export(s, "json"))
        assert [(r["name"], r["rank"], r["separable_rank"]) for r in exported] == [
            ("half", 1, 1), ("uniform", 2, 2), ("uniform-copy", 3, 2), ("double", 4, 4)]
