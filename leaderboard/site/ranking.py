"""Ranking by the score, shared by the leaderboard views.

Per suite (name and version) every entry is scored
(:func:`swarmloc.bench.scoring.score.suite_score`, ``docs/scoring.md``): ``S`` = mean
over tasks of the mean per-episode gain ``log2(RMSE_uniform / RMSE)``, shown as ``2^S``.
Entries then fall into three tables:

* **ranked** — non-privileged methods that cover every task of the suite, by S (best first);
* **partial** — non-privileged methods that cannot run some tasks (null RMSE there), ranked
  apart by S over the tasks they cover (``k/T``), so they are compared only on those tasks;
  entries with no score at all come last, by age;
* **privileged** — methods that read ground truth (the oracle): shown apart, not ranked.

Ties go to the higher IQM of the gains, then to the older submission.

**Separable rank.** The order by S says nothing of whether the seeds can tell two neighbours
apart. Each ranked method also gets ``1 +`` the number of ranked methods ahead of it beyond
doubt: the 95 % CI of their paired difference in S (same tasks, same seeds; stratified
bootstrap) lies above 0 (:func:`swarmloc.bench.scoring.score.separable_ranks`). The views
show it as the rank; methods that share it are not told apart by the suite.

**The uniform fallback.** The score needs ``uniform_rmse`` per episode (results schema 2). A
results file without it (schema 1, e.g. the shipped standard-v0 results until they are
regenerated) takes it from the suite's stored ``uniform`` entry (entry point ``uniform``,
trusted before verified before older): the RMSE of uniform trust on the same (task, seed),
which is what ``uniform_rmse`` records. Nothing is estimated: an episode with no such entry
stays without a gain, and the count of filled episodes is kept (``Standing.filled``) and
shown by the views. This is valid while the stored results come from one simulator
version, as the suite hash (task specs) guarantees for a suite version.

**Score v2.** A v2 suite (name ending ``-v2``) is scored and ranked by score v2
(:func:`swarmloc.bench.scoring.score.score_version`): families weigh equally and the CIs and
separable ranks come from the hierarchical bootstrap. Its cooperation gain needs
``non-cooperative``'s RMSE per episode, which results files do not carry: it is taken, the way
the uniform fallback is, from the suite's ``non-cooperative`` entry (same preference), and is
None on a board without one.

**Runs.** The training runs of one method (entries that declare a ``run``, same name, entry point,
track and coverage: :mod:`swarmloc.leaderboard.site.runs`) are one standing, and an entry that
repeats one of them (same weights, or same episodes) is left out. Its score is the interquartile
mean over runs of the runs' S with a 95 % CI over runs, families and seeds
(:mod:`swarmloc.bench.scoring.runs`); it ranks by it, and its separable rank compares that IQM
on paired draws. Its per-task columns, gap closed and cooperation gain are those of the run-mean
(each episode's gain averaged over runs). A method with one run shows as before.

**Tracks.** A v2 suite's tasks fall into tracks (``spec.track``: cooperative, robust-ranging;
:mod:`swarmloc.bench.scoring.tracks`) whose scores never mix: :func:`track_boards` scores and
ranks each track's tasks as a board of their own, which the site draws a part of the front page
for (:mod:`swarmloc.leaderboard.site.track_plots`).
"""

from __future__ import annotations

import json
from collections.abc import Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from swarmloc.bench.evaluation.shipped import DEFAULT_SUITE
from swarmloc.bench.scoring.families import group_by_family, short_task, task_label
from swarmloc.bench.scoring.runs import OverRuns, over_runs, run_mean_episodes, separable_ranks_over_runs
from swarmloc.bench.scoring.score import SuiteScore, rmse_by_episode, score_version, suite_score
from swarmloc.bench.scoring.tracks import TRACKS, TrackOf, registered_track, tasks_by_track
from swarmloc.leaderboard.site.runs import Run, group_runs, representative, without_repeats
from swarmloc.leaderboard.store.database import LeaderboardEntry

SuiteKey = tuple[str, str]

#: entry point of the reference whose RMSE fills a missing ``uniform_rmse``
UNIFORM_ENTRY_POINT = "uniform"

#: entry point of the reference of score v2's cooperation gain
NON_COOPERATIVE_ENTRY_POINT = "non-cooperative"


