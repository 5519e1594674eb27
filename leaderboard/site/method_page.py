"""A method's page on the leaderboard site: what it is and how it was made, its score (per track on a v2
suite; over its runs when it has several), provenance, per-task results, plots and explanation."""

from __future__ import annotations

import json
import shutil
import warnings
from collections.abc import Iterable, Sequence
from pathlib import Path
from urllib.parse import quote

from swarmloc.bench.evaluation.results import METRIC_NAMES
from swarmloc.bench.scoring.score import SuiteScore
from swarmloc.leaderboard.site.markup import escape, num_cell, page
from swarmloc.leaderboard.site.ranking import (
    PRIVILEGED_TRAINING_MARK,
    Standing,
    fmt_pct,
    fmt_score,
    fmt_times,
    status,
)
from swarmloc.leaderboard.store.database import LeaderboardEntry

_PLOT_SUFFIXES = (".png", ".svg", ".jpg", ".jpeg", ".webp")


def _definition_rows(rows: Iterable[tuple[str, str]]) -> str:
    return "\n".join(f"<tr><th scope=\"row\">{escape(k)}</th><td>{v}</td></tr>" for k, v in rows)


def _make_plots(results_file: Path, plots_dir: Path) -> tuple[list[Path], str | None]:
    """Call ``swarmloc.bench.reports.plots.plot_results`` if it exists; (images, error note)."""
    try:
        from swarmloc.bench.reports.plots import plot_results  # type: ignore[import-not-found]
    except ImportError:
        return [], None
    plots_dir.mkdir(parents=True, exist_ok=True)
    try:
        plot_results(results_file, plots_dir)
    except Exception as err:  # a broken plot must not take the site down
        warnings.warn(f"plot_results failed for {results_file}: {err}", stacklevel=2)
        return [], f"{type(err).__name__}: {err}"
    images = sorted(p for p in plots_dir.iterdir() if p.suffix.lower() in _PLOT_SUFFIXES)
    return images, None


def _score_text(score: SuiteScore | None, n_tasks: int) -> str:
    """A method page's score line: 2^S with its CI, S, IQM, gap closed and coverage."""
    return "—" if score is None else (
        f"{fmt_score(score)}× lower error than uniform (S = {score.S:.3f}; IQM of the gains "
        f"{score.iqm:.3f}; gap closed {fmt_pct(score.gap_closed)}; {len(score.tasks)}/{n_tasks} tasks)")


def _training_text(standing: Standing) -> str:
    """How the method was made, for its page (HTML)."""
    declared = {e.privileged_training for e in standing.entries}
    if declared == {True}:
        return escape(f"{PRIVILEGED_TRAINING_MARK} fitted to privileged labels while training (fault or error labels); "
                  "it runs without them")
    return "not declared (results file older than schema 6)" if None in declared else "no privileged labels"


def _runs_html(standing: Standing) -> str:
    """A standing of several runs: the IQM over runs and each run's S, with its results file (HTML)."""
    total = standing.over_runs
    assert total is not None
    each = ", ".join(f"<a href=\"{e.id}.html\">run {escape(e.run)}</a>: 2^S {fmt_times(2.0 ** s)} "
                     f"(<a href=\"../results/{e.id}.json\" download>results</a>)"
                     for e, s in zip(standing.entries, total.runs))
    return (f"{total.n_runs} training runs, shown as one: 2^S of the interquartile mean over runs "
            f"{fmt_times(2.0 ** total.S)} [{fmt_times(2.0 ** total.ci_low)}, {fmt_times(2.0 ** total.ci_high)}] "
            f"(95% CI over runs, families and seeds). {each}. This page is run {escape(standing.entry.run)}'s: per "
            "task, × uniform and gap closed are the run-mean's, the metrics that run's.")


