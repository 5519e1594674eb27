"""``swarmloc leaderboard html``: the static leaderboard site."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rich.console import Console


@dataclass
class Options:
    """Write the static HTML leaderboard site."""

    out: Path
    """Output directory (created if missing)."""
    db_url: str | None = None
    """Store URL (default: $SWARMLOC_DB, else a SQLite file in the user data directory)."""
    suite: str | None = None
    """Only this suite (all suites when omitted)."""


def run(opts: Options, console: Console | None = None) -> int:
    """Render the site; 1 when the store cannot be opened."""
    from rich.console import Console
    from rich.text import Text

    from swarmloc.leaderboard.site.views import open_store_or_refuse, render_html

    with open_store_or_refuse(opts.db_url, console) as store:
        if store is None:
            return 1
        index = render_html(store, opts.out, opts.suite)
    (console or Console()).print(Text(f"wrote {index}"))
    return 0