@dataclass(frozen=True)
class Standing:
    """One entry on its suite's board.

    Attributes:
        entry: the stored submission.
        score: its score (None when no task has a gain: no ``uniform_rmse`` and no reference); the
            entry's own ``score`` (``records.EntryScore``) is the same without the uniform fallback.
        rank: 1-based place in its table (None for privileged methods).
        filled: episodes whose ``uniform_rmse`` came from the suite's ``uniform`` entry.
        separable_rank: in the ranked table, 1 + the ranked methods ahead of it beyond doubt
            (see the module docstring); None elsewhere.
        runs: the training runs it stands for when it stands for several (see "Runs" in the module
            docstring; ``entry`` is the one nearest their IQM), else empty.
        over_runs: the IQM over those runs with its CI, and each run's S (None for an entry alone);
            ``score`` then carries it as S and CI, and the run-mean of everything else.
    """

    entry: LeaderboardEntry
    score: SuiteScore | None
    rank: int | None
    filled: int
    separable_rank: int | None = None
    runs: tuple[Run, ...] = ()
    over_runs: OverRuns | None = None

    @property
    def n_runs(self) -> int:
        """The training runs this standing stands for (1 for an entry alone)."""
        return max(1, len(self.runs))

    @property
    def entries(self) -> tuple[LeaderboardEntry, ...]:
        """Its stored entries: the runs' (representative among them), or the entry alone."""
        return tuple(run.entry for run in self.runs) or (self.entry,)

    @property
    def full(self) -> bool:
        """True when the entry covers every task of the suite."""
        return self.score is not None and not self.score.uncovered

    def coverage(self, n_tasks: int) -> tuple[int, int]:
        """``(k, T)``: tasks with a score out of the suite's ``n_tasks``."""
        return (0 if self.score is None else len(self.score.tasks)), n_tasks


@dataclass(frozen=True)
class Column:
    """A group of tasks shown as one column: its header, hover text and tasks."""

    header: str
    title: str
    tasks: tuple[str, ...]


@dataclass(frozen=True)
class SuiteBoard:
    """One suite's leaderboard.

    Attributes:
        name, version: the suite.
        tasks: the suite's tasks, in results-file order.
        ranked: full-coverage, non-privileged standings, best first.
        partial: partial-coverage (or unscored) non-privileged standings, best first.
        privileged: privileged standings (not ranked; ordered the same way).
        reference: the ``uniform`` entry used for the fallback, if any.
    """

    name: str
    version: str
    tasks: tuple[str, ...]
    ranked: tuple[Standing, ...]
    partial: tuple[Standing, ...]
    privileged: tuple[Standing, ...]
    reference: LeaderboardEntry | None

    @property
    def standings(self) -> tuple[Standing, ...]:
        """Every standing: ranked, partial, privileged."""
        return self.ranked + self.partial + self.privileged

    @property
    def filled(self) -> int:
        """Episodes (over all entries) whose ``uniform_rmse`` came from the reference entry."""
        return sum(s.filled for s in self.standings)


# -- scoring ---------------------------------------------------------------------------


def episodes_of(entry: LeaderboardEntry) -> list[dict[str, Any]]:
    """The episodes of an entry's stored results file (plain dicts)."""
    return json.loads(entry.results_json)["episodes"]


def reference_entry(entries: Iterable[LeaderboardEntry],
                    entry_point: str = UNIFORM_ENTRY_POINT) -> LeaderboardEntry | None:
    """The suite's ``uniform`` entry (or that of another reference's entry point): trusted before verified
    before older; None if absent."""
    candidates = [e for e in entries if e.entry_point == entry_point and not e.privileged]
    if not candidates:
        return None
    return min(candidates, key=lambda e: (not e.trusted, not e.verified, e.created_utc, e.id or 0))


def fill_uniform_rmse(episodes: Sequence[Mapping[str, Any]],
                      reference: Mapping[tuple[str, int], float | None]) -> tuple[list[dict[str, Any]], int]:
    """Episodes with an RMSE but no ``uniform_rmse`` filled from the reference's RMSE on the same (task, seed).

    An episode the method did not run (no RMSE) has no gain either way and is left as it is.

    Args:
        episodes: results-file episodes (``{"task", "seed", "metrics"}``).
        reference: (task, seed) → the uniform entry's RMSE.

    Returns:
        (the episodes, filled where possible; how many were filled).
    """
    out, filled = [], 0
    for ep in episodes:
        metrics = ep["metrics"]
        if metrics.get("uniform_rmse") is None and metrics.get("rmse") is not None:
            rmse = reference.get((ep["task"], int(ep["seed"])))
            if rmse is not None:
                metrics = {**metrics, "uniform_rmse": rmse}
                filled += 1
        out.append({**ep, "metrics": metrics})
    return out, filled


