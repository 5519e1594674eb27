"""A method's training runs on the leaderboard: one standing scored by the IQM over runs with a CI over runs,
a repeated run counted once, privileged_training marked, the compute view, and the exports (CSV, JSON,
marl-eval's raw-data layout). Synthetic results only: no simulation."""

from __future__ import annotations

import csv
import hashlib
import io
import json
import re
import shutil
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np
import pytest
from rich.console import Console

from swarmloc.bench.evaluation.results import EpisodeMetrics, MethodInfo, SuiteInfo, dumps_results, make_results
from swarmloc.bench.scoring.runs import over_runs, run_mean_episodes
from swarmloc.bench.scoring.score import suite_score
from swarmloc.leaderboard.site import ranking, views
from swarmloc.leaderboard.site.compute import DELAY_BUDGET_MS
from swarmloc.leaderboard.store.database import LeaderboardStore
from swarmloc.leaderboard.store.records import LeaderboardEntry

TASKS = ("swarmloc/Ideal-v0", "swarmloc/NLOS-v0")  # an unversioned suite: score v1, S = mean over tasks of G_t
SEEDS = (0, 1, 2, 3)
UNIFORM = {(t, s): 1.0 + 0.5 * i + 0.1 * s for i, t in enumerate(TASKS) for s in SEEDS}
TASK_OFFSET = {"swarmloc/Ideal-v0": 0.0, "swarmloc/NLOS-v0": 0.2}
SEED_WIGGLE = (0.1, -0.1, 0.05, -0.05)  # averages to 0 over a task's seeds
#: the learned method's three runs: run seed → c_r; run r's gain on (t, s) is c_r + offset_t + wiggle_s
RUNS = {1: 0.2, 2: 0.8, 3: 0.5}
#: its mean delay per update [ms] per task: one task over the 50 ms budget
DELAY = {"swarmloc/Ideal-v0": 30.0, "swarmloc/NLOS-v0": 80.0}
T0 = datetime(2026, 1, 1, tzinfo=timezone.utc)


def _entry(name: str, c: float | None, *, i: int, run: int | None = None, weights: str | None = None,
           privileged_training: bool = False, flops: float | None = None,
           delay: dict[str, float] | None = None) -> LeaderboardEntry:
    """An entry whose gain on (t, s) is c + offset_t + wiggle_s (RMSE = uniform's · 2^-g; c None: uniform itself)."""
    episodes = [{"task": t, "seed": s, "metrics": EpisodeMetrics.of(
        rmse=UNIFORM[t, s] * 2.0 ** -(0.0 if c is None else c + TASK_OFFSET[t] + SEED_WIGGLE[s]),
        uniform_rmse=UNIFORM[t, s],
        delay_ms=None if delay is None else delay[t])} for t in TASKS for s in SEEDS]
    method = MethodInfo(name=name, entry_point=name, weights_sha256=weights, privileged=False, track="A",
                        deterministic=True, privileged_training=privileged_training, run=run, flops_per_channel=flops)
    results = make_results(method, SuiteInfo(name="tiny", version="1", sha256="0" * 64), episodes)
    return LeaderboardEntry(
        name=name, authors="t", url=None, description="", track="A", privileged=False, deterministic=True,
        entry_point=name, method_hash=f"{i:064x}", weights_sha256=weights, suite_name="tiny", suite_version="1",
        suite_sha256="0" * 64, verified=False, trusted=True, verification_seed=None, verified_episodes=0, score=None,
        delay_ms=None if delay is None else sum(delay.values()) / len(delay), energy_j=None, jitter=None,
        package_version="0", git_commit=None, results_json=dumps_results(results), created_utc=T0 + timedelta(minutes=i),
        run=run, privileged_training=privileged_training, flops_per_channel=flops,
        task_aggregates={t: {m: a for m, a in per.items() if a is not None} for t, per in results.aggregates.items()})


