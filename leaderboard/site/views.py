"""Views of the store: the terminal tables (accuracy and compute), the static HTML site, the exports.

Methods are ranked per suite by the score (``2^S``: how many times lower the error is than
the standard CEKF's, with its 95 % CI), beside the gap closed towards the information bound
and the task coverage ``k/T``; partial coverage is ranked in its own table and privileged
methods (those that read ground truth) are shown apart, not ranked (see
:mod:`swarmloc.leaderboard.site.ranking`). The terminal table fits 100 columns: one column per
task family, or per task of one family (``family=``) or of a list (``tasks=``). ``‡`` marks a
method fitted to privileged labels while training, ``(n runs)`` a method's n training runs shown as
one standing. The compute view (``view="compute"``) gives, beside the same order, each method's
delay per update against the 50 ms budget and its FLOPs per channel
(:mod:`swarmloc.leaderboard.site.compute`). The exports are :mod:`swarmloc.leaderboard.site.export`'s.

Every submitted string is treated as data: escaped with ``html.escape`` in HTML
(:mod:`swarmloc.leaderboard.site.html`), shown as literal ``rich.text.Text`` in the
terminal, and guarded against spreadsheet formula injection in CSV.
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Iterator, Sequence
from typing import Any, Literal

from rich import box
from rich.console import Console
from rich.table import Table
from rich.text import Text

from swarmloc.bench.scoring.score import SuiteScore
from swarmloc.leaderboard.errors import StoreError
from swarmloc.leaderboard.site.compute import DELAY_BUDGET_MS, compute_rows, place
from swarmloc.leaderboard.site.export import ExportFormat, export
from swarmloc.leaderboard.site.html import render_html
from swarmloc.leaderboard.site.ranking import (
    PRIVILEGED_TRAINING_NOTE,
    Column,
    Standing,
    SuiteBoard,
    by_suite,
    column_score,
    family_columns,
    fmt,
    fmt_pct,
    fmt_times,
    method_label,
    privileged_training,
    runs_note,
    split_ranked,
    suite_board,
    task_columns,
    task_label,
    track_boards,
)
from swarmloc.leaderboard.store.database import LeaderboardStore

View = Literal["accuracy", "compute"]
VIEWS: tuple[str, ...] = ("accuracy", "compute")

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
        cells += [Text(method_label(standing)), Text(standing.entry.track),
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
    out.append(Text(legend + _made_note(board) + _filled_note(board), style=LEGEND_STYLE))
    return out


#: the track whose tables carry the cooperation gain
COOPERATIVE_TRACK = "cooperative"


def track_tables(board: SuiteBoard, per_track: dict[str, SuiteBoard], family: str | None = None,
                 tasks: str | Sequence[str] | None = None, top: int | None = None) -> list[Table | Text]:
    """The terminal view of a benchmark v2 suite: per track (headline first) its own ranked, partial-coverage and
    privileged tables, each with its own S, CI and ranks (and the cooperation gain on the cooperative track); one
    legend.

    Args:
        board: the suite's board (named family or tasks are checked against its tasks).
        per_track: track → its board (:func:`~swarmloc.leaderboard.site.ranking.track_boards`).
        family, tasks: per-task columns of one family or of these tasks; a track holding none of them
            shows its family columns.
        top: only the first ``top`` ranked methods of each track, without the partial-coverage and
            privileged tables (the README's summary); None: every table whole.

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
            ranked = tb.ranked if top is None else tb.ranked[:top]
            out.append(_rich_table(ranked, columns, n, ranked=True, coverage=False, cooperation=cooperation))
            if len(ranked) < len(tb.ranked):
                out.append(Text(f"… and {len(tb.ranked) - len(ranked)} more ranked methods, the partial-coverage and "
                                f"privileged tables: swarmloc leaderboard show --shipped", style="italic"))
        else:
            out.append(Text("No ranked methods: none has a score on every task of the track.", style="italic"))
        if top is not None:
            continue
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
    out.append(Text(legend + _made_note(board) + _filled_note(board), style=LEGEND_STYLE))
    return out


def _made_note(board: SuiteBoard) -> str:
    """The legend's notes on how the methods were made: ‡ and (n runs), where the board has them ('' if not)."""
    notes = [PRIVILEGED_TRAINING_NOTE] if any(privileged_training(s) for s in board.standings) else []
    notes += [runs_note(board)] if runs_note(board) else []
    return "".join(f" {note}" for note in notes)


def _filled_note(board) -> str:
    """The legend's note on episodes whose uniform RMSE came from the stored uniform entry ('' if none)."""
    if not board.filled:
        return ""
    ref = board.reference
    return (f" uniform_rmse of {board.filled} episode(s) taken from the stored uniform entry"
            f" (#{ref.id if ref else '?'}): their results files predate it.")


def _compute_table(board: SuiteBoard) -> Table:
    """One board's compute view: the accuracy order, 2^S beside the delay per update, its worst task, the tasks
    over the budget and the FLOPs per channel."""
    table = Table(header_style="bold", box=box.SIMPLE_HEAD, padding=(0, 1, 0, 0), show_edge=False)
    number: dict[str, Any] = {"justify": "right", "no_wrap": True}
    table.add_column(Text("#"), **number)
    table.add_column(Text("Method"), overflow="fold", max_width=METHOD_WIDTH + 8)
    table.add_column(Text("Trk"), justify="center", no_wrap=True)
    table.add_column(Text("2^S"), **number)
    table.add_column(Text("Delay/update\n[ms]"), **number)
    table.add_column(Text("Worst task\n[ms]"), **number)
    table.add_column(Text(f"Over\n{DELAY_BUDGET_MS:g} ms"), **number)
    table.add_column(Text("FLOPs/\nchannel"), **number)
    for standing, cost in compute_rows(board):
        score = standing.score
        worst = "—" if cost.worst_task is None else f"{task_label(cost.worst_task[0])} {fmt(cost.worst_task[1], 2)}"
        table.add_row(Text(place(board, standing)), Text(method_label(standing)),
                      Text(standing.entry.track), Text(fmt_times(score.times if score else None)),
                      Text("not measured" if cost.delay_ms is None else fmt(cost.delay_ms, 2)), Text(worst),
                      Text("—" if cost.delay_ms is None else f"{cost.over_budget}/{cost.measured}"),
                      Text("—" if cost.flops_per_channel is None else f"{cost.flops_per_channel:,.0f}"))
    return table


def compute_tables(board: SuiteBoard, per_track: dict[str, SuiteBoard]) -> list[Table | Text]:
    """The terminal compute view of a suite (per track for a benchmark v2 suite), in the accuracy tables' order.

    Args:
        board: the suite's board.
        per_track: track → its board (empty for a v1 suite).
    """
    out: list[Table | Text] = []
    suite = f"{board.name} v{board.version}"
    for track, tb in (per_track.items() if per_track else [(None, board)]):
        where = suite if track is None else f"{suite}, {track} track"
        out += [Text(f"swarmloc compute — suite {where} (the accuracy order; budget {DELAY_BUDGET_MS:g} ms per "
                     f"update)", style="bold"), _compute_table(tb)]
    legend = (f"Delay/update: compute time per UAV-step, filter + the method's FLOPs on the processor profile "
              f"(results' delay_ms), mean over the tasks; not measured where the method reports no FLOPs. Worst "
              f"task: the task of the highest mean delay. Over {DELAY_BUDGET_MS:g} ms: tasks whose mean delay "
              f"exceeds the standard reward's T_max (madrl's budget), of those measured. FLOPs/channel: what the "
              f"method declares per present channel and step (— where it declares none). #: the accuracy tables' (p: "
              f"partial coverage).")
    out.append(Text(legend + _made_note(board), style=LEGEND_STYLE))
    return out


def leaderboard_tables(store: LeaderboardStore, suite: str | None = None, family: str | None = None,
                       tasks: str | Sequence[str] | None = None, view: View = "accuracy",
                       top: int | None = None) -> list[Table | Text]:
    """Rich renderables: per suite, the tables of :func:`board_tables`, or of :func:`compute_tables`.

    Args:
        store: The store to read.
        suite: Only this suite name (all suites when None).
        family, tasks: per-task columns of one family or of these tasks (default: per family; accuracy view).
        view: ``"accuracy"`` (the ranking) or ``"compute"`` (delay per update and FLOPs, same order).
        top: a v2 suite's accuracy view shows only each track's first ``top`` ranked methods (:func:`track_tables`).

    Returns:
        The tables and legends, in display order (empty when the store has no entries); a benchmark v2
        suite's per track (:func:`track_tables`).

    Raises:
        ValueError: an unknown view, family or task (see :func:`board_columns`).
    """
    if view not in VIEWS:
        raise ValueError(f"unknown view {view!r}; allowed: {', '.join(map(repr, VIEWS))}")
    parts: list[Table | Text] = []
    for (name, version), group in by_suite(store.entries(suite)).items():
        board = suite_board(name, version, group)
        per_track = track_boards(board, group)
        if view == "compute":
            parts += compute_tables(board, per_track)
        else:
            parts += (track_tables(board, per_track, family, tasks, top) if per_track
                      else board_tables(board, family, tasks))
    return parts


def print_leaderboard(store: LeaderboardStore, suite: str | None = None, console: Console | None = None,
                      family: str | None = None, tasks: str | Sequence[str] | None = None,
                      view: View = "accuracy", top: int | None = None) -> None:
    """Print the terminal leaderboard (see :func:`leaderboard_tables`)."""
    # Piped output has no terminal width to fit: use the width the table is laid out for.
    out = console or (Console() if sys.stdout.isatty() else Console(width=TERMINAL_WIDTH))
    parts = leaderboard_tables(store, suite, family, tasks, view, top)
    if not parts:
        out.print(Text(f"The leaderboard at {store.url} is empty."))
    for part in parts:
        out.print(part)
        if isinstance(part, Text) and part.style == LEGEND_STYLE:
            out.print()


__all__ = [
    "TERMINAL_WIDTH",
    "VIEWS",
    "ExportFormat",
    "View",
    "board_columns",
    "board_tables",
    "by_suite",
    "compute_tables",
    "export",
    "leaderboard_tables",
    "print_leaderboard",
    "render_html",
    "split_ranked",
]