def _order_key(standing: Standing) -> tuple[Any, ...]:
    s, e = standing.score, standing.entry
    return (s is None, -(s.S if s else 0.0), -(s.iqm if s else 0.0), e.created_utc, e.id or 0)


def suite_board(name: str, version: str, entries: Sequence[LeaderboardEntry],
                tasks: Collection[str] | None = None) -> SuiteBoard:
    """Score and rank the entries of one suite (see the module docstring).

    Args:
        name, version: the suite.
        entries: its stored entries.
        tasks: only these of its tasks (a track's board: :func:`track_boards`); default every task.
    """
    episodes = {id(e): [ep for ep in episodes_of(e) if tasks is None or ep["task"] in tasks] for e in entries}
    tasks = tuple(dict.fromkeys(ep["task"] for e in entries for ep in episodes[id(e)]))
    reference = reference_entry(entries)
    uniform: dict[tuple[str, int], float | None] = {}
    if reference is not None:
        uniform = rmse_by_episode(episodes[id(reference)])
    alone = reference_entry(entries, NON_COOPERATIVE_ENTRY_POINT)
    non_cooperative = None if alone is None else rmse_by_episode(episodes[id(alone)])
    runs, filled_episodes = [], {}
    for entry in entries:
        filled_episodes[id(entry)], filled = fill_uniform_rmse(episodes[id(entry)], uniform)
        score = suite_score(filled_episodes[id(entry)], tasks, suite=name, non_cooperative=non_cooperative)
        runs.append(Run(entry, score, filled))
    standings = [_standing(group, filled_episodes, tasks, name, non_cooperative)
                 for group in group_runs(without_repeats(runs, episodes))]
    standings.sort(key=_order_key)
    public = [s for s in standings if not s.entry.privileged]
    full = [s for s in public if s.full]
    separable = separable_ranks_over_runs([[r.score for r in s.runs] or [s.score] for s in full])
    ranked = [replace(s, rank=i, separable_rank=r) for i, (s, r) in enumerate(zip(full, separable), 1)]
    partial = [replace(s, rank=i) for i, s in enumerate((s for s in public if not s.full), 1)]
    return SuiteBoard(name, version, tasks, tuple(ranked), tuple(partial),
                      tuple(s for s in standings if s.entry.privileged), reference)


def _standing(group: Sequence[Run], episodes: Mapping[int, list[dict[str, Any]]], tasks: Sequence[str], suite: str,
              non_cooperative: Mapping[tuple[str, int], float | None] | None) -> Standing:
    """One entry's standing, or that of a method's runs: scored by the IQM over runs with its CI over runs, the rest
    (tasks, gap closed, cooperation gain) of the run-mean episodes (:mod:`swarmloc.bench.scoring.runs`)."""
    if len(group) == 1:
        (run,) = group
        return Standing(run.entry, run.score, None, run.filled)
    scores = [r.score for r in group if r.score is not None]  # grouped runs all have one
    total = over_runs(scores)
    mean = suite_score(run_mean_episodes([episodes[id(r.entry)] for r in group]), tasks, suite=suite,
                       non_cooperative=non_cooperative)
    assert mean is not None  # the runs cover the same tasks, so their mean does
    score = replace(mean, S=total.S, ci_low=total.ci_low, ci_high=total.ci_high)
    return Standing(representative(group, total.S).entry, score, None, sum(r.filled for r in group),
                    runs=tuple(group), over_runs=total)


#: the current benchmark's suite: its board comes first, the shipped results and the demo default to it


def by_suite(entries: Iterable[LeaderboardEntry]) -> dict[SuiteKey, list[LeaderboardEntry]]:
    """Group entries by (suite name, suite version): ``DEFAULT_SUITE`` first, then by name and version."""
    groups: dict[SuiteKey, list[LeaderboardEntry]] = {}
    for entry in entries:
        groups.setdefault((entry.suite_name, entry.suite_version), []).append(entry)
    return dict(sorted(groups.items(), key=lambda item: (item[0][0] != DEFAULT_SUITE, item[0])))