def _learned(seed: int, i: int, shift: float = 0.0, **changes) -> LeaderboardEntry:
    """Run ``seed`` of 'learned' (its weights' hash is the seed's hex digit repeated; ``shift`` moves every gain)."""
    kwargs = {"run": seed, "weights": f"{seed:x}" * 64, "privileged_training": True, "flops": 150_000.0,
              "delay": DELAY} | changes
    return _entry("learned", RUNS[seed] + shift, i=i, **kwargs)


@pytest.fixture
def store(tmp_path: Path):
    """uniform; three runs of 'learned'; the chosen run shipped again twice (same weights; same episodes, no run
    declared); a classical method of one run."""
    with LeaderboardStore(f"sqlite:///{tmp_path / 'lb.db'}") as s:
        for entry in (_entry("uniform", None, i=0, flops=0.0), _learned(1, 1), _learned(2, 2), _learned(3, 3),
                      _learned(3, 4, 1e-3, run=None),  # the same weights as run 3 (re-run on another machine)
                      _learned(3, 5, run=None, weights=None),  # the same episodes as run 3
                      _entry("classic", 0.3, i=6, flops=4.0, delay=dict.fromkeys(TASKS, 0.03))):
            s.add(entry)
        yield s


def _board(store: LeaderboardStore) -> ranking.SuiteBoard:
    (board,) = ranking.suite_boards(store.entries())
    return board


# -- the score over runs ---------------------------------------------------------------------------


def test_three_runs_are_one_standing_scored_by_their_iqm(store: LeaderboardStore) -> None:
    board = _board(store)
    assert [(s.entry.name, s.n_runs) for s in board.ranked] == [("learned", 3), ("classic", 1), ("uniform", 1)]
    learned = board.ranked[0]
    # S_r = c_r + mean over tasks of the offsets (the wiggles average out); the IQM of three values is their mean
    per_run = [c + 0.1 for c in RUNS.values()]
    assert learned.over_runs.runs == pytest.approx(per_run)
    assert learned.score.S == pytest.approx(np.mean(per_run)) == pytest.approx(0.6)
    assert min(per_run) <= learned.score.ci_low < 0.6 < learned.score.ci_high <= max(per_run)
    assert [r.entry.run for r in learned.runs] == [1, 2, 3] and learned.entry.run == 3  # the run nearest the IQM
    # the per-task columns are the run-mean's: G_t averaged over runs
    assert learned.score.tasks["swarmloc/NLOS-v0"].mean == pytest.approx(0.5 + 0.2)
    # a method of one run shows as before: its own score and CI
    classic = board.ranked[1]
    alone = suite_score(ranking.episodes_of(classic.entry), TASKS, suite="tiny")
    assert (classic.score.S, classic.score.ci_low, classic.score.ci_high) == (alone.S, alone.ci_low, alone.ci_high)
    assert classic.runs == () and classic.over_runs is None


def test_the_iqm_over_runs_trims_a_quarter_from_each_end() -> None:
    """rliable's IQM: with four runs the best and the worst are dropped (0.4, where the mean is 0.6); one run
    gives its own S and CI exactly."""
    def run(c: float):
        return suite_score([{"task": t, "seed": s, "metrics": {"rmse": UNIFORM[t, s] * 2.0 ** -c,
                                                                "uniform_rmse": UNIFORM[t, s]}}
                            for t in TASKS for s in SEEDS], suite="tiny")

    four = over_runs([run(c) for c in (0.1, 0.3, 0.5, 1.5)])
    assert four.S == pytest.approx(0.4) and four.n_runs == 4 and four.ci_low <= 0.4 <= four.ci_high
    one = run(0.7)
    assert (over_runs([one]).S, over_runs([one]).ci_low, over_runs([one]).ci_high) == (one.S, one.ci_low, one.ci_high)
    with pytest.raises(ValueError, match="different \\(task, seed\\) episodes"):
        run_mean_episodes([[{"task": "a", "seed": 0, "metrics": {}}], [{"task": "a", "seed": 1, "metrics": {}}]])


