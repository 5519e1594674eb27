"""Two results files of one suite, compared episode by episode: is B better than A, and where?

The question a researcher asks between two runs (a new method against a baseline, new
weights against the shipped ones, two training seeds) before submitting anything. Both
files ran the same (task, seed) episodes, so the comparison is paired: per episode the
difference of the gains over uniform (the score, ``docs/scoring.md``), which is
``log2(RMSE_A / RMSE_B)`` — uniform's RMSE cancels. Per task the mean difference with its
paired bootstrap CI; over the suite ``S_B − S_A`` with the CI the leaderboard ranks by
(:func:`swarmloc.bench.scoring.score.paired_difference`: score v1's stratified bootstrap, or score
v2's hierarchical one for a v2 suite), and rliable's probability of improvement ``P(B > A)``.
Under score v2 the difference in cooperation gain is the same number (non-cooperative's RMSE
cancels as uniform's does), so one verdict serves both.

Both files ran one suite, or part of it (``--tasks``: ``<suite>-subset``). Only episodes
both files hold are compared, and only tasks both methods cover (a null RMSE
on a seed leaves the task out, as on the leaderboard); what was left out is listed.

**Tracks.** A v2 suite's tasks fall into tracks, each its own board, and scores never mix tracks
(:mod:`swarmloc.bench.scoring.tracks`). The verdict is the leaderboard's rank criterion (the paired
CI of ``S_B − S_A``), so it is given per track, as the boards rank: :func:`compare_tracks` (what
``swarmloc compare`` prints) compares each track on its own tasks and families, and
:func:`compare` refuses files whose tasks span two tracks unless told which one (``track=``), so no
caller gets a number that mixes them. A v1 suite, or tasks of one track, compare as one.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from swarmloc.bench.evaluation.results import Results
from swarmloc.bench.scoring.bootstrap import DEFAULT_RESAMPLES, DEFAULT_SEED
from swarmloc.bench.scoring.profiles import probability_of_improvement
from swarmloc.bench.scoring.score import (
    PairedDifference,
    SuiteScore,
    paired_difference,
    score_version,
    suite_score,
)
from swarmloc.bench.scoring.tracks import TrackOf, named_tracks, registered_track


class NothingToCompare(ValueError):
    """The two files (or one track of them) share no task both methods cover."""


@dataclass(frozen=True)
class TaskComparison:
    """One task: both methods' mean RMSE and gain, and B − A.

    Attributes:
        task: task ID.
        rmse_a, rmse_b: task-mean RMSE [m] over the compared seeds.
        gain_a, gain_b: ``G_t`` of each (log2 units over uniform).
        difference: ``G_B − G_A`` with its paired CI; ``ahead`` counts seeds.
    """

    task: str
    rmse_a: float
    rmse_b: float
    gain_a: float
    gain_b: float
    difference: PairedDifference


@dataclass(frozen=True)
class Comparison:
    """B against A on the tasks and seeds both cover.

    Attributes:
        name_a, name_b: the two methods' names.
        suite: the suite name both files ran.
        score_a, score_b: the score of each on the compared episodes.
        difference: ``S_B − S_A`` with its paired CI; ``ahead`` counts tasks.
        p_improvement: ``P(B > A)`` (rliable; per task over all seed pairs, mean over tasks).
        tasks: per task, in the order of A's file.
        left_out: tasks not compared, each with the reason.
        track: the v2 track compared (its tasks only); None for a v1 suite or untracked tasks.
    """

    name_a: str
    name_b: str
    suite: str
    score_a: SuiteScore
    score_b: SuiteScore
    difference: PairedDifference
    p_improvement: float
    tasks: tuple[TaskComparison, ...]
    left_out: tuple[tuple[str, str], ...]
    track: str | None = None

    @property
    def b_ahead(self) -> bool:
        """B ahead beyond doubt: the paired CI of ``S_B − S_A`` is above 0 (the leaderboard's rule)."""
        return self.difference.ci_low > 0.0


def _base_suite(name: str) -> str:
    """The suite a run of part of it (``swarmloc evaluate --tasks``: ``<name>-subset``) belongs to."""
    return name.removesuffix("-subset")


def _episodes_by_task(results: Results, tasks: set[str] | None = None) -> dict[str, dict[int, dict]]:
    """task → seed → the episode as plain data (``{"task", "seed", "metrics"}``), of ``tasks`` only when given."""
    out: dict[str, dict[int, dict]] = {}
    for e in results.episodes:
        if tasks is None or e.task in tasks:
            out.setdefault(e.task, {})[e.seed] = e.model_dump()
    return out


def _not_covered(rows: dict[int, dict], seeds: Sequence[int]) -> str | None:
    """Why a method has no task score on these seeds (None when it has one)."""
    if any(rows[s]["metrics"]["rmse"] is None for s in seeds):
        return "null RMSE"
    if any(rows[s]["metrics"]["uniform_rmse"] is None for s in seeds):
        return "no uniform_rmse: a results file older than schema 2"
    return None


def _check_same_world(task: str, seeds: Sequence[int], rows_a: dict, rows_b: dict) -> None:
    """Both files' uniform RMSE agree on every seed: the same episode, so uniform cancels in B − A."""
    for s in seeds:
        ua, ub = (rows[s]["metrics"]["uniform_rmse"] for rows in (rows_a, rows_b))
        if not math.isclose(ua, ub, rel_tol=1e-9):
            raise ValueError(f"{task} seed {s}: uniform's RMSE is {ua!r} in A and {ub!r} in B, so the two files did "
                             "not run the same episode (a task or filter changed between them)")


def _tracks_of(a: Results, b: Results, track_of: TrackOf) -> dict[str, list[str]]:
    """The v2 tracks the two files' tasks fall into (none for a v1 suite: one board)."""
    if score_version(_base_suite(a.suite.name)) < 2:
        return {}
    return named_tracks(dict.fromkeys(e.task for results in (a, b) for e in results.episodes), track_of)


def compare(a: Results, b: Results, *, track: str | None = None, track_of: TrackOf = registered_track,
            n_resamples: int = DEFAULT_RESAMPLES, seed: int = DEFAULT_SEED) -> Comparison:
    """Compare results B against results A, paired on the episodes both hold (one track of a v2 suite).

    Args:
        a: the reference (baseline) results.
        b: the results compared with it.
        track: of a v2 suite whose tasks span several tracks, the one to compare (its tasks only);
            None: the files' only track, or every task of a v1 suite.
        track_of: task → track (default: the registered spec's; None for an unregistered task).
        n_resamples, seed: of the paired bootstrap.

    Returns:
        The comparison; ``left_out`` names every task of either file (of the track) that was not compared.

    Raises:
        ValueError: the files ran different suites or different episodes under one (task, seed)
            (their uniform RMSE differ); their tasks span tracks and ``track`` is None, or ``track``
            is not one of theirs.
        NothingToCompare: they share no task both methods cover (on the track).
    """
    if _base_suite(a.suite.name) != _base_suite(b.suite.name):
        raise ValueError(f"the results ran different suites ({a.suite.name!r} and {b.suite.name!r}); "
                         "only the same episodes compare")
    tracks = _tracks_of(a, b, track_of)
    if track is None and len(tracks) > 1:
        raise ValueError(f"the files' tasks span the tracks {', '.join(tracks)} of {_base_suite(a.suite.name)}, and "
                         "scores never mix tracks (one board each): compare one (track=...) or each with "
                         "compare_tracks, as swarmloc compare does")
    if track is not None and track not in tracks:
        raise ValueError(f"track {track!r} is not among the files' tracks; allowed: {list(tracks)}")
    members = None if track is None else set(tracks[track])
    if track is None and tracks and set(next(iter(tracks.values()))) >= {e.task for e in (*a.episodes, *b.episodes)}:
        track = next(iter(tracks))  # every task on one track: name the board (untracked tasks keep it None)
    rows_a, rows_b = _episodes_by_task(a, members), _episodes_by_task(b, members)
    left_out: list[tuple[str, str]] = []
    kept_a, kept_b, seeds_of = [], [], {}
    for task in list(rows_a) + [t for t in rows_b if t not in rows_a]:
        if task not in rows_a or task not in rows_b:
            left_out.append((task, f"only in {'A' if task in rows_a else 'B'}"))
            continue
        seeds = sorted(set(rows_a[task]) & set(rows_b[task]))
        if not seeds:
            left_out.append((task, "no seed in common"))
            continue
        why = [(label, _not_covered(rows[task], seeds)) for label, rows in (("A", rows_a), ("B", rows_b))]
        if any(w for _, w in why):
            left_out.append((task, "not covered by " + " and ".join(f"{label} ({w})" for label, w in why if w)))
            continue
        _check_same_world(task, seeds, rows_a[task], rows_b[task])
        seeds_of[task] = seeds
        kept_a += [rows_a[task][s] for s in seeds]
        kept_b += [rows_b[task][s] for s in seeds]
    names = list(seeds_of)
    if not names:
        on = "" if track is None else f" on the {track} track"
        raise NothingToCompare(f"{a.method.name!r} and {b.method.name!r} share no covered task{on}; "
                               f"left out: {left_out}")
    # the suite picks the score (score.score_version): a v2 suite's verdict resamples families, then seeds
    score_a, score_b = (suite_score(kept, names, suite=_base_suite(a.suite.name)) for kept in (kept_a, kept_b))
    assert score_a is not None and score_b is not None  # every kept task is covered by both
    suite_diff, task_diffs = paired_difference(score_a, score_b, n_resamples, seed)
    tasks = []
    for task, seeds in seeds_of.items():
        rmse_a, rmse_b = (float(np.mean([rows[task][s]["metrics"]["rmse"] for s in seeds]))
                          for rows in (rows_a, rows_b))
        tasks.append(TaskComparison(task, rmse_a, rmse_b, score_a.tasks[task].mean, score_b.tasks[task].mean,
                                    task_diffs[task]))
    # P(B > A) weighs tasks as the score does: families equally under score v2 (none under v1: tasks equally)
    p = probability_of_improvement({t: s.gains for t, s in score_b.tasks.items()},
                                   {t: s.gains for t, s in score_a.tasks.items()}, families=score_b.families)
    return Comparison(a.method.name, b.method.name, a.suite.name, score_a, score_b, suite_diff, p, tuple(tasks),
                      tuple(left_out), track)


@dataclass(frozen=True)
class TrackComparisons:
    """B against A on each board: per track of a v2 suite, or once for a v1 suite.

    Attributes:
        comparisons: track → its comparison, ``TRACKS`` order (the headline first); the one key
            None for a v1 suite (or tasks without a track).
        not_compared: tracks with no task both methods cover, and a v2 suite's tasks without a
            track, each with the reason.
    """

    comparisons: dict[str | None, Comparison]
    not_compared: tuple[tuple[str, str], ...] = ()


def compare_tracks(a: Results, b: Results, *, track_of: TrackOf = registered_track,
                   n_resamples: int = DEFAULT_RESAMPLES, seed: int = DEFAULT_SEED) -> TrackComparisons:
    """:func:`compare` on every track the files' tasks fall into: one verdict per board.

    Args:
        a, b, track_of, n_resamples, seed: as :func:`compare`.

    Raises:
        ValueError: as :func:`compare` (different suites or episodes).
        NothingToCompare: no track has a task both methods cover.
    """
    tracks = _tracks_of(a, b, track_of)
    if len(tracks) < 2:  # a v1 suite, or one track: one board
        comparison = compare(a, b, track_of=track_of, n_resamples=n_resamples, seed=seed)
        return TrackComparisons({comparison.track: comparison})
    out: dict[str | None, Comparison] = {}
    not_compared: list[tuple[str, str]] = []
    for track in tracks:
        try:
            out[track] = compare(a, b, track=track, track_of=track_of, n_resamples=n_resamples, seed=seed)
        except NothingToCompare as err:
            not_compared.append((track, str(err)))
    tracked = {t for members in tracks.values() for t in members}
    untracked = dict.fromkeys(e.task for results in (a, b) for e in results.episodes if e.task not in tracked)
    not_compared += [(task, "no track: on no board of the suite") for task in untracked]
    if not out:
        raise NothingToCompare(f"{a.method.name!r} and {b.method.name!r} share no covered task on any track: "
                               + "; ".join(why for _, why in not_compared))
    return TrackComparisons(out, tuple(not_compared))


def _difference_dict(d: PairedDifference) -> dict:
    return {"mean": d.mean, "ci": [d.ci_low, d.ci_high], "ahead": d.ahead, "count": d.count}


def comparison_dict(c: Comparison) -> dict:
    """The comparison as plain JSON data (gains in log2 units over uniform, RMSE in metres); ``track`` only
    for a v2 track's comparison."""
    return {
        "suite": c.suite, "a": c.name_a, "b": c.name_b, **({} if c.track is None else {"track": c.track}),
        "score": {name: {"S": s.S, "ci": [s.ci_low, s.ci_high], "times": s.times}
                  for name, s in (("a", c.score_a), ("b", c.score_b))},
        "difference": _difference_dict(c.difference), "b_ahead": c.b_ahead, "p_improvement": c.p_improvement,
        "tasks": [{"task": t.task, "rmse_a": t.rmse_a, "rmse_b": t.rmse_b, "gain_a": t.gain_a, "gain_b": t.gain_b,
                   "difference": _difference_dict(t.difference)} for t in c.tasks],
        "left_out": [{"task": task, "reason": why} for task, why in c.left_out],
    }


def track_comparisons_dict(c: TrackComparisons) -> dict:
    """As JSON: a v1 suite's one comparison as :func:`comparison_dict`; a v2 suite's as
    ``{"suite", "a", "b", "tracks": {track: comparison_dict}, "not_compared": [{"what", "reason"}]}``."""
    if list(c.comparisons) == [None]:
        return comparison_dict(c.comparisons[None])
    first = next(iter(c.comparisons.values()))
    return {"suite": first.suite, "a": first.name_a, "b": first.name_b,
            "tracks": {str(track): comparison_dict(comparison) for track, comparison in c.comparisons.items()},
            "not_compared": [{"what": what, "reason": why} for what, why in c.not_compared]}
