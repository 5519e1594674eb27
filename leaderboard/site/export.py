"""The leaderboard as data: CSV and JSON rows per method and board, and marl-eval's raw-data JSON.

One row per standing and board: a v1 suite's board, or each track's board of a benchmark v2 suite
(scores never mix tracks). A standing is one entry, or the training runs of one method
(:mod:`swarmloc.leaderboard.site.runs`), whose row carries the run-level numbers. The marl-eval
layout is :mod:`swarmloc.leaderboard.site.marl_eval`'s.

Every submitted string is data: CSV text cells that start with ``= + - @`` are prefixed with ``'``
so spreadsheets do not run them (OWASP CSV injection); JSON keeps the exact text.
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Sequence
from typing import Any, Literal, get_args

from swarmloc.leaderboard.site.compute import DELAY_BUDGET_MS, standing_compute
from swarmloc.leaderboard.site.marl_eval import marl_eval_data
from swarmloc.leaderboard.site.ranking import Standing, SuiteBoard, by_suite, suite_board, task_rmse, track_boards
from swarmloc.leaderboard.store.database import LeaderboardEntry, LeaderboardStore

ExportFormat = Literal["csv", "json", "marl-eval"]
EXPORT_FORMATS: tuple[str, ...] = get_args(ExportFormat)


def boards(entries: Sequence[LeaderboardEntry]) -> list[tuple[SuiteBoard, str | None]]:
    """Every board with its track: a v1 suite's board (track None), or each track's board of a v2 suite."""
    out = []
    for (name, version), group in by_suite(entries).items():
        board = suite_board(name, version, group)
        per_track = track_boards(board, group)
        out += [(b, track) for track, b in per_track.items()] if per_track else [(board, None)]
    return out


def _shared(standing: Standing, field: str) -> Any:
    """A field every entry of the standing agrees on (its runs are one method), else None."""
    values = {getattr(e, field) for e in standing.entries}
    return values.pop() if len(values) == 1 else None


def _runs_fields(standing: Standing) -> dict[str, Any]:
    """The run count, the runs' seeds and S, and the IQM over runs with its CI (log2 units; one run: its S and CI)."""
    score, total = standing.score, standing.over_runs
    return {
        "runs": standing.n_runs,
        "run_seeds": [e.run for e in standing.entries],
        "runs_S": list(total.runs) if total else ([score.S] if score else []),
        "runs_iqm": score.S if score else None,
        "runs_ci_low": score.ci_low if score else None,
        "runs_ci_high": score.ci_high if score else None,
    }


def _compute_fields(standing: Standing, tasks: Sequence[str]) -> dict[str, Any]:
    """The compute view's numbers (:mod:`swarmloc.leaderboard.site.compute`)."""
    cost = standing_compute(standing, tasks)
    return {
        "delay_ms": cost.delay_ms,
        "delay_worst_task": None if cost.worst_task is None else cost.worst_task[0],
        "delay_worst_ms": None if cost.worst_task is None else cost.worst_task[1],
        "delay_budget_ms": DELAY_BUDGET_MS,
        "tasks_over_delay_budget": cost.over_budget if cost.measured else None,
        "flops_per_channel": cost.flops_per_channel,
    }


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
                "privileged_training": _shared(standing, "privileged_training"),
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
                **_runs_fields(standing),
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
                **_compute_fields(standing, board.tasks),
                "energy_j": _mean(e.energy_j for e in standing.entries),
                "jitter": _mean(e.jitter for e in standing.entries),
            }
            for task in board.tasks:
                t = score.tasks.get(task) if score else None
                row[f"times[{task}]"] = None if t is None else 2.0**t.mean
                row[f"gap_closed[{task}]"] = None if t is None else t.gap_closed
                row[f"rmse[{task}]"] = _mean(task_rmse(e, task) for e in standing.entries)
            row.update(
                entry_point=entry.entry_point,
                method_hash=entry.method_hash,
                created_utc=entry.created_utc.isoformat(),
            )
            rows.append(row)
    return rows


