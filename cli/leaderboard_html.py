"""``swarmloc leaderboard html``: the static leaderboard site."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from swarmloc.cli.leaderboard_store import StoreOptions, print_wrote

if TYPE_CHECKING:
    from rich.console import Console


@dataclass
class Options(StoreOptions):
    """Write the static HTML leaderboard site."""

    out: Path
    """Output directory (created if missing)."""


def run(opts: Options, console: Console | None = None) -> int:
    """Render the site; 1 when the store cannot be opened."""
    from swarmloc.leaderboard.site.views import open_store_or_refuse, render_html

    with open_store_or_refuse(opts.db_url, console) as store:
        if store is None:
            return 1
        index = render_html(store, opts.out, opts.suite)
    print_wrote(index, console)
    return 0
