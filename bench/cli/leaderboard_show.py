"""``swarmloc leaderboard show``: the leaderboard in the terminal."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rich.console import Console


@dataclass
class Options:
    """Print the leaderboard in the terminal."""

    db_url: str | None = None
    """Store URL (default: $SWARMLOC_DB, else a SQLite file in the user data directory)."""
    suite: str | None = None
    """Only this suite (all suites when omitted)."""


def run(opts: Options, console: Console | None = None) -> int:
    """Print the tables; 1 when the store cannot be opened."""
    from swarmloc.leaderboard.views import open_store_or_refuse, print_leaderboard

    with open_store_or_refuse(opts.db_url, console) as store:
        if store is None:
            return 1
        print_leaderboard(store, opts.suite, console)
    return 0