def suite_boards(entries: Iterable[LeaderboardEntry]) -> list[SuiteBoard]:
    """One board per suite, in ``by_suite`` order."""
    return [suite_board(name, version, group) for (name, version), group in by_suite(entries).items()]


def track_boards(board: SuiteBoard, entries: Sequence[LeaderboardEntry],
                 track_of: TrackOf = registered_track) -> dict[str, SuiteBoard]:
    """A benchmark v2 suite's board per track: each track's tasks scored and ranked as a suite of their own.

    Scores never mix tracks (:mod:`swarmloc.bench.scoring.tracks`): on a track's board the
    score, its CI, the separable ranks and every plot see that track's tasks only.

    Args:
        board: the suite's board (its name picks the score).
        entries: the suite's stored entries (those ``board`` was built from).
        track_of: task → track (default: the registered spec's).

    Returns:
        track → its board, tracks in ``TRACKS`` order; empty for a suite scored by score v1
        or one whose tasks name no track.
    """
    if score_version(board.name) < 2:
        return {}
    groups = tasks_by_track(board.tasks, track_of)
    return {track: suite_board(board.name, board.version, entries, tasks=tuple(groups[track]))
            for track in TRACKS if track in groups}


def split_ranked(entries: Iterable[LeaderboardEntry]) -> tuple[list[LeaderboardEntry], list[LeaderboardEntry]]:
    """(non-privileged entries — ranked, then partial coverage —, privileged entries), one suite."""
    board = suite_board("", "", list(entries))
    return [s.entry for s in board.ranked + board.partial], [s.entry for s in board.privileged]


def best_ranked_on(board: SuiteBoard, tasks: Iterable[str]) -> tuple[Standing, float] | None:
    """The ranked standing with the highest mean ``G_t`` over ``tasks``, and that mean (None if none is ranked).

    How a partial-coverage method compares with the full-coverage ones on its own tasks.
    """
    tasks = list(tasks)
    scored = [(s, float(np.mean([s.score.tasks[t].mean for t in tasks]))) for s in board.ranked if s.score and tasks]
    return max(scored, key=lambda pair: pair[1]) if scored else None


# -- columns ---------------------------------------------------------------------------


def family_columns(tasks: Sequence[str]) -> list[Column]:
    """One column per task family (``swarmloc.bench.scoring.families``)."""
    return [Column(family, f"{family}: {', '.join(task_label(t) for t in members)}", tuple(members))
            for family, members in group_by_family(tasks).items()]


def task_columns(tasks: Sequence[str], family: str | None = None, only: str | Sequence[str] | None = None) -> list[Column]:
    """The per-task columns of one family, or of the listed tasks.

    Args:
        tasks: the suite's tasks.
        family: a family name (case-insensitive), e.g. ``Scale``.
        only: task IDs, comma-separated or a list (the ``swarmloc/`` prefix and the
            version may be omitted: ``Scale32`` matches ``swarmloc/Scale32-v0``).

    Raises:
        ValueError: an unknown family or task, naming the suite's.
    """
    chosen: list[str] = []
    if family is not None:
        groups = {f.casefold(): members for f, members in group_by_family(tasks).items()}
        if family.casefold() not in groups:
            raise ValueError(f"unknown task family {family!r}; this suite's families: "
                             f"{', '.join(group_by_family(tasks))}")
        chosen += groups[family.casefold()]
    if only is not None:
        names = [n.strip() for n in only.split(",")] if isinstance(only, str) else list(only)
        for name in filter(None, names):
            match = [t for t in tasks if name in (t, short_task(t), task_label(t))]
            if not match:
                raise ValueError(f"task {name!r} is not in this suite; its tasks: "
                                 f"{', '.join(task_label(t) for t in tasks)}")
            chosen += match
    return [Column(task_label(t), t, (t,)) for t in dict.fromkeys(chosen)]


@dataclass(frozen=True)
class ColumnScore:
    """A standing on one column: ``2^G`` over its covered tasks, and the worst of them."""

    times: float
    worst_task: str
    worst_times: float
    covered: int
    total: int


