"""``swarmloc demo``: every shipped method on the quick suite, a comparison table, plots.

Runs the registry's methods on a suite (default ``quick``), writes one results file per
method (``<out>/results/<method>.json`` + traces), prints two tables — mean RMSE per
task and method, and a per-method summary (the score: 2^S with its 95 % CI, gap closed, coverage, delay,
energy, jitter, weight variance, anomaly detection, divergence) — with the privileged
oracle shown apart, writes the same tables as Markdown (``<out>/summary.md``) and the
plots (``<out>/plots/``).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from swarmloc.bench.common.files import write_text_atomic
from swarmloc.bench.evaluation.backends import Backend
from swarmloc.bench.evaluation.results import Results, write_results
from swarmloc.bench.evaluation.runner import EvaluationFailed, evaluate_methods, traces_path, write_traces
from swarmloc.bench.evaluation.suites import Suite
from swarmloc.bench.reports.markdown import markdown_table
from swarmloc.bench.reports.plots import plot_results, short_name
from swarmloc.bench.scoring.score import suite_score
from swarmloc.bench.scoring.tracks import tasks_by_track


@dataclass(frozen=True)
class SummaryRow:
    """One method's line of the summary table (means over every episode of the suite)."""

    method: str
    track: str
    privileged: bool
    tasks: str  # tasks covered / tasks in the suite
    full: bool  # every task covered
    score: tuple[float, float, float] | None  # 2^S, CI low, CI high (the score)
    gap_closed: float | None
    iqm_gain: float | None
    delay_ms: float | None
    energy_mj: float | None
    jitter: float | None
    weight_var: float | None
    detection: float | None
    diverged: float | None
    cpu_s: float | None = None


def _mean(results: Results, metric: str) -> float | None:
    values = [getattr(e.metrics, metric) for e in results.episodes]
    values = [v for v in values if v is not None]
    return float(np.mean(values)) if values else None


def summarize_results(results: Results, cpu_s: float | None = None, tasks: Sequence[str] | None = None) -> SummaryRow:
    """The summary line of one results file (``cpu_s``: the method's CPU time, if measured), over ``tasks``
    (default: every task of the file; a benchmark v2 board scores one track's tasks)."""
    chosen = list(results.aggregates) if tasks is None else [t for t in results.aggregates if t in tasks]
    score = suite_score([e.model_dump() for e in results.episodes if e.task in chosen], chosen,
                        suite=results.suite.name)
    energy = _mean(results, "energy_j")
    k, n = score.coverage if score is not None else (0, len(chosen))
    return SummaryRow(
        method=results.method.name, track=results.method.track, privileged=results.method.privileged,
        tasks=f"{k}/{n}", full=k == n,
        score=None if score is None else (score.times, *score.times_ci),
        gap_closed=None if score is None else score.gap_closed, iqm_gain=None if score is None else score.iqm,
        delay_ms=_mean(results, "delay_ms"),
        energy_mj=None if energy is None else 1e3 * energy, jitter=_mean(results, "jitter"),
        weight_var=_mean(results, "weight_var"), detection=_mean(results, "anomaly_detection_rate"),
        diverged=_mean(results, "diverged"), cpu_s=cpu_s,
    )


def _fmt(value: float | None, digits: int = 3) -> str:
    if value is None:
        return "—"
    if value != 0 and (abs(value) >= 1000 or abs(value) < 10 ** -(digits - 1)):
        return f"{value:.2e}"
    return f"{value:.{digits}f}"


def _ordered(all_results: dict[str, Results]) -> list[Results]:
    """Non-privileged methods first (in the given order), privileged ones last."""
    items = list(all_results.values())
    return [r for r in items if not r.method.privileged] + [r for r in items if r.method.privileged]


def task_label(task: str) -> str:
    """Column label of a task: ``swarmloc/NLOS-v0`` → ``NLOS``."""
    return short_name(task).removesuffix("-v0")


def rmse_rows(all_results: dict[str, Results]) -> tuple[list[str], list[list[str]]]:
    """Header (tasks) and rows (methods; privileged marked †) of the mean-RMSE table."""
    ordered = _ordered(all_results)
    tasks = list(dict.fromkeys(e.task for r in ordered for e in r.episodes))
    header = ["method"] + [task_label(t) for t in tasks]
    rows = []
    for r in ordered:
        cells = [r.method.name + ("†" if r.method.privileged else "")]
        for task in tasks:
            agg = r.aggregates.get(task, {}).get("rmse")
            cells.append(_fmt(None if agg is None else agg.mean, 3 if agg is None or agg.mean < 100 else 1))
        rows.append(cells)
    return header, rows


#: the width the tables are laid out for when the output is not a terminal: the summary's 14 columns need 153
PIPE_WIDTH = 160

