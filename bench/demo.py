"""``swarmloc demo``: every shipped method on the quick suite, a comparison table, plots.

Runs the registry's methods on a suite (default ``quick``), writes one results file per
method (``<out>/results/<method>.json`` + traces), prints two tables — mean RMSE per
task and method, and a per-method summary (normalized score with IQM and 95 % CI, delay,
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
from rich.table import Table

from swarmloc.bench.plots import plot_results, short_name
from swarmloc.bench.results import Results, write_results
from swarmloc.bench.runner import evaluate_methods, traces_path, write_traces
from swarmloc.bench.stats import aggregate_across_tasks
from swarmloc.bench.suites import Suite


@dataclass(frozen=True)
class SummaryRow:
    """One method's line of the summary table (means over every episode of the suite)."""

    method: str
    track: str
    privileged: bool
    score: tuple[float, float, float, float] | None  # mean, IQM, CI low, CI high
    rmse: float
    delay_ms: float | None
    energy_mj: float | None
    jitter: float | None
    weight_var: float | None
    detection: float | None
    diverged: float


def _mean(results: Results, metric: str) -> float | None:
    values = [getattr(e.metrics, metric) for e in results.episodes]
    values = [v for v in values if v is not None]
    return float(np.mean(values)) if values else None


def summarize_results(results: Results) -> SummaryRow:
    """The summary line of one results file."""
    score = aggregate_across_tasks(results.episodes, "normalized_score")
    energy = _mean(results, "energy_j")
    return SummaryRow(
        method=results.method.name, track=results.method.track, privileged=results.method.privileged,
        score=None if score is None else (score.mean, score.iqm, score.ci_low, score.ci_high),
        rmse=float(_mean(results, "rmse") or 0.0), delay_ms=_mean(results, "delay_ms"),
        energy_mj=None if energy is None else 1e3 * energy, jitter=_mean(results, "jitter"),
        weight_var=_mean(results, "weight_var"), detection=_mean(results, "anomaly_detection_rate"),
        diverged=float(_mean(results, "diverged") or 0.0),
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


def rmse_rows(all_results: dict[str, Results]) -> tuple[list[str], list[list[str]]]:
    """Header and rows of the per-task mean-RMSE table (privileged methods marked †)."""
    ordered = _ordered(all_results)
    header = ["task"] + [r.method.name + ("†" if r.method.privileged else "") for r in ordered]
    tasks = list(dict.fromkeys(e.task for r in ordered for e in r.episodes))
    rows = []
    for task in tasks:
        cells = [short_name(task)]
        for r in ordered:
            agg = r.aggregates.get(task, {}).get("rmse")
            cells.append(_fmt(None if agg is None else agg.mean))
        rows.append(cells)
    return header, rows


SUMMARY_HEADER = ["method", "track", "score", "IQM", "95% CI", "RMSE [m]", "delay [ms]", "energy [mJ]",
                  "jitter", "α var", "detect", "diverged"]


def summary_cells(row: SummaryRow) -> list[str]:
    """Cells of one summary line (see :data:`SUMMARY_HEADER`)."""
    s = row.score
    return [row.method + ("†" if row.privileged else ""), row.track,
            _fmt(s[0]) if s else "—", _fmt(s[1]) if s else "—",
            f"[{_fmt(s[2])}, {_fmt(s[3])}]" if s else "—", _fmt(row.rmse), _fmt(row.delay_ms, 4),
            _fmt(row.energy_mj), _fmt(row.jitter), _fmt(row.weight_var), _fmt(row.detection),
            f"{100 * row.diverged:.0f}%"]


def print_tables(all_results: dict[str, Results], console: Console, suite: Suite) -> None:
    """Print the per-task RMSE table and the per-method summary (privileged apart)."""
    header, rows = rmse_rows(all_results)
    n_seeds = len(suite.seeds(suite.tasks[0]))
    t1 = Table(title=f"mean RMSE [m] per task — suite {suite.name}, {n_seeds} seeds per task "
                     f"(† privileged: reads fault labels, not ranked)", title_style="bold")
    n_public = sum(not r.method.privileged for r in all_results.values())
    for j, name in enumerate(header):
        style = "dim italic" if j > n_public else None
        t1.add_column(name, justify="left" if j == 0 else "right", style=style)
    for cells in rows:
        t1.add_row(*cells)
    console.print(t1)
    t2 = Table(title="summary over all episodes — normalized score: 0 = uniform CEKF, 1 = privileged oracle "
                     "(mean, IQM, stratified bootstrap 95% CI; tasks without labelled faults have none)",
               title_style="bold")
    for j, name in enumerate(SUMMARY_HEADER):
        t2.add_column(name, justify="left" if j < 2 else "right")
    rows2 = [summarize_results(r) for r in _ordered(all_results)]
    public = [r for r in rows2 if not r.privileged]
    public.sort(key=lambda r: -(r.score[0] if r.score else -np.inf))
    for r in public:
        t2.add_row(*summary_cells(r))
    privileged = [r for r in rows2 if r.privileged]
    if privileged:
        t2.add_section()
        for r in privileged:
            t2.add_row(*summary_cells(r), style="dim italic")
    console.print(t2)


def markdown_tables(all_results: dict[str, Results], suite: Suite) -> str:
    """The two tables as Markdown (for ``summary.md`` and the README)."""
    header, rows = rmse_rows(all_results)
    lines = [f"Mean RMSE [m] per task (suite `{suite.name}`, {len(suite.seeds(suite.tasks[0]))} seeds per task; "
             "† privileged, not ranked):", "",
             "| " + " | ".join(header) + " |", "|" + "|".join(["---"] + ["---:"] * (len(header) - 1)) + "|"]
    lines += ["| " + " | ".join(cells) + " |" for cells in rows]
    rows2 = [summarize_results(r) for r in _ordered(all_results)]
    public = sorted([r for r in rows2 if not r.privileged], key=lambda r: -(r.score[0] if r.score else -np.inf))
    lines += ["", "Summary over all episodes (normalized score: 0 = uniform CEKF, 1 = privileged oracle):", "",
              "| " + " | ".join(SUMMARY_HEADER) + " |",
              "|" + "|".join(["---", "---"] + ["---:"] * (len(SUMMARY_HEADER) - 2)) + "|"]
    lines += ["| " + " | ".join(summary_cells(r)) + " |" for r in public]
    lines += ["| " + " | ".join(summary_cells(r)) + " |" for r in rows2 if r.privileged]
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
             console: Console | None = None) -> dict[str, Results]:
    """Evaluate ``methods`` on ``suite``, print the tables, write results, Markdown and plots.

    Args:
        methods: method names or entry points.
        suite: the suite (the demo uses ``quick``).
        out: output folder (created): ``results/``, ``plots/``, ``summary.md``.
        workers: worker processes.
        plots: also write the PNGs.
        console: where to print (default: a new rich console).

    Returns:
        method → its ``Results``.
    """
    console = console or Console()
    started = time.perf_counter()
    methods = loadable_methods(methods, console)
    out.mkdir(parents=True, exist_ok=True)
    (out / "results").mkdir(exist_ok=True)
    console.print(f"[bold]swarmloc demo[/bold]: {len(methods)} methods × {len(suite.tasks)} tasks × "
                  f"{len(suite.seeds(suite.tasks[0]))} seeds (suite {suite.name}), {workers} worker(s)")
    runs = evaluate_methods(methods, suite, workers=workers, trace=plots)
    all_results: dict[str, Results] = {}
    paths = []
    for name, run in runs.items():
        results = run.results(suite)
        path = out / "results" / f"{run.loaded.name}.json"
        write_results(path, results)
        if run.traces:
            write_traces(traces_path(path), run.traces)
        all_results[name] = results
        paths.append(path)
    evaluated = time.perf_counter() - started
    print_tables(all_results, console, suite)
    (out / "summary.md").write_text(markdown_tables(all_results, suite), encoding="utf-8")
    if plots:
        written = plot_results(paths, out / "plots", workers=workers)
        console.print(f"wrote {len(written)} plots to {out / 'plots'}")
    console.print(f"results in {out / 'results'}, tables in {out / 'summary.md'}; evaluation {evaluated:.0f} s, "
                  f"total {time.perf_counter() - started:.0f} s")
    return all_results
