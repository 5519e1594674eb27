"""Which stored entries of a board are the training runs of one method, and which repeat another.

A learned method ships one results file per training run (``<method>.seed<k>.json``, each
declaring its ``run``: the run seed of its weights), and anyone may submit several runs of their
own. On a board the runs of one method are one standing (:mod:`swarmloc.leaderboard.site.ranking`
scores it by the IQM over runs, :mod:`swarmloc.bench.scoring.runs`):

* **the runs of one method** are the entries that declare a run and share the method's name, entry
  point, track, privileged flag and the tasks they cover (a run that covers other tasks is not
  comparable and stands alone);
* **a repeat** of a kept entry of the same method — the same weights (SHA-256), or the same
  episodes to the last digit (the chosen run shipped again as ``<method>.json``, say) — is left out,
  so one run never counts twice. Entries that declare a run are kept before those that do not,
  then the older first;
* every other entry is a standing of its own, as before.
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from swarmloc.bench.scoring.score import SuiteScore
from swarmloc.leaderboard.store.records import LeaderboardEntry


@dataclass(frozen=True)
class Run:
    """One stored entry scored on its board.

    Attributes:
        entry: the stored submission.
        score: its score on the board's tasks (None without a gain on any of them).
        filled: its episodes whose ``uniform_rmse`` came from the board's ``uniform`` entry.
    """

    entry: LeaderboardEntry
    score: SuiteScore | None
    filled: int


def _method_key(run: Run) -> tuple[Any, ...]:
    e = run.entry
    return e.name, e.entry_point, e.track, e.privileged


def _episodes_text(episodes: Sequence[Mapping[str, Any]]) -> str:
    """The episodes as canonical text (sorted by task and seed): equal text, equal results."""
    ordered = sorted(episodes, key=lambda ep: (str(ep["task"]), int(ep["seed"])))
    return json.dumps(ordered, sort_keys=True, separators=(",", ":"))


def without_repeats(runs: Sequence[Run], episodes: Mapping[int, Sequence[Mapping[str, Any]]]) -> list[Run]:
    """The runs, less the entries that repeat a kept entry of the same method (same weights or same episodes).

    Args:
        runs: a board's scored entries, in board order.
        episodes: ``id(entry)`` → the entry's episodes on the board's tasks.

    Returns:
        The kept runs, in the order given.
    """
    preferred = sorted(range(len(runs)), key=lambda i: (runs[i].entry.run is None, runs[i].entry.created_utc,
                                                        runs[i].entry.id or 0))
    shared = Counter(_method_key(run) for run in runs)  # only entries of a method stored more than once can repeat
    seen_weights: set[tuple[Any, ...]] = set()
    seen_episodes: set[tuple[Any, ...]] = set()
    kept = set()
    for i in preferred:
        key, entry = _method_key(runs[i]), runs[i].entry
        if shared[key] == 1:
            kept.add(i)
            continue
        weights = None if entry.weights_sha256 is None else (*key, entry.weights_sha256)
        text = (*key, _episodes_text(episodes[id(entry)]))
        if (weights is not None and weights in seen_weights) or text in seen_episodes:
            continue
        kept.add(i)
        seen_episodes.add(text)
        if weights is not None:
            seen_weights.add(weights)
    return [run for i, run in enumerate(runs) if i in kept]


def group_runs(runs: Sequence[Run]) -> list[tuple[Run, ...]]:
    """The runs of each method together (see the module docstring); every other entry alone.

    Args:
        runs: a board's scored entries, repeats left out (:func:`without_repeats`).

    Returns:
        The groups, each in run-seed order (then the order given), groups in the order of their
        first member.
    """
    groups: dict[tuple[Any, ...], list[Run]] = {}
    for i, run in enumerate(runs):
        if run.entry.run is None or run.score is None:
            groups[("alone", i)] = [run]
        else:
            covered = tuple(sorted(run.score.tasks))
            groups.setdefault((*_method_key(run), covered), []).append(run)
    return [tuple(sorted(group, key=lambda r: r.entry.run if r.entry.run is not None else -1)) for group in
            groups.values()]


def representative(group: Sequence[Run], S: float) -> Run:
    """The run whose suite score is nearest ``S`` (the group's IQM over runs), the lower run seed on a tie:
    the entry a grouped standing shows for its metadata, page and results file."""
    return min(group, key=lambda r: (abs((r.score.S if r.score else 0.0) - S), r.entry.run or 0))


__all__ = ["Run", "group_runs", "representative", "without_repeats"]
