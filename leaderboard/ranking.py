"""Ranking and formatting shared by the leaderboard views.

Per suite (name and version), non-privileged methods are ranked by mean normalized score,
then IQM, then submission time; privileged methods are listed apart, ordered the same way.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from swarmloc.leaderboard.store import LeaderboardEntry

SuiteKey = tuple[str, str]


def _rank_key(entry: LeaderboardEntry) -> tuple[Any, ...]:
    score = entry.score
    return (
        score is None,
        -(score.mean if score else 0.0),
        -(score.iqm if score else 0.0),
        entry.created_utc,
        entry.id or 0,
    )


def by_suite(entries: Iterable[LeaderboardEntry]) -> dict[SuiteKey, list[LeaderboardEntry]]:
    """Group entries by (suite name, suite version), suites sorted by name then version."""
    groups: dict[SuiteKey, list[LeaderboardEntry]] = {}
    for entry in entries:
        groups.setdefault((entry.suite_name, entry.suite_version), []).append(entry)
    return dict(sorted(groups.items()))


def split_ranked(
    entries: Iterable[LeaderboardEntry],
) -> tuple[list[LeaderboardEntry], list[LeaderboardEntry]]:
    """(ranked non-privileged entries, privileged entries), each best first."""
    ordered = sorted(entries, key=_rank_key)
    return [e for e in ordered if not e.privileged], [e for e in ordered if e.privileged]


def suite_tasks(entries: Iterable[LeaderboardEntry]) -> list[str]:
    """All task IDs appearing in the entries, sorted."""
    return sorted({task for entry in entries for task in entry.task_aggregates})


def task_rmse(entry: LeaderboardEntry, task: str) -> float | None:
    """Mean RMSE of an entry on a task (None when absent)."""
    agg = entry.task_aggregates.get(task, {}).get("rmse")
    return None if agg is None else agg.mean


def short_task(task: str) -> str:
    """Task ID without the ``swarmloc/`` namespace, for column headers."""
    return task.removeprefix("swarmloc/")


def fmt(value: float | None, digits: int = 3) -> str:
    """Fixed-point text, or an em dash for a missing value."""
    return "—" if value is None else f"{value:.{digits}f}"


def fmt_ci(entry: LeaderboardEntry) -> str:
    """The score's 95 % CI as ``[low, high]``."""
    s = entry.score
    return "—" if s is None else f"[{s.ci_low:.3f}, {s.ci_high:.3f}]"


def status(entry: LeaderboardEntry) -> str:
    """Verification status in words."""
    if entry.verified:
        return f"verified ({entry.verified_episodes} ep.)"
    return "shipped (trusted)" if entry.trusted else "unverified"


__all__ = [
    "SuiteKey",
    "by_suite",
    "fmt",
    "fmt_ci",
    "short_task",
    "split_ranked",
    "status",
    "suite_tasks",
    "task_rmse",
]
