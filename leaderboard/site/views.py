"""Views of the store: a terminal table, the static HTML site, CSV/JSON exports.

Methods are ranked per suite by the score (``2^S``: how many times lower the error is than
the standard CEKF's, with its 95 % CI), beside the gap closed towards the information bound
and the task coverage ``k/T``; partial coverage is ranked in its own table and privileged
methods (those that read ground truth) are shown apart, not ranked (see
:mod:`swarmloc.leaderboard.site.ranking`). The terminal table fits 100 columns: one column per
task family, or per task of one family (``family=``) or of a list (``tasks=``).

Every submitted string is treated as data: escaped with ``html.escape`` in HTML
(:mod:`swarmloc.leaderboard.site.html`), shown as literal ``rich.text.Text`` in the
terminal, and guarded against spreadsheet formula injection in CSV.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import sys
from collections.abc import Iterator, Sequence
from typing import Any, Literal

from rich import box
from rich.console import Console
from rich.table import Table
from rich.text import Text

from swarmloc.bench.scoring.score import SuiteScore
from swarmloc.leaderboard.errors import StoreError
from swarmloc.leaderboard.site.html import render_html
from swarmloc.leaderboard.site.ranking import (
    Column,
    Standing,
    SuiteBoard,
    by_suite,
    column_score,
    family_columns,
    fmt_pct,
    fmt_times,
    split_ranked,
    suite_board,
    task_columns,
    task_rmse,
    track_boards,
)
from swarmloc.leaderboard.store.database import LeaderboardEntry, LeaderboardStore

ExportFormat = Literal["csv", "json"]

#: the terminal table is laid out for this many columns
TERMINAL_WIDTH = 100
LEGEND_STYLE = "dim"
#: method names wider than this fold onto a second line
METHOD_WIDTH = 20
#: column headers are broken into lines of at most this many characters where they can be
HEADER_WIDTH = 7
#: at most this many task columns (``tasks=``); more would not fit TERMINAL_WIDTH
MAX_TASK_COLUMNS = 6


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


def _words(label: str) -> list[str]:
    """``NLOSStep`` → NLOS, Step; ``HybridNoise10`` → Hybrid, Noise, 10 (CamelCase, acronyms, digits)."""
    words: list[str] = []
    for i, ch in enumerate(label):
        prev, nxt = label[i - 1] if i else "", label[i + 1 : i + 2]
        starts = bool(i) and ((ch.isupper() and (prev.islower() or prev.isdigit() or (prev.isupper() and nxt.islower())))
                              or ch.isdigit() != prev.isdigit())
        if starts or not words:
            words.append(ch)
        else:
            words[-1] += ch
    return words


def stacked_header(label: str, width: int = HEADER_WIDTH) -> str:
    """A column header in lines of at most ``width`` characters, broken at CamelCase and digits.

    >>> stacked_header("HybridNoise10"), stacked_header("CascadedFaultRandom"), stacked_header("Scale32")
    ('Hybrid\\nNoise10', 'Cascaded\\nFault\\nRandom', 'Scale32')

    A word longer than ``width`` keeps its own line whole.
    """
    lines: list[str] = []
    for word in _words(label):
        if lines and len(lines[-1]) + len(word) <= width:
            lines[-1] += word
        else:
            lines.append(word)
    return "\n".join(lines)


def _cooperation_text(score: SuiteScore | None) -> str:
    """``2^C`` with its CI, ``1.52 (1.40–1.66)``; a dash without a cooperation gain."""
    gain = None if score is None else score.cooperation
    if gain is None:
        return "—"
    return f"{fmt_times(2.0 ** gain.S)} ({fmt_times(2.0 ** gain.ci_low)}–{fmt_times(2.0 ** gain.ci_high)})"


def _rich_table(standings: Sequence[Standing], columns: Sequence[Column], n_tasks: int, ranked: bool,
                coverage: bool = True, cooperation: bool = False) -> Table:
    # SIMPLE_HEAD draws a space between columns; no padding beside it, so seven families fit TERMINAL_WIDTH.
    table = Table(header_style="bold", box=box.SIMPLE_HEAD, padding=0, show_edge=False)
    number: dict[str, Any] = {"justify": "right", "no_wrap": True}
    if ranked:
        table.add_column(Text("#"), **number)
    table.add_column(Text("Method"), overflow="fold", max_width=METHOD_WIDTH)
    table.add_column(Text("Trk"), justify="center", no_wrap=True)
    table.add_column(Text("2^S"), **number)
    table.add_column(Text("95% CI"), **number)
    if cooperation:  # a v2 cooperative track: × lower error than each UAV alone, with its CI
        table.add_column(Text("2^C (95% CI)"), **number)
    table.add_column(Text("Gap"), **number)
    if coverage:  # the ranked table holds full coverage only: its k/T column would repeat T/T
        table.add_column(Text("Tasks"), **number)
    for column in columns:
        # Text, not str: rich would read "[...]" in a submitted task ID as markup.
        table.add_column(Text(stacked_header(column.header)), **number)
    for standing in standings:
        score = standing.score
        k, n = standing.coverage(n_tasks)
        shown = standing.separable_rank if standing.separable_rank is not None else standing.rank
        cells = [Text(str(shown))] if ranked else []
        ci = "—" if score is None else "–".join(fmt_times(x) for x in score.times_ci)
        cells += [Text(standing.entry.name), Text(standing.entry.track),
                  Text(fmt_times(score.times if score else None)), Text(ci)]
        cells += [Text(_cooperation_text(score))] if cooperation else []
        cells += [Text(fmt_pct(score.gap_closed if score else None))] + ([Text(f"{k}/{n}")] if coverage else [])
        for column in columns:
            cs = column_score(score, column)
            cells.append(Text("—" if cs is None else fmt_times(cs.times) + ("" if cs.covered == cs.total else "*")))
        table.add_row(*cells)
    return table


def board_columns(board: SuiteBoard, family: str | None = None, tasks: str | Sequence[str] | None = None) -> list[Column]:
    """The task columns of a board: per family by default, else per task of ``family`` / ``tasks``.

    Raises:
        ValueError: an unknown family or task, or more than ``MAX_TASK_COLUMNS`` tasks.
    """
    if family is None and tasks is None:
        return family_columns(board.tasks)
    columns = task_columns(board.tasks, family, tasks)
    if len(columns) > MAX_TASK_COLUMNS:
        raise ValueError(f"{len(columns)} task columns do not fit a {TERMINAL_WIDTH}-column terminal; "
                         f"name at most {MAX_TASK_COLUMNS} tasks (or one family)")
    return columns


def board_tables(board: SuiteBoard, family: str | None = None,
                 tasks: str | Sequence[str] | None = None) -> list[Table | Text]:
    """The terminal view of one suite: ranked, partial-coverage and privileged tables, then a legend.

    Args:
        board: the suite's board.
        family, tasks: per-task columns of one family or of these tasks (see :func:`board_columns`).
    """
    columns = board_columns(board, family, tasks)
    n = len(board.tasks)
    suite = f"{board.name} v{board.version}"
    # titles as their own lines: a table title would wrap at the (narrower) table's width
    out: list[Table | Text] = [Text(f"swarmloc leaderboard — suite {suite} (ranked by 2^S; covering all "
                                    f"{n} tasks)", style="bold")]
    if board.ranked:
        out.append(_rich_table(board.ranked, columns, n, ranked=True, coverage=False))
    else:
        out.append(Text("No ranked methods: none has a score on every task of the suite.", style="italic"))
    if board.partial:
        out += [Text(f"Partial coverage on {suite} (ranked apart; 2^S over the covered tasks only)", style="bold"),
                _rich_table(board.partial, columns, n, ranked=True)]
    if board.privileged:
        out += [Text(f"Privileged methods on {suite} (use ground truth; not ranked)", style="bold"),
                _rich_table(board.privileged, columns, n, ranked=False)]
    what = "family" if family is None and tasks is None else "task"
    legend = (f"2^S: × lower error than the standard CEKF (uniform), geometric mean over tasks, stratified-"
              f"bootstrap 95% CI. #: 1 + the methods ahead beyond doubt (paired 95% CI of the difference in S "
              f"above 0); methods that share a # are not told apart by the seeds. Gap: share of the achievable "
              f"gain (to the information bound) closed, mean over tasks where it is defined. Tasks: "
              f"covered/total. {what.capitalize()} columns: × uniform over the {what}'s tasks (* some not "
              f"covered).")
    out.append(Text(legend + _filled_note(board), style=LEGEND_STYLE))
    return out


#: the track whose tables carry the cooperation gain
COOPERATIVE_TRACK = "cooperative"


def track_tables(board: SuiteBoard, per_track: dict[str, SuiteBoard], family: str | None = None,
                 tasks: str | Sequence[str] | None = None) -> list[Table | Text]:
    """The terminal view of a benchmark v2 suite: per track (headline first) its own ranked, partial-coverage and
    privileged tables, each with its own S, CI and ranks (and the cooperation gain on the cooperative track); one
    legend.

    Args:
        board: the suite's board (named family or tasks are checked against its tasks).
        per_track: track → its board (:func:`~swarmloc.leaderboard.site.ranking.track_boards`).
        family, tasks: per-task columns of one family or of these tasks; a track holding none of them
            shows its family columns.

    Raises:
        ValueError: an unknown family or task, or more than ``MAX_TASK_COLUMNS`` tasks.
    """
    chosen = board_columns(board, family, tasks)
    per_task = family is not None or tasks is not None
    suite = f"{board.name} v{board.version}"
    out: list[Table | Text] = []
    for track, tb in per_track.items():
        n = len(tb.tasks)
        columns = [c for c in chosen if set(c.tasks) <= set(tb.tasks)] if per_task else []
        columns = columns or family_columns(tb.tasks)
        cooperation = track == COOPERATIVE_TRACK
        where = f"{suite}, {track} track"
        out.append(Text(f"swarmloc leaderboard — suite {where} (ranked by 2^S; covering all {n} tasks of the track)",
                        style="bold"))
        if tb.ranked:
            out.append(_rich_table(tb.ranked, columns, n, ranked=True, coverage=False, cooperation=cooperation))
        else:
            out.append(Text("No ranked methods: none has a score on every task of the track.", style="italic"))
        if tb.partial:
            out += [Text(f"Partial coverage on {where} (ranked apart; 2^S over the covered tasks only)", style="bold"),
                    _rich_table(tb.partial, columns, n, ranked=True, cooperation=cooperation)]
        if tb.privileged:
            out += [Text(f"Privileged methods on {where} (use ground truth; not ranked)", style="bold"),
                    _rich_table(tb.privileged, columns, n, ranked=False, cooperation=cooperation)]
    legend = ("Scores never mix tracks: each track is ranked on its own tasks. 2^S: × lower error than the "
              "standard CEKF (uniform), score v2 (geometric mean over the track's task families, each weighing the "
              "same), hierarchical-bootstrap 95% CI (families, then seeds). #: 1 + the methods ahead beyond doubt on "
              "the track (paired 95% CI of the difference in S above 0). 2^C: cooperation gain, × lower error than "
              "each UAV localizing alone (non-cooperative), with its CI. Gap: share of the achievable gain (to the "
              "information bound) closed. Tasks: covered/total on the track. Other columns: × uniform over the "
              "family's or task's tasks (* some not covered).")
    out.append(Text(legend + _filled_note(board), style=LEGEND_STYLE))
    return out


def _filled_note(board) -> str:
    """The legend's note on episodes whose uniform RMSE came from the stored uniform entry ('' if none)."""
    if not board.filled:
        return ""
    ref = board.reference
    return (f" uniform_rmse of {board.filled} episode(s) taken from the stored uniform entry"
            f" (#{ref.id if ref else '?'}): their results files predate it.")