def _mean(values: Any) -> float | None:
    """The mean of the values, None when any is None (a standing's runs: each must have it)."""
    values = list(values)
    return None if not values or any(v is None for v in values) else sum(values) / len(values)


def _csv_cell(value: Any) -> Any:
    """A CSV cell: a list as its items joined by ``;``, text with a leading formula character neutralized."""
    if isinstance(value, list):
        value = ";".join("" if v is None else str(v) for v in value)
    if isinstance(value, str) and value[:1] in ("=", "+", "-", "@", "\t", "\r"):
        return "'" + value
    return value


def export(store: LeaderboardStore, format: ExportFormat = "csv", suite: str | None = None) -> str:
    """The leaderboard as CSV, JSON or marl-eval JSON text.

    CSV and JSON: one row per standing and board, in board order: a v1 suite's board, or each track's board
    of a benchmark v2 suite (scores never mix tracks: such a row carries ``suite_track`` and is scored on
    that track's tasks only, with the cooperation gain ``cooperation_times`` = 2^C, its CI and ``C``).
    Then: suite, rank (empty outside the ranked table), metadata (``privileged_training``: weights fitted
    to privileged labels while training), ``table`` (``ranked``, ``partial`` or ``privileged``),
    ``partial_rank`` and ``separable_rank`` (1 + the ranked methods ahead beyond doubt; empty outside the
    ranked table), the score (``times_uniform`` = 2^S with its CI, ``S``), the runs (``runs``: how many
    training runs the standing stands for, ``run_seeds``, ``runs_S`` each run's S, ``runs_iqm`` with
    ``runs_ci_low``/``runs_ci_high``: the IQM over runs and its 95 % CI in log2 units, equal to S and its
    CI), ``iqm_gain``, ``gap_closed``, ``tasks_covered``/``tasks_total``, ``uniform_rmse_filled``
    (episodes scored through the uniform fallback), the compute view (``delay_ms`` per update, its worst
    task ``delay_worst_task``/``delay_worst_ms``, ``delay_budget_ms``, ``tasks_over_delay_budget``,
    ``flops_per_channel``), mean energy/jitter, per task ``times[<task>]`` (2^G_t), ``gap_closed[<task>]``
    and the mean RMSE ``rmse[<task>]``, entry point, method hash, submission time (a standing of several
    runs: those of the run nearest the IQM). JSON rows also carry ``task_aggregates`` (every metric's mean,
    IQM and CI per task, of that run); CSV writes a list as its items joined by ``;``.

    marl-eval: :func:`swarmloc.leaderboard.site.marl_eval.marl_eval_data` as JSON.

    Args:
        store: The store to read.
        format: ``"csv"``, ``"json"`` or ``"marl-eval"``.
        suite: Only this suite name (all suites when None).

    Returns:
        The exported text.

    Raises:
        ValueError: an unknown format (naming the allowed ones).
    """
    if format not in EXPORT_FORMATS:
        raise ValueError(f"unknown export format {format!r}; allowed: {', '.join(map(repr, EXPORT_FORMATS))}")
    entries = store.entries(suite)
    if format == "marl-eval":
        return json.dumps(marl_eval_data(boards(entries)), indent=1, allow_nan=False) + "\n"
    rows = [row for board, track in boards(entries) for row in _board_rows(board, track)]
    if format == "json":
        by_id = {e.id: e for e in entries}
        for row in rows:
            row["task_aggregates"] = {
                task: {m: agg.model_dump() for m, agg in per.items()}
                for task, per in sorted(by_id[row["id"]].task_aggregates.items())
            }
        return json.dumps(rows, indent=1, allow_nan=False) + "\n"
    buffer = io.StringIO()
    fields: list[str] = []
    for row in rows:
        fields += [k for k in row if k not in fields]
    writer = csv.DictWriter(buffer, fieldnames=fields, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: _csv_cell(v) for k, v in row.items()})
    return buffer.getvalue()


__all__ = ["EXPORT_FORMATS", "ExportFormat", "boards", "export"]
