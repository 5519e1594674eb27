"""The static HTML leaderboard site: ``render_html(store, out_dir)``.

Self-contained: vanilla JS and CSS from ``swarmloc.leaderboard/static`` are copied next to
the pages, a Content-Security-Policy forbids anything but the site's own files, and every
submitted string goes through ``html.escape``.
"""

from __future__ import annotations

import html
import json
import shutil
import warnings
from collections.abc import Iterable, Sequence
from datetime import datetime, timezone
from importlib import resources
from pathlib import Path
from urllib.parse import quote

from swarmloc.bench.evaluation.results import METRIC_NAMES
from swarmloc.leaderboard.ranking import (
    SuiteKey,
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

_STATIC_FILES = ("leaderboard.css", "leaderboard.js")
_PLOT_SUFFIXES = (".png", ".svg", ".jpg", ".jpeg", ".webp")
_CSP = (
    "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self'; "
    "base-uri 'none'; form-action 'none'"
)


def _e(value: object) -> str:
    """HTML-escape any value (quotes included, so it is safe in attributes)."""
    return html.escape(str(value), quote=True)


def _page(title: str, body: str, root: str) -> str:
    return (
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
        f"<meta http-equiv=\"Content-Security-Policy\" content=\"{_CSP}\">\n"
        "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n"
        "<meta name=\"referrer\" content=\"no-referrer\">\n"
        f"<title>{_e(title)}</title>\n"
        f"<link rel=\"stylesheet\" href=\"{root}static/leaderboard.css\">\n"
        f"<script src=\"{root}static/leaderboard.js\" defer></script>\n"
        f"</head>\n<body>\n{body}\n</body>\n</html>\n"
    )


def _num_cell(value: float | None, digits: int = 3) -> str:
    data = "" if value is None else repr(float(value))
    return f"<td class=\"num\" data-value=\"{data}\">{_e(fmt(value, digits))}</td>"


def _html_table(entries: Sequence[LeaderboardEntry], tasks: Sequence[str], ranked: bool,
                table_id: str) -> str:
    heads: list[tuple[str, str, str]] = []  # (label, sort type, title)
    if ranked:
        heads.append(("#", "number", "rank by mean normalized score"))
    heads += [
        ("Method", "text", "method name"),
        ("Track", "text", "A: link trust, B: full estimator"),
        ("Score", "number", "mean normalized score over all task × seed runs"),
        ("IQM", "number", "interquartile mean of the normalized score"),
        ("95% CI", "number", "task-stratified bootstrap 95% CI of the mean score"),
    ]
    heads += [(f"RMSE {short_task(t)}", "number", f"mean RMSE [m] on {t}") for t in tasks]
    heads += [
        ("Delay [ms]", "number", "mean computation delay per step"),
        ("Energy [J]", "number", "mean energy per episode"),
        ("Jitter", "number", "mean |Δ trust| per step"),
        ("Status", "text", "verification status"),
    ]
    head_html = "".join(
        f"<th scope=\"col\" data-type=\"{kind}\" title=\"{_e(tip)}\">"
        f"<button type=\"button\">{_e(label)}</button></th>"
        for label, kind, tip in heads
    )
    rows = []
    for rank, entry in enumerate(entries, start=1):
        score = entry.score
        cells = [f"<td class=\"num\" data-value=\"{rank}\">{rank}</td>"] if ranked else []
        cells += [
            f"<td data-value=\"{_e(entry.name.casefold())}\">"
            f"<a href=\"methods/{entry.id}.html\">{_e(entry.name)}</a></td>",
            f"<td data-value=\"{_e(entry.track)}\">{_e(entry.track)}</td>",
            _num_cell(score.mean if score else None),
            _num_cell(score.iqm if score else None),
            f"<td class=\"num\" data-value=\"{'' if score is None else repr(score.ci_low)}\">"
            f"{_e(fmt_ci(entry))}</td>",
            *(_num_cell(task_rmse(entry, t)) for t in tasks),
            _num_cell(entry.delay_ms, 2),
            _num_cell(entry.energy_j, 3),
            _num_cell(entry.jitter, 4),
            f"<td data-value=\"{_e(status(entry))}\">{_e(status(entry))}</td>",
        ]
        rows.append(f"<tr data-method-id=\"{entry.id}\">{''.join(cells)}</tr>")
    return (
        f"<table class=\"sortable\" id=\"{_e(table_id)}\">\n<thead><tr>{head_html}</tr></thead>\n"
        f"<tbody>\n" + "\n".join(rows) + "\n</tbody>\n</table>"
    )


def _slug(*parts: str) -> str:
    text = "-".join(parts)
    return "".join(c if c.isalnum() else "-" for c in text).strip("-").lower() or "suite"


def _index_html(groups: dict[SuiteKey, list[LeaderboardEntry]]) -> str:
    generated = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    parts = [
        "<header><h1>swarmloc leaderboard</h1>",
        f"<p class=\"meta\">Generated {_e(generated)}. Methods are ranked by their mean "
        "normalized score (0 = uniform-trust CEKF, 1 = privileged oracle trust). Click a "
        "column header to sort.</p></header>",
        "<main>",
    ]
    if not groups:
        parts.append("<p class=\"empty\">No submissions yet.</p>")
    for (name, version), entries in groups.items():
        slug = _slug(name, version)
        tasks = suite_tasks(entries)
        ranked, privileged = split_ranked(entries)
        parts.append(f"<section class=\"suite\" id=\"suite-{slug}\">")
        parts.append(f"<h2>Suite {_e(name)} <span class=\"version\">v{_e(version)}</span></h2>")
        if ranked:
            parts.append(_html_table(ranked, tasks, ranked=True, table_id=f"ranked-{slug}"))
        else:
            parts.append("<p class=\"empty\">No ranked methods yet.</p>")
        if privileged:
            parts.append(
                "<h3>Privileged methods</h3><p class=\"meta\">These read ground truth or fault "
                "labels (e.g. the oracle that defines score 1) and are not ranked.</p>"
            )
            parts.append(_html_table(privileged, tasks, ranked=False,
                                     table_id=f"privileged-{slug}"))
        parts.append("</section>")
    parts.append("</main>")
    return _page("swarmloc leaderboard", "\n".join(parts), root="")


def _definition_rows(rows: Iterable[tuple[str, str]]) -> str:
    return "\n".join(f"<tr><th scope=\"row\">{_e(k)}</th><td>{v}</td></tr>" for k, v in rows)


def _make_plots(results_file: Path, plots_dir: Path) -> tuple[list[Path], str | None]:
    """Call ``swarmloc.bench.evaluation.plots.plot_results`` if it exists; (images, error note)."""
    try:
        from swarmloc.bench.evaluation.plots import plot_results  # type: ignore[import-not-found]
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


def _method_html(entry: LeaderboardEntry, images: Sequence[Path], plot_error: str | None) -> str:
    results = json.loads(entry.results_json)
    prov = results.get("provenance", {})
    machine = prov.get("machine", {})
    url = entry.url
    url_html = (
        f"<a href=\"{_e(url)}\" rel=\"nofollow noopener noreferrer\">{_e(url)}</a>"
        if url and url.startswith(("http://", "https://")) else "—"
    )
    score = entry.score
    about = _definition_rows([
        ("Authors", _e(entry.authors or "—")),
        ("URL", url_html),
        ("Track", _e({"A": "A — link trust", "B": "B — full estimator"}.get(entry.track, entry.track))),
        ("Privileged", "yes" if entry.privileged else "no"),
        ("Deterministic", "yes" if entry.deterministic else "no"),
        ("Status", _e(status(entry))),
        ("Entry point", f"<code>{_e(entry.entry_point)}</code>"),
        ("Method hash", f"<code>{_e(entry.method_hash)}</code>"),
        ("Weights SHA-256", f"<code>{_e(entry.weights_sha256 or '—')}</code>"),
        ("Suite", _e(f"{entry.suite_name} v{entry.suite_version} ({entry.suite_sha256[:12]}…)")),
        ("Submitted", _e(entry.created_utc.strftime("%Y-%m-%d %H:%M UTC"))),
        ("Normalized score",
         _e("—" if score is None else
            f"{score.mean:.3f} (IQM {score.iqm:.3f}, 95% CI [{score.ci_low:.3f}, {score.ci_high:.3f}])")),
    ])
    provenance = _definition_rows([
        ("swarmloc version", _e(prov.get("package_version", "—"))),
        ("Git commit", f"<code>{_e(prov.get('git_commit') or '—')}</code>"),
        ("Created", _e(prov.get("created_utc", "—"))),
        ("Python", _e(prov.get("python_version", "—"))),
        ("NumPy", _e(prov.get("numpy_version", "—"))),
        ("PyTorch", _e(prov.get("torch_version") or "—")),
        ("Platform", _e(machine.get("platform", "—"))),
        ("CPUs", _e(machine.get("cpu_count", "—"))),
    ])
    present = {m for per in entry.task_aggregates.values() for m in per}
    metrics = [m for m in METRIC_NAMES if m in present]
    head = "".join(
        f"<th scope=\"col\" data-type=\"number\"><button type=\"button\">{_e(m)}</button></th>"
        for m in metrics
    )
    body_rows = []
    for task in sorted(entry.task_aggregates):
        cells = []
        for m in metrics:
            agg = entry.task_aggregates[task].get(m)
            if agg is None:
                cells.append("<td class=\"num\" data-value=\"\">—</td>")
            else:
                tip = f"IQM {agg.iqm:.4g}, 95% CI [{agg.ci_low:.4g}, {agg.ci_high:.4g}]"
                cells.append(f"<td class=\"num\" data-value=\"{agg.mean!r}\" title=\"{_e(tip)}\">"
                             f"{_e(f'{agg.mean:.4g}')}</td>")
        body_rows.append(f"<tr><th scope=\"row\" data-value=\"{_e(task)}\">{_e(task)}</th>"
                         f"{''.join(cells)}</tr>")
    per_task = (
        "<table class=\"sortable\" id=\"per-task\">\n<thead><tr><th scope=\"col\" data-type=\"text\">"
        f"<button type=\"button\">Task</button></th>{head}</tr></thead>\n<tbody>\n"
        + "\n".join(body_rows) + "\n</tbody>\n</table>"
    )
    plots = ""
    if images:
        figures = "\n".join(
            f"<figure><img src=\"../plots/{entry.id}/{_e(quote(p.name))}\" "
            f"alt=\"{_e(p.stem.replace('_', ' '))}\" loading=\"lazy\"></figure>"
            for p in images
        )
        plots = f"<section><h2>Plots</h2>\n<div class=\"plots\">{figures}</div></section>"
    elif plot_error:
        plots = f"<section><h2>Plots</h2><p class=\"meta\">Plots unavailable: {_e(plot_error)}</p></section>"
    body = "\n".join([
        "<header><p><a href=\"../index.html\">← leaderboard</a></p>",
        f"<h1>{_e(entry.name)}</h1></header><main>",
        f"<p class=\"description\">{_e(entry.description)}</p>" if entry.description else "",
        f"<section><h2>Method</h2><table class=\"facts\">{about}</table></section>",
        f"<section><h2>Provenance</h2><table class=\"facts\">{provenance}</table>",
        f"<p><a href=\"../results/{entry.id}.json\" download>Download the results file</a></p></section>",
        "<section><h2>Per-task results</h2><p class=\"meta\">Mean over seeds; hover for IQM "
        f"and 95% CI.</p>\n{per_task}</section>",
        plots,
        "</main>",
    ])
    return _page(f"{entry.name} — swarmloc leaderboard", body, root="../")


def render_html(store: LeaderboardStore, out_dir: str | Path, suite: str | None = None,
                plots: bool = True) -> Path:
    """Write the static leaderboard site.

    Layout: ``index.html`` (one section per suite: ranked table, privileged table),
    ``methods/<id>.html`` (metadata, provenance, per-task table, plots),
    ``results/<id>.json`` (the submitted results files, for download),
    ``plots/<id>/`` (images from ``swarmloc.bench.evaluation.plots.plot_results`` when available)
    and ``static/`` (CSS and the vanilla-JS table sorter). No external resources.

    Args:
        store: The store to read.
        out_dir: Output directory (created; files it already holds are overwritten).
        suite: Only this suite name (all suites when None).
        plots: Draw each method's plots (re-runs the first seed of every task when the
            results file has no traces beside it: minutes for a full suite).

    Returns:
        Path of ``index.html``.
    """
    out = Path(out_dir)
    for sub in ("static", "methods", "results", "plots"):
        (out / sub).mkdir(parents=True, exist_ok=True)
    package_static = resources.files("swarmloc.leaderboard") / "static"
    for name in _STATIC_FILES:
        (out / "static" / name).write_bytes((package_static / name).read_bytes())
    entries = store.entries(suite)
    for entry in entries:
        results_file = out / "results" / f"{entry.id}.json"
        results_file.write_text(entry.results_json, encoding="utf-8")
        plots_dir = out / "plots" / str(entry.id)
        if plots_dir.exists():
            shutil.rmtree(plots_dir)
        images, error = _make_plots(results_file, plots_dir) if plots else ([], None)
        (out / "methods" / f"{entry.id}.html").write_text(
            _method_html(entry, images, error), encoding="utf-8"
        )
    index = out / "index.html"
    index.write_text(_index_html(by_suite(entries)), encoding="utf-8")
    return index


__all__ = ["render_html"]