def column_score(score: SuiteScore | None, column: Column) -> ColumnScore | None:
    """``2^(mean G_t)`` over the column's tasks the standing covers (None if it covers none)."""
    if score is None:
        return None
    covered = [score.tasks[t] for t in column.tasks if t in score.tasks]
    if not covered:
        return None
    worst = min(covered, key=lambda t: t.mean)
    return ColumnScore(2.0 ** float(np.mean([t.mean for t in covered])), worst.task, 2.0**worst.mean,
                       len(covered), len(column.tasks))


# -- formatting ------------------------------------------------------------------------

#: the mark of a method whose weights were fitted to privileged labels while training
PRIVILEGED_TRAINING_MARK = "‡"
#: what the mark means, for legends
PRIVILEGED_TRAINING_NOTE = (f"{PRIVILEGED_TRAINING_MARK} fitted to privileged labels while training: its weights "
                            "learned from fault or error labels, which it does not read when it runs (ranked).")


def privileged_training(standing: Standing) -> bool:
    """True when the standing's weights were fitted to privileged labels (every run declares it)."""
    return all(e.privileged_training for e in standing.entries)


def method_label(standing: Standing) -> str:
    """The method's name as the tables show it: ``‡`` when fitted to privileged labels, ``(3 runs)`` for
    several runs."""
    mark = f" {PRIVILEGED_TRAINING_MARK}" if privileged_training(standing) else ""
    runs = f" ({standing.n_runs} runs)" if standing.n_runs > 1 else ""
    return f"{standing.entry.name}{mark}{runs}"


def runs_note(board: SuiteBoard) -> str:
    """The legend's note on standings of several training runs ('' when the board has none)."""
    if not any(s.n_runs > 1 for s in board.standings):
        return ""
    return ("(n runs): the method's n training runs, one standing: 2^S of the interquartile mean over runs of each "
            "run's S (rliable; the mean for up to 3 runs), 95% CI over runs, families and seeds; the other columns "
            "are the run-mean's.")



def fmt(value: float | None, digits: int = 3) -> str:
    """Fixed-point text, or an em dash for a missing value."""
    return "—" if value is None else f"{value:.{digits}f}"


def fmt_times(value: float | None) -> str:
    """A ratio to uniform in at most five characters (three significant digits)."""
    if value is None:
        return "—"
    if value >= 99.95:
        return f"{value:.0f}"
    if value >= 9.995:
        return f"{value:.1f}"
    return f"{value:.2f}" if value >= 0.01 else f"{value:.3f}"


def fmt_score(score: SuiteScore | None) -> str:
    """``2^S [low–high]``, e.g. ``2.78 [2.64–2.93]``."""
    if score is None:
        return "—"
    low, high = score.times_ci
    return f"{fmt_times(score.times)} [{fmt_times(low)}–{fmt_times(high)}]"


def fmt_pct(value: float | None) -> str:
    """A fraction as a whole percentage (``—`` when missing)."""
    return "—" if value is None else f"{100.0 * value:.0f}%"


def status(entry: LeaderboardEntry) -> str:
    """Verification status in words."""
    if entry.verified:
        return f"verified ({entry.verified_episodes} ep.)"
    return "shipped (trusted)" if entry.trusted else "unverified"


def task_rmse(entry: LeaderboardEntry, task: str) -> float | None:
    """Mean RMSE of an entry on a task (None when absent)."""
    agg = entry.task_aggregates.get(task, {}).get("rmse")
    return None if agg is None else agg.mean


__all__ = [
    "PRIVILEGED_TRAINING_MARK",
    "PRIVILEGED_TRAINING_NOTE",
    "UNIFORM_ENTRY_POINT",
    "Column",
    "ColumnScore",
    "Standing",
    "SuiteBoard",
    "SuiteKey",
    "best_ranked_on",
    "by_suite",
    "column_score",
    "episodes_of",
    "family_columns",
    "fill_uniform_rmse",
    "fmt",
    "fmt_pct",
    "fmt_score",
    "fmt_times",
    "method_label",
    "privileged_training",
    "reference_entry",
    "registered_track",
    "runs_note",
    "short_task",
    "split_ranked",
    "status",
    "suite_board",
    "suite_boards",
    "task_columns",
    "task_rmse",
    "track_boards",
]