SUMMARY_HEADER = ["method", "track", "tasks", "× uniform", "95% CI", "gap closed", "IQM g", "ms/step", "mJ/UAV",
                  "jitter", "α var", "detect", "diverged", "CPU [s]"]


def summary_cells(row: SummaryRow) -> list[str]:
    """Cells of one summary line (see :data:`SUMMARY_HEADER`)."""
    s = row.score
    return [row.method + ("†" if row.privileged else ""), row.track, row.tasks,
            f"{s[0]:.2f}×" if s else "—", f"{s[1]:.2f}–{s[2]:.2f}" if s else "—",
            "—" if row.gap_closed is None else f"{100 * row.gap_closed:.0f}%", _fmt(row.iqm_gain, 2),
            _fmt(row.delay_ms, 4),
            _fmt(row.energy_mj), _fmt(row.jitter), _fmt(row.weight_var), _fmt(row.detection),
            "—" if row.diverged is None else f"{100 * row.diverged:.0f}%",
            "—" if row.cpu_s is None else f"{row.cpu_s:.1f}"]


def _ranked(all_results: dict[str, Results], cpu: dict[str, float] | None = None,
            tasks: Sequence[str] | None = None) -> tuple[list[SummaryRow], list[SummaryRow]]:
    """Summary rows over ``tasks`` (default all): public methods covering every task by 2^S (best first), then
    partial coverage, then privileged ones."""
    cpu = cpu or {}
    rows = [summarize_results(r, cpu.get(r.method.name), tasks) for r in _ordered(all_results)]
    public = sorted([r for r in rows if not r.privileged],
                    key=lambda r: (not r.full, -(r.score[0] if r.score else -np.inf)))
    return public, [r for r in rows if r.privileged]