def leaderboard_tables(store: LeaderboardStore, suite: str | None = None, family: str | None = None,
                       tasks: str | Sequence[str] | None = None) -> list[Table | Text]:
    """Rich renderables: per suite, the tables of :func:`board_tables`.

    Args:
        store: The store to read.
        suite: Only this suite name (all suites when None).
        family, tasks: per-task columns of one family or of these tasks (default: per family).

    Returns:
        The tables and legends, in display order (empty when the store has no entries); a benchmark v2
        suite's per track (:func:`track_tables`).

    Raises:
        ValueError: an unknown family or task (see :func:`board_columns`).
    """
    parts: list[Table | Text] = []
    for (name, version), group in by_suite(store.entries(suite)).items():
        board = suite_board(name, version, group)
        per_track = track_boards(board, group)
        parts += track_tables(board, per_track, family, tasks) if per_track else board_tables(board, family, tasks)
    return parts


def print_leaderboard(store: LeaderboardStore, suite: str | None = None, console: Console | None = None,
                      family: str | None = None, tasks: str | Sequence[str] | None = None) -> None:
    """Print the terminal leaderboard (see :func:`leaderboard_tables`)."""
    # Piped output has no terminal width to fit: use the width the table is laid out for.
    out = console or (Console() if sys.stdout.isatty() else Console(width=TERMINAL_WIDTH))
    parts = leaderboard_tables(store, suite, family, tasks)
    if not parts:
        out.print(Text(f"The leaderboard at {store.url} is empty."))
    for part in parts:
        out.print(part)
        if isinstance(part, Text) and part.style == LEGEND_STYLE:
            out.print()