def test_a_repeated_run_counts_once(store: LeaderboardStore) -> None:
    """Six stored 'learned' entries, three runs: the same weights, or the same episodes, as a run is that run."""
    assert sum(e.name == "learned" for e in store.entries()) == 5
    learned = _board(store).ranked[0]
    assert learned.n_runs == 3 and {e.id for e in learned.entries} == {2, 3, 4}
    assert all(s.entry.name != "learned" for s in _board(store).standings[1:])


def test_runs_that_cover_other_tasks_stand_apart(tmp_path: Path) -> None:
    with LeaderboardStore(f"sqlite:///{tmp_path / 'lb.db'}") as s:
        s.add(_entry("uniform", None, i=0))
        s.add(_learned(1, 1))
        half = _learned(2, 2)
        raw = json.loads(half.results_json)
        for ep in raw["episodes"]:
            if ep["task"] == TASKS[1]:
                ep["metrics"]["rmse"] = None
        s.add(LeaderboardEntry(**{**half.__dict__, "results_json": json.dumps(raw)}))
        board = _board(s)
    assert [(st.entry.name, st.n_runs, st.full) for st in board.standings] == [
        ("learned", 1, True), ("uniform", 1, True), ("learned", 1, False)]


# -- privileged_training and the compute view --------------------------------------------------------


def _text(store: LeaderboardStore, view: str = "accuracy") -> str:
    console = Console(width=views.TERMINAL_WIDTH, record=True, color_system=None)
    views.print_leaderboard(store, console=console, view=view)
    return " ".join(console.export_text().split())


def test_the_terminal_marks_privileged_training_and_counts_runs(store: LeaderboardStore) -> None:
    text = _text(store)
    assert "learned ‡ (3 runs)" in text and "classic ‡" not in text
    assert "‡ fitted to privileged labels while training" in text and "interquartile mean over runs" in text


def test_the_compute_view_puts_the_delay_beside_the_budget(store: LeaderboardStore) -> None:
    assert DELAY_BUDGET_MS == 50.0
    text = _text(store, "compute")
    assert "budget 50 ms per update" in text
    row = re.search(r"learned ‡ \(3 runs\) A (\S+) (\S+) (\S+) (\S+) (\S+) (\S+)", text).groups()
    assert row == ("1.52", "55.00", "NLOS", "80.00", "1/2", "150,000")  # 2^0.6, mean delay, worst task, over 50 ms
    assert re.search(r"uniform A 1.00 not measured — — 0\b", text)
    with pytest.raises(ValueError, match="unknown view 'speed'; allowed: 'accuracy', 'compute'"):
        views.leaderboard_tables(store, view="speed")  # type: ignore[arg-type]


def test_the_site_marks_privileged_training_and_shows_the_compute_view(store: LeaderboardStore,
                                                                      tmp_path: Path) -> None:
    index = views.render_html(store, tmp_path / "site", plots=False, explanations=False).read_text()
    learned = _board(store).ranked[0]
    row = re.search(rf'<tr data-method-id="{learned.entry.id}">(.*?)</tr>', index).group(1)
    assert "‡" in row and "3 runs" in row
    assert "fitted to privileged labels while training" in index
    compute = re.search(r'<table class="sortable" id="compute-tiny-1">(.*?)</table>', index, re.DOTALL).group(1)
    assert "55.00" in compute and "150,000" in compute and "not measured" in compute
    page = (tmp_path / "site" / "methods" / f"{learned.entry.id}.html").read_text()
    assert "3 training runs" in page and "fitted to privileged labels while training" in page
    for entry in learned.entries:  # every run's results file can be downloaded
        assert f"../results/{entry.id}.json" in page and (tmp_path / "site" / "results" / f"{entry.id}.json").is_file()


# -- the exports -----------------------------------------------------------------------------------


