"""Views of the store: a terminal table, the static HTML site, CSV/JSON exports.

Methods are ranked per suite by their mean normalized score (higher is better), shown
with its IQM and 95 % CI, the per-task RMSE, and the mean delay, energy and jitter.
Privileged methods (those that read ground truth) appear in a separate section and are
not ranked with the rest (see :mod:`swarmloc.leaderboard.ranking`).

Every submitted string is treated as data: escaped with ``html.escape`` in HTML
(:mod:`swarmloc.leaderboard.html_site`), shown as literal ``rich.text.Text`` in the
terminal, and guarded against spreadsheet formula injection in CSV.
"""

from __future__ import annotations

import csv
import io
import json
import sys
import contextlib
from collections.abc import Iterator, Sequence
from typing import Any, Literal

from rich.console import Console
from rich.table import Table
from rich.text import Text

from swarmloc.leaderboard.errors import StoreError
from swarmloc.leaderboard.html_site import render_html
from swarmloc.leaderboard.ranking import (
    by_suite,
    fmt,
    fmt_ci,
    short_task,
    split_ranked,
    status,
    suite_tasks,
    task_rmse,
)
from swarmloc.leaderboard.store import LeaderboardEntry, LeaderboardStore

ExportFormat = Literal["csv", "json"]


# -- terminal ------------------------------------------------------------------------


@contextlib.contextmanager
def open_store_or_refuse(db_url: str | None, console: Console | None = None) -> Iterator[LeaderboardStore | None]:
    """The store at ``db_url`` (closed on exit), or None after printing why it cannot be opened.

    Args:
        db_url: store URL (None: ``$SWARMLOC_DB`` or the default SQLite file).
        console: where the refusal is printed (default: standard output).
    """
    try:
        store = LeaderboardStore(db_url)
    except StoreError as err:
        (console or Console()).print(Text(f"cannot open the leaderboard: {err}", style="bold red"))
        yield None
        return
    with store:
        yield store


def _rich_table(title: str, entries: Sequence[LeaderboardEntry], tasks: Sequence[str],
                ranked: bool) -> Table:
    table = Table(title=title, title_justify="left", header_style="bold")
    number: dict[str, Any] = {"justify": "right"}
    headers: list[tuple[str, dict[str, Any]]] = [("#", number)] if ranked else []
    headers += [("Method", {"min_width": 12}), ("Track", {"justify": "center"}),
                ("Score", number), ("IQM", number), ("95% CI", number)]
    headers += [(f"RMSE {short_task(task)} [m]", number) for task in tasks]
    headers += [("Delay [ms]", number), ("Energy [J]", number), ("Jitter", number),
                ("Status", {})]
    for header, options in headers:
        # Text, not str: rich would read "[ms]" as markup.
        table.add_column(Text(header), **options)
    for rank, entry in enumerate(entries, start=1):
        cells: list[Text] = [Text(str(rank))] if ranked else []
        cells += [
            Text(entry.name),
            Text(entry.track),
            Text(fmt(entry.score.mean if entry.score else None)),
            Text(fmt(entry.score.iqm if entry.score else None)),
            Text(fmt_ci(entry)),
            *(Text(fmt(task_rmse(entry, task))) for task in tasks),
            Text(fmt(entry.delay_ms, 2)),
            Text(fmt(entry.energy_j, 3)),
            Text(fmt(entry.jitter, 4)),
            Text(status(entry)),
        ]
        table.add_row(*cells)
    return table


def leaderboard_tables(store: LeaderboardStore, suite: str | None = None) -> list[Table]:
    """Rich tables: per suite, the ranked methods, then the privileged ones (if any).

    Args:
        store: The store to read.
        suite: Only this suite name (all suites when None).

    Returns:
        The tables, in display order (empty when the store has no entries).
    """
    tables = []
    for (name, version), entries in by_suite(store.entries(suite)).items():
        tasks = suite_tasks(entries)
        ranked, privileged = split_ranked(entries)
        title = f"swarmloc leaderboard — suite {name} v{version} (ranked by mean normalized score)"
        tables.append(_rich_table(title, ranked, tasks, ranked=True))
        if privileged:
            tables.append(_rich_table(
                f"Privileged methods on {name} v{version} (use ground truth; not ranked)",
                privileged, tasks, ranked=False,
            ))
    return tables


