"""``swarmloc leaderboard export``: the leaderboard as CSV or JSON."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

if TYPE_CHECKING:
    from rich.console import Console


@dataclass
class Options:
    """Export the leaderboard as CSV or JSON."""

    format: Literal["csv", "json"] = "csv"
    """Output format."""
    out: Path | None = None
    """Output file (standard output when omitted)."""
    db_url: str | None = None
    """Store URL (default: $SWARMLOC_DB, else a SQLite file in the user data directory)."""
    suite: str | None = None
    """Only this suite (all suites when omitted)."""


def run(opts: Options, console: Console | None = None) -> int:
    """Write the export (atomically when to a file); 1 when the store cannot be opened."""
    from rich.console import Console
    from rich.text import Text

    from swarmloc.bench.common.files import write_text_atomic
    from swarmloc.leaderboard.site.views import export, open_store_or_refuse

    with open_store_or_refuse(opts.db_url, console) as store:
        if store is None:
            return 1
        text = export(store, opts.format, opts.suite)
    if opts.out is None:
        sys.stdout.write(text)
    else:
        write_text_atomic(opts.out, text)
        (console or Console()).print(Text(f"wrote {opts.out}"))
    return 0