def test_the_json_and_csv_exports_carry_the_runs_and_how_the_method_was_made(store: LeaderboardStore) -> None:
    rows = {row["name"]: row for row in json.loads(views.export(store, "json"))}
    learned = rows["learned"]
    assert (learned["runs"], learned["run_seeds"]) == (3, [1, 2, 3])
    assert learned["runs_S"] == pytest.approx([0.3, 0.9, 0.6])
    assert learned["runs_iqm"] == pytest.approx(0.6) == pytest.approx(learned["S"])
    assert learned["runs_ci_low"] < 0.6 < learned["runs_ci_high"]
    assert learned["privileged_training"] is True and rows["classic"]["privileged_training"] is False
    assert (learned["delay_ms"], learned["delay_worst_task"], learned["delay_worst_ms"]) == (55.0, TASKS[1], 80.0)
    assert (learned["delay_budget_ms"], learned["tasks_over_delay_budget"], learned["flops_per_channel"]) == (
        50.0, 1, 150_000.0)
    assert (rows["classic"]["runs"], rows["classic"]["run_seeds"]) == (1, [None])
    assert rows["uniform"]["delay_ms"] is None and rows["uniform"]["tasks_over_delay_budget"] is None
    table = {row["name"]: row for row in csv.DictReader(io.StringIO(views.export(store, "csv")))}
    assert (table["learned"]["runs"], table["learned"]["run_seeds"]) == ("3", "1;2;3")
    assert float(table["learned"]["runs_iqm"]) == pytest.approx(0.6) and table["learned"]["privileged_training"] == "True"
    assert table["learned"]["flops_per_channel"] == "150000.0" and table["classic"]["tasks_over_delay_budget"] == "0"
    with pytest.raises(ValueError, match="unknown export format 'xml'; allowed: 'csv', 'json', 'marl-eval'"):
        views.export(store, "xml")  # type: ignore[arg-type]


def test_the_marl_eval_export_has_the_layout_marl_eval_reads(store: LeaderboardStore) -> None:
    """{env: {task: {algorithm: {run_k: {"step_0": {"step_count", metrics}, "absolute_metrics": {metrics}}}}}}:
    every algorithm of the environment under every task, the runs run_0…, one value per episode, finite."""
    data = json.loads(views.export(store, "marl-eval"))
    assert list(data) == ["swarmloc-tiny"]
    env = data["swarmloc-tiny"]
    assert list(env) == list(TASKS)
    for task in TASKS:
        assert sorted(env[task]) == ["classic", "learned", "uniform"]
        assert list(env[task]["learned"]) == ["run_0", "run_1", "run_2"] and list(env[task]["classic"]) == ["run_0"]
        for algorithm in env[task].values():
            for run in algorithm.values():
                assert list(run) == ["step_0", "absolute_metrics"]  # the absolute metrics last, as marl-eval logs
                assert run["step_0"]["step_count"] == 0
                assert set(run["step_0"]) == {"step_count", "gain", "rmse"} and set(run["absolute_metrics"]) == {
                    "gain", "rmse"}
                assert len(run["absolute_metrics"]["gain"]) == len(run["absolute_metrics"]["rmse"]) == len(SEEDS)
    # run_k is the k-th run in run-seed order, one value per seed in seed order: g = log2(RMSE_uniform / RMSE)
    gains = env[TASKS[1]]["learned"]["run_1"]["absolute_metrics"]["gain"]
    assert gains == pytest.approx([RUNS[2] + 0.2 + w for w in SEED_WIGGLE])
    rmse = env[TASKS[1]]["learned"]["run_1"]["absolute_metrics"]["rmse"]
    assert rmse == pytest.approx([UNIFORM[TASKS[1], s] * 2.0 ** -g for s, g in zip(SEEDS, gains)])


# -- the shipped runs ------------------------------------------------------------------------------