def print_leaderboard(
    store: LeaderboardStore, suite: str | None = None, console: Console | None = None
) -> None:
    """Print the terminal leaderboard (see :func:`leaderboard_tables`)."""
    # Piped output has no terminal to fit; keep the wide table readable there.
    out = console or (Console() if sys.stdout.isatty() else Console(width=240))
    tables = leaderboard_tables(store, suite)
    if not tables:
        out.print(Text(f"The leaderboard at {store.url} is empty."))
    for table in tables:
        out.print(table)


# -- export --------------------------------------------------------------------------


def _export_rows(entries: Sequence[LeaderboardEntry]) -> list[dict[str, Any]]:
    rows = []
    for (_name, _version), group in by_suite(entries).items():
        tasks = suite_tasks(group)
        ranked, privileged = split_ranked(group)
        for rank, entry in [(i, e) for i, e in enumerate(ranked, 1)] + [(None, e) for e in privileged]:
            score = entry.score
            row: dict[str, Any] = {
                "id": entry.id,
                "suite": entry.suite_name,
                "suite_version": entry.suite_version,
                "rank": rank,
                "name": entry.name,
                "authors": entry.authors,
                "url": entry.url,
                "track": entry.track,
                "privileged": entry.privileged,
                "deterministic": entry.deterministic,
                "verified": entry.verified,
                "trusted": entry.trusted,
                "score_mean": score.mean if score else None,
                "score_iqm": score.iqm if score else None,
                "score_ci_low": score.ci_low if score else None,
                "score_ci_high": score.ci_high if score else None,
                "delay_ms": entry.delay_ms,
                "energy_j": entry.energy_j,
                "jitter": entry.jitter,
            }
            for task in tasks:
                row[f"rmse[{task}]"] = task_rmse(entry, task)
            row.update(
                entry_point=entry.entry_point,
                method_hash=entry.method_hash,
                created_utc=entry.created_utc.isoformat(),
            )
            rows.append(row)
    return rows


def _csv_safe(value: Any) -> Any:
    """Neutralize spreadsheet formulas in text cells (OWASP CSV injection)."""
    if isinstance(value, str) and value[:1] in ("=", "+", "-", "@", "\t", "\r"):
        return "'" + value
    return value


def export(store: LeaderboardStore, format: ExportFormat = "csv", suite: str | None = None) -> str:
    """The leaderboard as CSV or JSON text.

    One row per submission: suite, rank (empty for privileged methods), metadata, the
    normalized score (mean, IQM, CI), mean delay/energy/jitter, per-task mean RMSE
    (``rmse[<task>]``), entry point, method hash, submission time. JSON rows also carry
    ``task_aggregates`` (every metric's mean, IQM and CI per task). Text cells in CSV
    that start with ``= + - @`` are prefixed with ``'`` so spreadsheets do not run them.

    Args:
        store: The store to read.
        format: ``"csv"`` or ``"json"``.
        suite: Only this suite name (all suites when None).

    Returns:
        The exported text.
    """
    entries = store.entries(suite)
    rows = _export_rows(entries)
    if format == "json":
        by_id = {e.id: e for e in entries}
        for row in rows:
            row["task_aggregates"] = {
                task: {m: agg.model_dump() for m, agg in per.items()}
                for task, per in sorted(by_id[row["id"]].task_aggregates.items())
            }
        return json.dumps(rows, indent=1, allow_nan=False) + "\n"
    if format != "csv":
        raise ValueError(f"unknown export format {format!r}; allowed: 'csv', 'json'")
    buffer = io.StringIO()
    fields: list[str] = []
    for row in rows:
        fields += [k for k in row if k not in fields]
    writer = csv.DictWriter(buffer, fieldnames=fields, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: _csv_safe(v) for k, v in row.items()})
    return buffer.getvalue()


__all__ = [
    "ExportFormat",
    "by_suite",
    "export",
    "leaderboard_tables",
    "print_leaderboard",
    "render_html",
    "split_ranked",
    "suite_tasks",
]