# -- export --------------------------------------------------------------------------


def _export_rows(entries: Sequence[LeaderboardEntry]) -> list[dict[str, Any]]:
    """Every board's rows: a v1 suite's board, or each track's board of a v2 suite (never one mixing tracks)."""
    rows = []
    for (name, version), group in by_suite(entries).items():
        board = suite_board(name, version, group)
        per_track = track_boards(board, group)
        for track, track_board in (per_track.items() if per_track else [(None, board)]):
            rows += _board_rows(track_board, track)
    return rows


def _board_rows(board: SuiteBoard, track: str | None) -> list[dict[str, Any]]:
    """The rows of one board; a v2 track's carry ``suite_track`` and the cooperation gain (``C``, ``cooperation_*``)."""
    rows = []
    for table, standings in (("ranked", board.ranked), ("partial", board.partial),
                             ("privileged", board.privileged)):
        for standing in standings:
            entry, score = standing.entry, standing.score
            k, n = standing.coverage(len(board.tasks))
            gain = None if score is None else score.cooperation
            row: dict[str, Any] = {
                "id": entry.id,
                "suite": entry.suite_name,
                "suite_version": entry.suite_version,
                **({} if track is None else {"suite_track": track}),
                "rank": standing.rank if table == "ranked" else None,
                "name": entry.name,
                "authors": entry.authors,
                "url": entry.url,
                "track": entry.track,
                "privileged": entry.privileged,
                "deterministic": entry.deterministic,
                "verified": entry.verified,
                "trusted": entry.trusted,
                "table": table,
                "partial_rank": standing.rank if table == "partial" else None,
                "separable_rank": standing.separable_rank,
                "times_uniform": score.times if score else None,
                "times_ci_low": score.times_ci[0] if score else None,
                "times_ci_high": score.times_ci[1] if score else None,
                "S": score.S if score else None,
                **({} if track is None else {
                    "cooperation_times": None if gain is None else 2.0**gain.S,
                    "cooperation_ci_low": None if gain is None else 2.0**gain.ci_low,
                    "cooperation_ci_high": None if gain is None else 2.0**gain.ci_high,
                    "C": None if gain is None else gain.S,
                }),
                "iqm_gain": score.iqm if score else None,
                "gap_closed": score.gap_closed if score else None,
                "tasks_covered": k,
                "tasks_total": n,
                "uniform_rmse_filled": standing.filled,
                "delay_ms": entry.delay_ms,
                "energy_j": entry.energy_j,
                "jitter": entry.jitter,
            }
            for task in board.tasks:
                t = score.tasks.get(task) if score else None
                row[f"times[{task}]"] = None if t is None else 2.0**t.mean
                row[f"gap_closed[{task}]"] = None if t is None else t.gap_closed
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

    One row per submission and board, in board order: a v1 suite's board, or each track's board of a
    benchmark v2 suite (scores never mix tracks: such a row carries ``suite_track`` and is scored on
    that track's tasks only, with the cooperation gain ``cooperation_times`` = 2^C, its CI and ``C``).
    Then: suite, rank (empty outside the ranked table),
    metadata, ``table`` (``ranked``, ``partial`` or ``privileged``), ``partial_rank`` and
    ``separable_rank`` (1 + the ranked methods ahead beyond doubt; empty outside the ranked table),
    the score (``times_uniform`` = 2^S with its CI, ``S``, ``iqm_gain``, ``gap_closed``,
    ``tasks_covered``/``tasks_total``, ``uniform_rmse_filled`` — episodes scored through the
    uniform fallback), mean delay/energy/jitter,
    per task ``times[<task>]`` (2^G_t), ``gap_closed[<task>]`` and the mean RMSE
    ``rmse[<task>]``, entry point, method hash, submission time. JSON rows also carry
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
    "TERMINAL_WIDTH",
    "ExportFormat",
    "board_columns",
    "board_tables",
    "by_suite",
    "export",
    "leaderboard_tables",
    "print_leaderboard",
    "render_html",
    "split_ranked",
]
