"""``swarmloc leaderboard show``: the leaderboard in the terminal."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rich.console import Console


@dataclass
class Options:
    """Print the leaderboard in the terminal (ranked by score v1; fits 100 columns)."""

    db_url: str | None = None
    """Store URL (default: $SWARMLOC_DB, else a SQLite file in the user data directory)."""
    suite: str | None = None
    """Only this suite (all suites when omitted)."""
    family: str | None = None
    """Show one column per task of this family (e.g. Scale, NLOS, Cascaded) instead of one per family."""
    tasks: str | None = None
    """Show one column per listed task, comma-separated IDs (`swarmloc/` and `-v0` may be omitted; at most 6)."""


def run(opts: Options, console: Console | None = None) -> int:
    """Print the tables; 1 when the store cannot be opened, 2 for an unknown family or task."""
    from rich.console import Console
    from rich.text import Text

    from swarmloc.leaderboard.views import open_store_or_refuse, print_leaderboard

    with open_store_or_refuse(opts.db_url, console) as store:
        if store is None:
            return 1
        try:
            print_leaderboard(store, opts.suite, console, family=opts.family, tasks=opts.tasks)
        except ValueError as err:
            (console or Console()).print(Text(f"error: {err}", style="bold red"))
            return 2
    return 0