def print_tables(all_results: dict[str, Results], console: Console, suite: Suite,
                 cpu: dict[str, float] | None = None) -> None:
    """Print the mean-RMSE table (methods × tasks, split to fit the width) and the summary."""
    header, rows = rmse_rows(all_results)
    n_seeds = len(suite.seeds(suite.tasks[0]))
    n_public = sum(not r.method.privileged for r in all_results.values())
    name_width = max(len(cells[0]) for cells in rows) + 3
    per_table = max(1, (console.width - name_width - 4) // 10)
    task_cols = list(range(1, len(header)))
    chunks = [task_cols[i:i + per_table] for i in range(0, len(task_cols), per_table)]
    for c, cols in enumerate(chunks):
        part = f" ({c + 1}/{len(chunks)})" if len(chunks) > 1 else ""
        table = Table(title=escape(f"mean RMSE [m] — suite {suite.name}, {n_seeds} seeds per task{part}; "
                            "† privileged (reads fault labels), not ranked; — not run"), title_style="bold")
        table.add_column("method", no_wrap=True)
        for j in cols:
            table.add_column(escape(header[j]), justify="right", max_width=8, overflow="fold")
        for i, cells in enumerate(rows):
            if i == n_public:
                table.add_section()
            table.add_row(escape(cells[0]), *[cells[j] for j in cols], style="dim italic" if i >= n_public else None)
        console.print(table)
    for board, tasks in boards(suite).items():
        t2 = Table(title=escape(_board_title(board) + "summary — × uniform: 2^S, how many times lower the error is "
                                f"than the standard CEKF's ({_averaging(board)} 95% CI); gap closed: of the way "
                                "from uniform to the information bound; partial coverage ranked apart; "
                                "CPU [s]: the method's evaluation time here"),
                   title_style="bold")
        for j, name in enumerate(SUMMARY_HEADER):
            t2.add_column(escape(name), justify="left" if j < 2 else "right", no_wrap=j in (0, 3, 4, 5))
        public, privileged = _ranked(all_results, cpu, tasks)
        for r in public:
            t2.add_row(*map(escape, summary_cells(r)))
        if privileged:
            t2.add_section()
            for r in privileged:
                t2.add_row(*map(escape, summary_cells(r)), style="dim italic")
        console.print(t2)


def boards(suite: Suite) -> dict[str | None, list[str] | None]:
    """The summary boards of a suite: one per benchmark v2 track (its tasks), or one board of every task (None)
    for a v0/v1 suite, whose tasks name no track. Scores never mix tracks."""
    groups = tasks_by_track(suite.tasks)
    if list(groups) == [None]:
        return {None: None}
    return dict(groups)


def _board_title(board: str | None) -> str:
    return "" if board is None else f"{board} track: "


def _averaging(board: str | None) -> str:
    if board is None:
        return "geometric mean over covered tasks, stratified bootstrap"
    return "families weigh equally, hierarchical bootstrap over families and seeds"


def markdown_tables(all_results: dict[str, Results], suite: Suite, cpu: dict[str, float] | None = None) -> str:
    """The two tables as Markdown (for ``summary.md`` and the README)."""
    header, rows = rmse_rows(all_results)
    lines = [f"Mean RMSE [m] per task (suite `{suite.name}`, {len(suite.seeds(suite.tasks[0]))} seeds per task; "
             "† privileged, not ranked; — not run):", ""]
    lines += markdown_table(header, rows, align="l" + "r" * (len(header) - 1))
    for board, tasks in boards(suite).items():
        public, privileged = _ranked(all_results, cpu, tasks)
        averaging = "geometric mean over the covered tasks, stratified bootstrap" if board is None else _averaging(board)
        lines += ["", f"{_board_title(board).capitalize()}Summary (× uniform: 2^S, how many times lower the error is "
                  f"than the standard CEKF's, {averaging} 95% CI; gap closed: mean over tasks of "
                  "the gain over the gain achievable down to the information bound; IQM g: interquartile mean of the "
                  "per-episode log2 gains; partial coverage ranked apart; ms/step and mJ/UAV on the reference "
                  "processor; CPU [s]: the method's own evaluation time here, all tasks):", ""]
        lines += markdown_table(SUMMARY_HEADER, [summary_cells(r) for r in public + privileged],
                                align="ll" + "r" * (len(SUMMARY_HEADER) - 2))
    return "\n".join(lines) + "\n"


def loadable_methods(methods: Sequence[str], console: Console) -> list[str]:
    """The methods that load here (e.g. a learned method whose weights are not shipped yet is skipped, with a note)."""
    from swarmloc.agents.registry import load_method

    ok = []
    for name in methods:
        try:
            load_method(name)
        except (OSError, ImportError) as err:
            console.print(f"[yellow]skipping {name}:[/yellow] {err}")
            continue
        ok.append(name)
    return ok


def run_demo(methods: Sequence[str], suite: Suite, out: Path, workers: int = 2, plots: bool = True,
             console: Console | None = None, backend: Backend | None = None,
             address: str | None = None) -> dict[str, Results]:
    """Evaluate ``methods`` on ``suite``, print the tables, write results, Markdown and plots.

    Args:
        methods: method names or entry points.
        suite: the suite (the demo uses ``quick``).
        out: output folder (created): ``results/``, ``plots/``, ``summary.md``.
        workers: worker processes (or CPUs of a local Ray cluster).
        plots: also write the PNGs.
        console: where to print (default: a new rich console).
        backend: ``serial``, ``process`` or ``ray`` (default: serial for one worker, else process).
        address: Ray cluster to join (``ray`` only).

    Returns:
        method → its ``Results``.
    """
    if console is None:
        console = Console()
        if not console.is_terminal:  # a pipe or file: do not squeeze the tables into 80 columns
            console.width = max(console.width, PIPE_WIDTH)
    started = time.perf_counter()
    methods = loadable_methods(methods, console)
    out.mkdir(parents=True, exist_ok=True)
    (out / "results").mkdir(exist_ok=True)
    console.print(f"[bold]swarmloc demo[/bold]: {len(methods)} methods × {len(suite.tasks)} tasks × "
                  f"{len(suite.seeds(suite.tasks[0]))} seeds (suite {suite.name}), {workers} worker(s)")
    runs = evaluate_methods(methods, suite, workers=workers, backend=backend, address=address, trace=plots)
    all_results: dict[str, Results] = {}
    cpu: dict[str, float] = {}
    paths = []
    for name, run in runs.items():
        if run.unsupported:
            tasks = ", ".join(short_name(t) for t in run.unsupported)
            first = next(iter(run.unsupported.values()))
            console.print(f"[yellow]{escape(run.loaded.name)} not run on {len(run.unsupported)} task(s)[/yellow] "
                          f"({escape(tasks)}): {escape(first)}")
        if run.failed:  # the other methods' tables still come
            console.print(f"[red]{escape(str(EvaluationFailed(run.loaded.name, run.failed, None)))}[/red]")
            continue
        results = run.results(suite)
        path = out / "results" / f"{run.loaded.name}.json"
        write_results(path, results)
        if run.traces:
            write_traces(traces_path(path), run.traces)
        all_results[name] = results
        cpu[run.loaded.name] = run.cpu_seconds
        if run.traces:
            paths.append(path)
    evaluated = time.perf_counter() - started
    print_tables(all_results, console, suite, cpu)
    write_text_atomic(out / "summary.md", markdown_tables(all_results, suite, cpu))
    if plots:
        written = plot_results(paths, out / "plots", workers=workers)
        console.print(f"wrote {len(written)} plots to {out / 'plots'}")
    console.print(f"results in {out / 'results'}, tables in {out / 'summary.md'}; evaluation {evaluated:.0f} s, "
                  f"total {time.perf_counter() - started:.0f} s")
    return all_results
