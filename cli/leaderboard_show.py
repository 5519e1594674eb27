"""``swarmloc leaderboard show``: the leaderboard in the terminal."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

from swarmloc.cli.leaderboard_store import StoreOptions, store_shipped

if TYPE_CHECKING:
    from rich.console import Console


@dataclass
class Options(StoreOptions):
    """Print the leaderboard in the terminal (ranked by the score, 2^S; fits 100 columns), or its compute view."""

    family: str | None = None
    """Show one column per task of this family (e.g. Scale, NLOS, Cascaded) instead of one per family."""
    tasks: str | None = None
    """Show one column per listed task, comma-separated IDs (`swarmloc/` and `-v0` may be omitted; at most 6)."""
    view: Literal["accuracy", "compute"] = "accuracy"
    """`accuracy`: the ranking by 2^S; `compute`: in the same order, each method's delay per update against the
    50 ms budget and its FLOPs per channel."""
    shipped: bool = False
    """First store the shipped reference results that the store lacks (those of --suite when given), as
    `swarmloc demo` does: the board of the shipped methods without evaluating anything."""


def run(opts: Options, console: Console | None = None) -> int:
    """Print the tables; 1 when the store cannot be opened, 2 for an unknown family, task or shipped suite."""
    from rich.console import Console
    from rich.text import Text

    from swarmloc.leaderboard.site.views import open_store_or_refuse, print_leaderboard

    with open_store_or_refuse(opts.db_url, console) as store:
        if store is None:
            return 1
        if opts.shipped and not store_shipped(store, opts.suite, console or Console()):
            return 2
        try:
            print_leaderboard(store, opts.suite, console, family=opts.family, tasks=opts.tasks, view=opts.view)
        except ValueError as err:
            (console or Console()).print(Text(f"error: {err}", style="bold red"))
            return 2
    return 0