def test_the_shipped_chosen_run_is_stored_once(tmp_path: Path) -> None:
    """A learned method ships <method>.seed<k>.json (its run and weights) beside <method>.json, the chosen run
    again: the store keeps the run, with the shipped weights file, and reports the other file present."""
    from swarmloc.agents.registry import WEIGHTS_DIR
    from swarmloc.bench.evaluation.shipped import RESULTS_DIRS
    from swarmloc.leaderboard.store.shipped import load_shipped

    digest = hashlib.sha256((WEIGHTS_DIR / "mappo.pt").read_bytes()).hexdigest()
    shipped = tmp_path / "shipped"
    shipped.mkdir()
    raw = json.loads((RESULTS_DIRS["standard-v0"] / "mappo.json").read_text())
    for name, run in (("mappo.json", None), ("mappo.seed1.json", 1)):
        raw["method"] |= {"weights_sha256": digest, "run": run}
        raw["provenance"]["created_utc"] = f"2026-01-0{2 - (run or 0)}T00:00:00Z"  # the two files differ in text
        (shipped / name).write_text(json.dumps(raw))
    with LeaderboardStore(f"sqlite:///{tmp_path / 'lb.db'}") as store:
        loaded = load_shipped(store, shipped)
        assert (loaded.stored, loaded.present, loaded.refused) == (("mappo",), ("mappo",), ())
        (entry,) = store.entries()
        assert (entry.run, entry.weights_sha256) == (1, digest)
        again = load_shipped(store, shipped)
        assert again.stored == () and store.count() == 1
        shutil.copy(shipped / "mappo.seed1.json", shipped / "other.seed1.json")
        raw["method"]["weights_sha256"] = "0" * 64
        (shipped / "mappo.seed2.json").write_text(json.dumps(raw))
        refused = dict(load_shipped(store, shipped).refused)
        assert "not among the shipped weights" in refused["mappo.seed2.json"]


def test_a_v2_suite_shows_the_runs_on_each_track(tmp_path: Path) -> None:
    """Scores never mix tracks: the runs are one standing on each track's board, with the track's IQM over runs;
    marl-eval gets one environment per track; every run has its page, with a score line per track."""
    import dataclasses

    from test_leaderboard_tracks import COOPERATIVE, ROBUST
    from test_leaderboard_tracks import UNIFORM as V2_UNIFORM
    from test_leaderboard_tracks import _entry as v2_entry

    with LeaderboardStore(f"sqlite:///{tmp_path / 'lb.db'}") as s:
        s.add(v2_entry("uniform", dict.fromkeys(V2_UNIFORM, 0.0), i=0))
        for k, c in ((1, 0.2), (2, 0.8), (3, 0.5)):
            entry = v2_entry("learned", dict.fromkeys(V2_UNIFORM, c), i=k)
            s.add(dataclasses.replace(entry, run=k, weights_sha256=f"{k:x}" * 64, privileged_training=True))
        entries = s.entries()
        rows = json.loads(views.export(s, "json"))
        marl = json.loads(views.export(s, "marl-eval"))
        views.render_html(s, tmp_path / "site", plots=False, explanations=False)
    per_track = ranking.track_boards(ranking.suite_board("tiny-v2", "1", entries), entries)
    assert list(per_track) == ["cooperative", "robust-ranging"]
    for board in per_track.values():
        learned = next(st for st in board.ranked if st.entry.name == "learned")
        assert learned.n_runs == 3 and learned.score.S == pytest.approx(0.5)
    assert [(r["suite_track"], r["runs"]) for r in rows if r["name"] == "learned"] == [
        ("cooperative", 3), ("robust-ranging", 3)]
    assert set(marl) == {"swarmloc-tiny-v2-cooperative", "swarmloc-tiny-v2-robust-ranging"}
    assert set(marl["swarmloc-tiny-v2-cooperative"]) == set(COOPERATIVE)
    assert set(marl["swarmloc-tiny-v2-robust-ranging"]) == set(ROBUST)
    for entry in entries[1:]:
        page = (tmp_path / "site" / "methods" / f"{entry.id}.html").read_text()
        assert "Score, cooperative track" in page and "Score, robust-ranging track" in page
        assert f"This page is run {entry.run}'s" in page
