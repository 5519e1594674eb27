"""Tracks: benchmark v2's separate boards, and one score per track.

Benchmark v2 splits its tasks into two tracks, each with its own board (``docs/scoring.md``,
"Score v2"): **cooperative** (swarms whose peers carry information; the headline) and
**robust-ranging** (one UAV against faulty ranging). A task's track is its spec's ``track``
field; v0 and v1 tasks have none (``None``), and a v1 suite is one board as before. Scores
never mix tracks: :func:`track_scores` scores each track's tasks as a suite of their own
(:func:`~swarmloc.bench.scoring.score.suite_score`, so the suite's name still picks score v1 or
v2 and families weigh equally within a track).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence

from swarmloc.bench.scoring.bootstrap import DEFAULT_RESAMPLES, DEFAULT_SEED
from swarmloc.bench.scoring.score import SuiteScore, suite_score
from swarmloc.envs.tasks.catalogue import get_spec

#: the tracks of benchmark v2, in display order (the headline first)
TRACKS: tuple[str, ...] = ("cooperative", "robust-ranging")

TrackOf = Callable[[str], "str | None"]
"""task → its track (None for a v0/v1 task)."""


def _checked(task: str, track: str | None) -> str | None:
    if track is not None and track not in TRACKS:
        raise ValueError(f"task {task}: unknown track {track!r}; allowed: {list(TRACKS)} or None (v0/v1 tasks)")
    return track


def task_track(task: str) -> str | None:
    """The track of a registered task: ``"cooperative"``, ``"robust-ranging"``, or None (a v0/v1 task).

    Raises:
        KeyError: the task is not registered (``get_spec``'s error).
        ValueError: the spec names a track outside ``TRACKS``.
    """
    # getattr: specs from before the field (v0/v1 catalogues) carry no track at all, which means None
    return _checked(task, getattr(get_spec(task), "track", None))


def registered_track(task: str) -> str | None:
    """The track of a registered task; None for a v0/v1 task or one this install does not register.

    The tolerant :func:`task_track` for boards and comparisons, whose results files may name tasks
    of another install (they then count as untracked rather than failing).
    """
    try:
        return task_track(task)
    except KeyError:
        return None


def named_tracks(tasks: Iterable[str], track_of: TrackOf = registered_track) -> dict[str, list[str]]:
    """:func:`tasks_by_track` without the untracked (None) group: the boards a set of tasks falls into.

    Args:
        tasks: task IDs.
        track_of: task → track (default: the registered spec's, None when unregistered).

    Returns:
        track → its tasks, ``TRACKS`` order; empty when no task names a track (a v1 suite).
    """
    return {track: members for track, members in tasks_by_track(tasks, track_of).items() if track is not None}


def tasks_by_track(tasks: Iterable[str], track_of: TrackOf = task_track) -> dict[str | None, list[str]]:
    """Tasks grouped by track: ``TRACKS`` in order, then None (v0/v1 tasks); each group keeps the given order.

    Args:
        tasks: task IDs.
        track_of: task → track (default: the registered spec's; tests pass their own).

    Returns:
        track → its tasks, only the tracks that have a task.

    Raises:
        ValueError: a track outside ``TRACKS`` (and not None).
    """
    groups: dict[str | None, list[str]] = {}
    for task in tasks:
        groups.setdefault(_checked(task, track_of(task)), []).append(task)
    order = [*TRACKS, None]
    return {track: groups[track] for track in order if track in groups}


def _task_of(episode: Mapping | object) -> str:
    return str(episode["task"] if isinstance(episode, Mapping) else episode.task)  # type: ignore[attr-defined]


def track_scores(episodes: Iterable[Mapping], suite_tasks: Sequence[str], *, suite: str | None,
                 non_cooperative: Mapping[tuple[str, int], float | None] | None = None, track_of: TrackOf = task_track,
                 n_resamples: int = DEFAULT_RESAMPLES, seed: int = DEFAULT_SEED) -> dict[str | None, SuiteScore | None]:
    """One method's score on each track of a suite: one board per track.

    Args:
        episodes: the method's results-file episodes (or their dumps).
        suite_tasks: every task of the suite (for coverage and for the split).
        suite: the suite's name (picks score v1 or v2).
        non_cooperative: (task, seed) → ``non-cooperative``'s RMSE, for the cooperation gain.
        track_of: task → track (default: the registered spec's).
        n_resamples, seed: of the bootstrap.

    Returns:
        track → the score on that track's tasks (None where the method covers none of them),
        tracks as :func:`tasks_by_track` orders them.
    """
    episodes = list(episodes)
    out: dict[str | None, SuiteScore | None] = {}
    for track, tasks in tasks_by_track(suite_tasks, track_of).items():
        members = set(tasks)
        out[track] = suite_score([e for e in episodes if _task_of(e) in members], tasks, suite=suite,
                                 non_cooperative=non_cooperative, n_resamples=n_resamples, seed=seed)
    return out


__all__ = ["TRACKS", "named_tracks", "registered_track", "task_track", "tasks_by_track", "track_scores"]