def _method_html(standing: Standing, n_tasks: int, images: Sequence[Path], plot_error: str | None,
                 explanation: str = "", tracks: Sequence[tuple[str, Standing, int]] = ()) -> str:
    """A method's page; ``tracks``: on a v2 suite, (track, its standing on the track's board, the track's task
    count) for each track (one score line each)."""
    entry, score = standing.entry, standing.score
    results = json.loads(entry.results_json)
    prov = results.get("provenance", {})
    machine = prov.get("machine", {})
    url = entry.url
    url_html = (
        f"<a href=\"{escape(url)}\" rel=\"nofollow noopener noreferrer\">{escape(url)}</a>"
        if url and url.startswith(("http://", "https://")) else "—"
    )
    about = _definition_rows([
        ("Authors", escape(entry.authors or "—")),
        ("URL", url_html),
        ("Track", escape({"A": "A — link trust", "B": "B — full estimator"}.get(entry.track, entry.track))),
        ("Privileged", "yes" if entry.privileged else "no"),
        ("Training", _training_text(standing)),
        *([("Runs", _runs_html(standing))] if standing.over_runs is not None else []),
        ("Deterministic", "yes" if entry.deterministic else "no"),
        ("Status", escape(status(entry))),
        ("Entry point", f"<code>{escape(entry.entry_point)}</code>"),
        ("Method hash", f"<code>{escape(entry.method_hash)}</code>"),
        ("Weights SHA-256", f"<code>{escape(entry.weights_sha256 or '—')}</code>"),
        ("Suite", escape(f"{entry.suite_name} v{entry.suite_version} ({entry.suite_sha256[:12]}…)")),
        ("Submitted", escape(entry.created_utc.strftime("%Y-%m-%d %H:%M UTC"))),
        # a v2 suite: one score per track, never one that mixes them
        *([(f"Score, {track} track", escape(_score_text(on.score, n))) for track, on, n in tracks]
          if tracks else [("Score", escape(_score_text(score, n_tasks)))]),
    ])
    provenance = _definition_rows([
        ("swarmloc version", escape(prov.get("package_version", "—"))),
        ("Git commit", f"<code>{escape(prov.get('git_commit') or '—')}</code>"),
        ("Created", escape(prov.get("created_utc", "—"))),
        ("Python", escape(prov.get("python_version", "—"))),
        ("NumPy", escape(prov.get("numpy_version", "—"))),
        ("PyTorch", escape(prov.get("torch_version") or "—")),
        ("Platform", escape(machine.get("platform", "—"))),
        ("CPUs", escape(machine.get("cpu_count", "—"))),
    ])
    present = {m for per in entry.task_aggregates.values() for m in per}
    metrics = [m for m in METRIC_NAMES if m in present]
    head = "".join(
        f"<th scope=\"col\" data-type=\"number\"><button type=\"button\">{escape(m)}</button></th>"
        for m in ("× uniform", "gap closed", *metrics)
    )
    body_rows = []
    for task in sorted(entry.task_aggregates):
        t = score.tasks.get(task) if score else None
        cells = [
            num_cell(None if t is None else 2.0**t.mean, "—" if t is None else fmt_times(2.0**t.mean),
                     None if t is None else f"G_t = {t.mean:.3f} (mean log2 gain over {t.gains.size} seeds)"),
            num_cell(None if t is None else t.gap_closed, fmt_pct(None if t is None else t.gap_closed)),
        ]
        for m in metrics:
            agg = entry.task_aggregates[task].get(m)
            if agg is None:
                cells.append("<td class=\"num\" data-value=\"\">—</td>")
            else:
                tip = f"IQM {agg.iqm:.4g}, 95% CI [{agg.ci_low:.4g}, {agg.ci_high:.4g}]"
                cells.append(f"<td class=\"num\" data-value=\"{agg.mean!r}\" title=\"{escape(tip)}\">"
                             f"{escape(f'{agg.mean:.4g}')}</td>")
        body_rows.append(f"<tr><th scope=\"row\" data-value=\"{escape(task)}\">{escape(task)}</th>"
                         f"{''.join(cells)}</tr>")
    per_task = (
        "<table class=\"sortable\" id=\"per-task\">\n<thead><tr><th scope=\"col\" data-type=\"text\">"
        f"<button type=\"button\">Task</button></th>{head}</tr></thead>\n<tbody>\n"
        + "\n".join(body_rows) + "\n</tbody>\n</table>"
    )
    plots = ""
    if images:
        figures = "\n".join(
            f"<figure><img src=\"../plots/{entry.id}/{escape(quote(p.name))}\" "
            f"alt=\"{escape(p.stem.replace('_', ' '))}\" loading=\"lazy\"></figure>"
            for p in images
        )
        plots = f"<section><h2>Plots</h2>\n<div class=\"plots\">{figures}</div></section>"
    elif plot_error:
        plots = f"<section><h2>Plots</h2><p class=\"meta\">Plots unavailable: {escape(plot_error)}</p></section>"
    body = "\n".join([
        "<header><p><a href=\"../index.html\">← leaderboard</a></p>",
        f"<h1>{escape(entry.name)}</h1></header><main>",
        f"<p class=\"description\">{escape(entry.description)}</p>" if entry.description else "",
        f"<section><h2>Method</h2><table class=\"facts\">{about}</table></section>",
        f"<section><h2>Provenance</h2><table class=\"facts\">{provenance}</table>",
        f"<p><a href=\"../results/{entry.id}.json\" download>Download the results file</a></p></section>",
        "<section><h2>Per-task results</h2><p class=\"meta\">× uniform: 2^G_t, G_t the mean over seeds of "
        "log2(RMSE_uniform / RMSE); metrics: mean over seeds, hover for IQM and 95% CI.</p>\n"
        f"{per_task}</section>",
        plots,
        explanation,
        "</main>",
    ])
    return page(f"{entry.name} — swarmloc leaderboard", body, root="../")


def write_method(out: Path, standing: Standing, n_tasks: int, plots: bool, explain: bool = False,
                 tracks: Sequence[tuple[str, Standing, int]] = ()) -> None:
    """A method's page, results file, (when ``plots``) its plots and (when ``explain``) its explanation.

    A standing of several runs has one page per run (``standing.entry`` the run shown; the render calls this
    once per run), each with the standing's score and links to the others."""
    entry = standing.entry
    results_file = out / "results" / f"{entry.id}.json"
    results_file.write_text(entry.results_json, encoding="utf-8")
    plots_dir = out / "plots" / str(entry.id)
    if plots_dir.exists():
        shutil.rmtree(plots_dir)
    images, error = _make_plots(results_file, plots_dir) if plots else ([], None)
    (out / "methods" / f"{entry.id}.html").write_text(
        _method_html(standing, n_tasks, images, error, _make_explanation(entry, out) if explain else "", tracks),
        encoding="utf-8",
    )


def _make_explanation(entry: LeaderboardEntry, out: Path) -> str:
    """The page's explanation section for a shipped Track A method ("" for any other entry)."""
    from swarmloc.leaderboard.site import explain as site_explain
    if not site_explain.explainable(entry):
        return ""
    try:
        return site_explain.explanation_section(site_explain.write_explanation(entry, out), None)
    except Exception as err:  # noqa: BLE001 - a failed explanation must not take the site down
        warnings.warn(f"explanation of {entry.name} failed: {err}", stacklevel=2)
        return site_explain.explanation_section(None, f"{type(err).__name__}: {err}")


__all__ = ["write_method"]
