"""What the ``swarmloc leaderboard`` commands share: the store and suite options, and the "wrote" line.

Not a command itself: ``leaderboard_show``, ``leaderboard_html`` and ``leaderboard_export``
derive their ``Options`` from ``StoreOptions``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from pathlib import Path

    from rich.console import Console

    from swarmloc.leaderboard.store.database import LeaderboardStore


@dataclass(kw_only=True)
class StoreOptions:
    """The options of every leaderboard command: which store to read, which suite to show."""

    db_url: str | None = None
    """Store URL (default: $SWARMLOC_DB, else a SQLite file in the user data directory)."""
    suite: str | None = None
    """Only this suite (all suites when omitted)."""


def print_wrote(path: Path, console: Console | None = None) -> None:
    """Say ``wrote <path>`` on ``console`` (a new one when None)."""
    from rich.console import Console
    from rich.text import Text

    (console or Console()).print(Text(f"wrote {path}"))


def store_shipped(store: LeaderboardStore, suite: str | None, console: Console) -> bool:
    """Store the shipped results that ``store`` lacks (of ``suite``, else of every suite); False for an unknown suite."""
    from rich.text import Text

    from swarmloc.bench.evaluation.shipped import RESULTS_DIRS
    from swarmloc.leaderboard.store.shipped import load_shipped

    if suite is not None and suite not in RESULTS_DIRS:
        console.print(Text(f"error: no shipped results of suite {suite!r}; shipped: {', '.join(RESULTS_DIRS)}",
                           style="bold red"))
        return False
    loaded = load_shipped(store, RESULTS_DIRS[suite] if suite is not None else None)
    for name, why in loaded.refused:
        console.print(Text(f"not stored {name}: {why}", style="yellow"))
    return True
