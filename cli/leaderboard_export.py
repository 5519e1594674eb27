"""``swarmloc leaderboard export``: the leaderboard as CSV, JSON or marl-eval's raw-data JSON."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from swarmloc.cli.leaderboard_store import StoreOptions, print_wrote, store_shipped

if TYPE_CHECKING:
    from rich.console import Console


@dataclass
class Options(StoreOptions):
    """Export the leaderboard as CSV, JSON or marl-eval's raw-data JSON."""

    format: Literal["csv", "json", "marl-eval"] = "csv"
    """Output format: `csv` or `json` (one row per method and board: score, runs with the IQM over runs and its CI,
    privileged_training, delay and FLOPs), or `marl-eval` (InstaDeep marl-eval's {env: {task: {algorithm: {run:
    ...}}}} with the per-episode gain and RMSE; see docs/leaderboard.md)."""
    out: Path | None = None
    """Output file (standard output when omitted)."""
    shipped: bool = True
    """First store the shipped reference results that the store lacks (those of --suite when given; none for a
    suite without shipped results), as `swarmloc leaderboard show --shipped` does, so that a fresh store exports
    the reference board; `--no-shipped`: the store as it is."""


def run(opts: Options, console: Console | None = None) -> int:
    """Write the export (atomically when to a file); 1 when the store cannot be opened. Messages go to standard
    error (standard output may be the export)."""
    from rich.console import Console

    from swarmloc.bench.common.files import write_text_atomic
    from swarmloc.bench.evaluation.shipped import RESULTS_DIRS
    from swarmloc.leaderboard.site.views import export, open_store_or_refuse

    with open_store_or_refuse(opts.db_url, console) as store:
        if store is None:
            return 1
        if opts.shipped and (opts.suite is None or opts.suite in RESULTS_DIRS):
            store_shipped(store, opts.suite, console or Console(stderr=True))
        text = export(store, opts.format, opts.suite)
    if opts.out is None:
        sys.stdout.write(text)
    else:
        write_text_atomic(opts.out, text)
        print_wrote(opts.out, console)
    return 0
