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
from typing import TYPE_CHECKING
from urllib.parse import quote

from swarmloc.bench.evaluation.results import METRIC_NAMES
from swarmloc.bench.scoring.families import group_by_family
from swarmloc.bench.scoring.score import SuiteScore, score_version
from swarmloc.leaderboard.site.compute import DELAY_BUDGET_MS, compute_rows, place
from swarmloc.leaderboard.site.ranking import (
    PRIVILEGED_TRAINING_MARK,
    PRIVILEGED_TRAINING_NOTE,
    Column,
    Standing,
    SuiteBoard,
    best_ranked_on,
    by_suite,
    column_score,
    family_columns,
    fmt,
    fmt_pct,
    fmt_score,
    fmt_times,
    privileged_training,
    runs_note,
    status,
    suite_board,
    track_boards,
)
from swarmloc.leaderboard.store.database import LeaderboardEntry, LeaderboardStore

if TYPE_CHECKING:
    from swarmloc.leaderboard.site.plots import SitePlot
    from swarmloc.leaderboard.site.track_plots import TrackSection

_STATIC_FILES = ("leaderboard.css", "leaderboard.js")
#: the track whose tables carry the cooperation gain (each UAV alone is the other track's setting)
COOPERATIVE_TRACK = "cooperative"
_COOPERATION_TIP = ("cooperation gain: × lower error than each UAV localizing alone (non-cooperative), score v2, "
                    "hierarchical-bootstrap 95% CI")
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


def _num_cell(value: float | None, text: str, title: str | None = None) -> str:
    data = "" if value is None else repr(float(value))
    tip = "" if title is None else f" title=\"{_e(title)}\""
    return f"<td class=\"num\" data-value=\"{data}\"{tip}>{_e(text)}</td>"


def _column_cell(standing: Standing, column: Column) -> str:
    """A family (or task) cell: 2^G over its covered tasks; the worst task on hover."""
    cs = column_score(standing.score, column)
    if cs is None:
        return _num_cell(None, "—", f"{column.title}: not covered")
    tip = f"worst task: {cs.worst_task} ({fmt_times(cs.worst_times)}× uniform)"
    if cs.covered < cs.total:
        tip += f"; {cs.covered} of {cs.total} tasks covered"
    return _num_cell(cs.times, fmt_times(cs.times) + ("" if cs.covered == cs.total else "*"), tip)


def _score_tip(board: SuiteBoard, standing: Standing) -> str | None:
    """Hover text of a 2^S cell; for partial coverage, how the best ranked method does on the same tasks."""
    score = standing.score
    if score is None:
        return "no score: no uniform_rmse in the results and no stored uniform entry for this suite"
    tip = f"S = {score.S:.3f}, IQM of the gains {score.iqm:.3f}"
    if standing.full or standing.entry.privileged:
        return tip
    best = best_ranked_on(board, score.tasks)
    tip += f"; over its {len(score.tasks)} of {len(board.tasks)} tasks only"
    if best is not None:
        tip += f"; on those tasks the best ranked method, {best[0].entry.name}, has 2^S = {fmt_times(2.0 ** best[1])}"
    return tip


def _cooperation_cell(score: SuiteScore | None) -> str:
    """The cooperation gain ``2^C [low, high]`` of a v2 standing (a dash without a non-cooperative entry)."""
    gain = None if score is None else score.cooperation
    if gain is None:
        return _num_cell(None, "—", "no cooperation gain: the suite has no stored non-cooperative entry")
    low, high = 2.0**gain.ci_low, 2.0**gain.ci_high
    return _num_cell(2.0**gain.S, f"{fmt_times(2.0 ** gain.S)} [{fmt_times(low)}, {fmt_times(high)}]",
                     f"C = {gain.S:.3f}: × lower error than each UAV localizing alone (non-cooperative), "
                     "hierarchical-bootstrap 95% CI")


def _made_marks(standing: Standing) -> str:
    """After a method's name: ‡ when fitted to privileged labels while training, and its runs when several."""
    marks = ""
    if privileged_training(standing):
        marks += f" <span class=\"mark\" title=\"{_e(PRIVILEGED_TRAINING_NOTE)}\">{PRIVILEGED_TRAINING_MARK}</span>"
    if standing.over_runs is not None:
        each = ", ".join(f"run {e.run}: 2^S {fmt_times(2.0 ** s)}" for e, s in zip(standing.entries,
                                                                                standing.over_runs.runs))
        marks += (f" <span class=\"runs\" title=\"{_e(f'interquartile mean over {standing.n_runs} training runs ({each})')}"
                  f"\">({standing.n_runs} runs)</span>")
    return marks


def _made_notes(board: SuiteBoard) -> str:
    """The notes under a board's tables on ‡ and on standings of several runs ('' where it has neither)."""
    notes = [PRIVILEGED_TRAINING_NOTE] if any(privileged_training(s) for s in board.standings) else []
    notes += [runs_note(board)] if runs_note(board) else []
    return "".join(f"<p class=\"meta\">{_e(note)}</p>" for note in notes)


def _compute_html(board: SuiteBoard, table_id: str) -> str:
    """The compute view of a board (:mod:`swarmloc.leaderboard.site.compute`), in the accuracy tables' order."""
    heads = [("#", "number", "the accuracy tables' rank (p: partial coverage; —: privileged)"),
             ("Method", "text", "method name"),
             ("2^S", "number", "× lower error than uniform (the accuracy ranking)"),
             ("Delay per update [ms]", "number", "compute time per UAV-step, filter + method FLOPs on the processor "
                                                 "profile (delay_ms), mean over the tasks"),
             ("Worst task [ms]", "number", "the task of the highest mean delay"),
             (f"Over {DELAY_BUDGET_MS:g} ms", "number", f"tasks whose mean delay exceeds the {DELAY_BUDGET_MS:g} ms "
                                                        "budget (the standard reward's T_max, madrl), of those measured"),
             ("FLOPs per channel", "number", "declared by the method, per present channel and step")]
    head_html = "".join(f"<th scope=\"col\" data-type=\"{kind}\" title=\"{_e(tip)}\"><button type=\"button\">"
                        f"{_e(label)}</button></th>" for label, kind, tip in heads)
    rows = []
    for i, (standing, cost) in enumerate(compute_rows(board)):
        entry, score = standing.entry, standing.score
        worst = cost.worst_task
        cells = [
            _num_cell(i, place(board, standing)),  # sorts back to the accuracy order
            f"<td data-value=\"{_e(entry.name.casefold())}\"><a href=\"methods/{entry.id}.html\">{_e(entry.name)}</a>"
            f"{_made_marks(standing)}</td>",
            _num_cell(score.times if score else None, fmt_times(score.times if score else None)),
            _num_cell(cost.delay_ms, "not measured" if cost.delay_ms is None else fmt(cost.delay_ms, 2)),
            _num_cell(None if worst is None else worst[1], "—" if worst is None else fmt(worst[1], 2),
                      None if worst is None else worst[0]),
            _num_cell(cost.over_budget if cost.measured else None,
                      "—" if not cost.measured else f"{cost.over_budget}/{cost.measured}"),
            _num_cell(cost.flops_per_channel,
                      "—" if cost.flops_per_channel is None else f"{cost.flops_per_channel:,.0f}"),
        ]
        rows.append(f"<tr data-method-id=\"{entry.id}\">{''.join(cells)}</tr>")
    return (f"<table class=\"sortable\" id=\"{_e(table_id)}\">\n<thead><tr>{head_html}</tr></thead>\n<tbody>\n"
            + "\n".join(rows) + "\n</tbody>\n</table>")


def _html_table(board: SuiteBoard, standings: Sequence[Standing], columns: Sequence[Column], ranked: bool,
                table_id: str, cooperation: bool = False) -> str:
    n = len(board.tasks)
    v2 = score_version(board.name) >= 2
    heads: list[tuple[str, str, str]] = []  # (label, sort type, title)
    if ranked:
        heads.append(("#", "number", "rank by the score (S). In the ranked table: 1 + the methods ahead beyond doubt "
                                     "(paired 95% CI of the difference in S above 0); a shared # is a tie the seeds "
                                     "cannot break"))
    heads += [
        ("Method", "text", "method name"),
        ("Track", "text", "A: link trust, B: full estimator"),
        ("2^S", "number", "× lower error than the standard CEKF (uniform): geometric mean over "
                          + ("families of the track's tasks (score v2)" if v2 else "tasks")),
        ("95% CI", "number", "hierarchical-bootstrap 95% CI of 2^S (families, then seeds within their tasks)" if v2
         else "stratified-bootstrap 95% CI of 2^S (seeds resampled within tasks)"),
        ("Gap closed", "number", "share of the achievable gain (uniform to the information bound) closed, "
                                 "mean over tasks where it is defined"),
        ("Tasks", "number", "tasks covered / tasks in the " + ("track" if v2 else "suite")),
    ]
    if cooperation:  # after the CI, before "Gap closed" and "Tasks"
        heads.insert(len(heads) - 2, ("2^C [95% CI]", "number", _COOPERATION_TIP))
    heads += [(c.header, "number", f"× uniform over {c.title}; hover a cell for its worst task") for c in columns]
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
    for standing in standings:
        entry, score = standing.entry, standing.score
        k, _ = standing.coverage(n)
        shown = standing.separable_rank if standing.separable_rank is not None else standing.rank
        cells = [f"<td class=\"num\" data-value=\"{standing.rank}\">{shown}</td>"] if ranked else []
        low_high = score.times_ci if score else None
        cells += [
            f"<td data-value=\"{_e(entry.name.casefold())}\">"
            f"<a href=\"methods/{entry.id}.html\">{_e(entry.name)}</a>{_made_marks(standing)}</td>",
            f"<td data-value=\"{_e(entry.track)}\">{_e(entry.track)}</td>",
            _num_cell(score.times if score else None, fmt_times(score.times) if score else "—",
                      _score_tip(board, standing)),
            _num_cell(low_high[0] if low_high else None,
                      "—" if low_high is None else f"[{fmt_times(low_high[0])}, {fmt_times(low_high[1])}]"),
            *([_cooperation_cell(score)] if cooperation else []),
            _num_cell(score.gap_closed if score else None, fmt_pct(score.gap_closed if score else None)),
            _num_cell(k, f"{k}/{n}"),
            *(_column_cell(standing, c) for c in columns),
            _num_cell(entry.delay_ms, fmt(entry.delay_ms, 2)),
            _num_cell(entry.energy_j, fmt(entry.energy_j, 3)),
            _num_cell(entry.jitter, fmt(entry.jitter, 4)),
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


def _figure_list(plots: Sequence[SitePlot], root: Path) -> str:
    figures = "\n".join(
        f"<figure><img src=\"{_e(quote(p.path.relative_to(root).as_posix()))}\" alt=\"{_e(p.alt)}\">"
        f"<figcaption>{_e(p.caption)}</figcaption></figure>"
        for p in plots
    )
    return f"<div class=\"plots suite-plots\">{figures}</div>"


def _figures(plots: Sequence[SitePlot], root: Path) -> str:
    if not plots:
        return ""
    return f"<h3>Plots</h3>\n{_figure_list(plots, root)}"


def _board_tables(board: SuiteBoard, columns: Sequence[Column], slug: str, what: str = "suite",
                  heading: str = "h3", cooperation: bool = False) -> list[str]:
    """A board's ranked, partial-coverage and privileged tables (a suite's, or one track's of a v2 suite)."""
    parts = []
    if board.ranked:
        parts.append(_html_table(board, board.ranked, columns, ranked=True, table_id=f"ranked-{slug}",
                                 cooperation=cooperation))
    else:
        parts.append("<p class=\"empty\">No ranked methods yet.</p>")
    if board.partial:
        parts.append(
            f"<{heading}>Partial coverage</{heading}><p class=\"meta\">These methods cannot run some tasks of the "
            f"{what}. They are ranked apart, by 2^S over the tasks they cover (so compared with uniform "
            "only on those tasks); * marks a family they cover in part.</p>"
        )
        parts.append(_html_table(board, board.partial, columns, ranked=True, table_id=f"partial-{slug}",
                                 cooperation=cooperation))
    if board.privileged:
        parts.append(
            f"<{heading}>Privileged methods</{heading}><p class=\"meta\">These read ground truth or fault "
            "labels (e.g. the oracle) and are not ranked.</p>"
        )
        parts.append(_html_table(board, board.privileged, columns, ranked=False,
                                 table_id=f"privileged-{slug}", cooperation=cooperation))
    parts.append(_made_notes(board))
    if board.standings:
        parts.append(f"<{heading}>Compute</{heading}><p class=\"meta\">Beside the accuracy ranking, in its order: "
                     f"each method's delay per update against the {DELAY_BUDGET_MS:g} ms budget and the FLOPs it "
                     "declares per channel. Not measured: the method reports no FLOPs.</p>")
        parts.append(_compute_html(board, f"compute-{slug}"))
    return parts


def _track_sections(slug: str, sections: Sequence[TrackSection], root: Path) -> str:
    """A v2 suite's per-track parts: each track's task families, its tables (its own S, CI, ranks and, on the
    cooperative track, the cooperation gain) and its figures."""
    parts = [
        "<p class=\"meta\">Benchmark v2 scores each track apart and never mixes them (score v2: mean over "
        "seeds, then over a family's tasks, then over families; hierarchical-bootstrap CIs, families then "
        "seeds): each track below has its own tables, ranks and figures, on its own tasks.</p>"
    ]
    for section in sections:
        families = group_by_family(section.board.tasks)
        listed = ", ".join(f"{family} ({len(tasks)})" for family, tasks in families.items())
        track_slug = _slug(section.track)
        parts.append(f"<section class=\"track\" id=\"track-{_e(slug)}-{_e(track_slug)}\">")
        parts.append(f"<h3>{_e(section.title)}</h3>")
        parts.append(f"<p class=\"meta\">{len(section.board.tasks)} tasks in {len(families)} families: "
                     f"{_e(listed)}.</p>")
        parts += _board_tables(section.board, family_columns(section.board.tasks), f"{slug}-{track_slug}",
                               what="track", heading="h4", cooperation=section.track == COOPERATIVE_TRACK)
        if section.plots:
            parts.append(_figure_list(section.plots, root))
        else:
            parts.append("<p class=\"empty\">No method has a score on this track yet.</p>")
        parts.append("</section>")
    return "\n".join(parts)


def _index_html(boards: Sequence[SuiteBoard], plots: dict[str, list[SitePlot]], root: Path,
                tracks: dict[str, list[TrackSection]] | None = None) -> str:
    generated = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    parts = [
        "<header><h1>swarmloc leaderboard</h1>",
        f"<p class=\"meta\">Generated {_e(generated)}. Methods are ranked by 2^S, how many "
        "times lower the position error is than the standard CEKF's (uniform trust), the geometric mean "
        "over the suite's tasks, with a stratified-bootstrap 95% CI. Family columns give × uniform over "
        "the family's tasks (hover for the worst task). Click a column header to sort.</p></header>",
        "<main>",
    ]
    if not boards:
        parts.append("<p class=\"empty\">No submissions yet.</p>")
    for board in boards:
        slug = _slug(board.name, board.version)
        parts.append(f"<section class=\"suite\" id=\"suite-{slug}\">")
        parts.append(f"<h2>Suite {_e(board.name)} <span class=\"version\">v{_e(board.version)}</span></h2>")
        if not (tracks and tracks.get(slug)):  # a v2 suite's tables are its tracks'
            parts += _board_tables(board, family_columns(board.tasks), slug)
        if board.filled:
            ref = board.reference
            parts.append(
                f"<p class=\"meta\">The uniform RMSE of {board.filled} episode(s) (results files older "
                "than results schema 2) is taken from the stored uniform entry"
                + ("" if ref is None else f" (<a href=\"methods/{ref.id}.html\">#{ref.id}</a>)")
                + " on the same task and seed.</p>"
            )
        if tracks and tracks.get(slug):
            parts.append(_track_sections(slug, tracks[slug], root))
        else:
            parts.append(_figures(plots.get(slug, []), root))
        parts.append("</section>")
    parts.append("</main>")
    return _page("swarmloc leaderboard", "\n".join(parts), root="")


def _definition_rows(rows: Iterable[tuple[str, str]]) -> str:
    return "\n".join(f"<tr><th scope=\"row\">{_e(k)}</th><td>{v}</td></tr>" for k, v in rows)


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
        return _e(f"{PRIVILEGED_TRAINING_MARK} fitted to privileged labels while training (fault or error labels); "
                  "it runs without them")
    return "not declared (results file older than schema 6)" if None in declared else "no privileged labels"


def _runs_html(standing: Standing) -> str:
    """A standing of several runs: the IQM over runs and each run's S, with its results file (HTML)."""
    total = standing.over_runs
    assert total is not None
    each = ", ".join(f"run {_e(e.run)}: 2^S {fmt_times(2.0 ** s)} (<a href=\"../results/{e.id}.json\" download>"
                     f"results</a>)" for e, s in zip(standing.entries, total.runs))
    return (f"{total.n_runs} training runs, shown as one: 2^S of the interquartile mean over runs "
            f"{fmt_times(2.0 ** total.S)} [{fmt_times(2.0 ** total.ci_low)}, {fmt_times(2.0 ** total.ci_high)}] "
            f"(95% CI over runs, families and seeds). {each}. This page shows run {_e(standing.entry.run)}, the run "
            "nearest the IQM; its per-task table is that run's.")


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
        f"<a href=\"{_e(url)}\" rel=\"nofollow noopener noreferrer\">{_e(url)}</a>"
        if url and url.startswith(("http://", "https://")) else "—"
    )
    about = _definition_rows([
        ("Authors", _e(entry.authors or "—")),
        ("URL", url_html),
        ("Track", _e({"A": "A — link trust", "B": "B — full estimator"}.get(entry.track, entry.track))),
        ("Privileged", "yes" if entry.privileged else "no"),
        ("Training", _training_text(standing)),
        *([("Runs", _runs_html(standing))] if standing.over_runs is not None else []),
        ("Deterministic", "yes" if entry.deterministic else "no"),
        ("Status", _e(status(entry))),
        ("Entry point", f"<code>{_e(entry.entry_point)}</code>"),
        ("Method hash", f"<code>{_e(entry.method_hash)}</code>"),
        ("Weights SHA-256", f"<code>{_e(entry.weights_sha256 or '—')}</code>"),
        ("Suite", _e(f"{entry.suite_name} v{entry.suite_version} ({entry.suite_sha256[:12]}…)")),
        ("Submitted", _e(entry.created_utc.strftime("%Y-%m-%d %H:%M UTC"))),
        # a v2 suite: one score per track, never one that mixes them
        *([(f"Score, {track} track", _e(_score_text(on.score, n))) for track, on, n in tracks]
          if tracks else [("Score", _e(_score_text(score, n_tasks)))]),
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
        for m in ("× uniform", "gap closed", *metrics)
    )
    body_rows = []
    for task in sorted(entry.task_aggregates):
        t = score.tasks.get(task) if score else None
        cells = [
            _num_cell(None if t is None else 2.0**t.mean, "—" if t is None else fmt_times(2.0**t.mean),
                      None if t is None else f"G_t = {t.mean:.3f} (mean log2 gain over {t.gains.size} seeds)"),
            _num_cell(None if t is None else t.gap_closed, fmt_pct(None if t is None else t.gap_closed)),
        ]
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
        "<section><h2>Per-task results</h2><p class=\"meta\">× uniform: 2^G_t, G_t the mean over seeds of "
        "log2(RMSE_uniform / RMSE); metrics: mean over seeds, hover for IQM and 95% CI.</p>\n"
        f"{per_task}</section>",
        plots,
        explanation,
        "</main>",
    ])
    return _page(f"{entry.name} — swarmloc leaderboard", body, root="../")


def render_html(store: LeaderboardStore, out_dir: str | Path, suite: str | None = None,
                plots: bool = True, explanations: bool | None = None) -> Path:
    """Write the static leaderboard site.

    Layout: ``index.html`` (one section per suite: ranked, partial-coverage and privileged
    tables, then the suite's plots from :mod:`swarmloc.leaderboard.site.plots`),
    ``methods/<id>.html`` (metadata, provenance, per-task table, plots),
    ``results/<id>.json`` (the submitted results files, for download),
    ``plots/<id>/`` (images from ``swarmloc.bench.reports.plots.plot_results`` when available),
    ``plots/suite-<suite>-<version>/`` (the suite plots, always drawn; for a benchmark v2 suite one
    folder per track instead, ``<track>/``, with rliable's plots and a family heat map:
    :mod:`swarmloc.leaderboard.site.track_plots`),
    ``explain/<id>/`` (a shipped Track A method's trust decisions on the step-NLOS task:
    :mod:`swarmloc.leaderboard.site.explain`)
    and ``static/`` (CSS and the vanilla-JS table sorter). No external resources.

    Args:
        store: The store to read.
        out_dir: Output directory (created; files it already holds are overwritten).
        suite: Only this suite name (all suites when None).
        plots: Draw each method's plots (re-runs the first seed of every task when the
            results file has no traces beside it: minutes for a full suite).
        explanations: Explain each shipped Track A method on the step-NLOS task (one 50 s
            episode each, seconds to a minute per method); default: as ``plots``.

    Returns:
        Path of ``index.html``.
    """
    out = Path(out_dir)
    for sub in ("static", "methods", "results", "plots"):
        (out / sub).mkdir(parents=True, exist_ok=True)
    package_static = resources.files("swarmloc.leaderboard.site") / "static"
    for name in _STATIC_FILES:
        (out / "static" / name).write_bytes((package_static / name).read_bytes())
    groups = by_suite(store.entries(suite))
    boards = [suite_board(name, version, group) for (name, version), group in groups.items()]
    explain = plots if explanations is None else explanations
    per_track_of = {(b.name, b.version): track_boards(b, groups[(b.name, b.version)]) for b in boards}
    for board in boards:
        per_track = per_track_of[(board.name, board.version)]
        for standing in board.standings:
            on_tracks = [(track, on, len(tb.tasks)) for track, tb in per_track.items()
                         for on in tb.standings if on.entry is standing.entry]
            _write_method(out, standing, len(board.tasks), plots, explain, on_tracks)
    suite_figures, track_figures = {}, {}
    for board in boards:
        slug = _slug(board.name, board.version)
        per_track = per_track_of[(board.name, board.version)]
        if per_track:  # a v2 suite: one part per track, never a plot that mixes tracks
            track_figures[slug] = _draw_track_plots(per_track, out / "plots" / f"suite-{slug}")
        else:
            suite_figures[slug] = _draw_suite_plots(board, out / "plots" / f"suite-{slug}")
    index = out / "index.html"
    index.write_text(_index_html(boards, suite_figures, out, track_figures), encoding="utf-8")
    return index


def _draw_suite_plots(board: SuiteBoard, plots_dir: Path) -> list[SitePlot]:
    """The suite's plots (none, with a warning, if drawing fails: the tables still render)."""
    from swarmloc.leaderboard.site.plots import suite_plots

    if plots_dir.exists():
        shutil.rmtree(plots_dir)
    try:
        return suite_plots(board, plots_dir)
    except Exception as err:  # a broken plot must not take the site down
        warnings.warn(f"suite plots of {board.name} v{board.version} failed: {err}", stacklevel=2)
        return []


def _draw_track_plots(boards: dict[str, SuiteBoard], plots_dir: Path) -> list[TrackSection]:
    """A v2 suite's per-track figures, ``plots_dir/<track>/`` (a track whose drawing fails, with a warning,
    keeps its section without figures)."""
    from swarmloc.leaderboard.site.track_plots import TrackSection, track_plots

    if plots_dir.exists():
        shutil.rmtree(plots_dir)
    sections = []
    for track, board in boards.items():
        try:
            sections.append(track_plots(board, track, plots_dir / track))
        except Exception as err:  # noqa: BLE001 - a broken plot must not take the site down
            warnings.warn(f"plots of {board.name} v{board.version}, track {track}, failed: {err}", stacklevel=2)
            sections.append(TrackSection(track, board, ()))
    return sections


def _write_method(out: Path, standing: Standing, n_tasks: int, plots: bool, explain: bool = False,
                  tracks: Sequence[tuple[str, Standing, int]] = ()) -> None:
    """A method's page, results file, (when ``plots``) its plots and (when ``explain``) its explanation."""
    entry = standing.entry
    for run in standing.entries:  # every run's results file, for download
        (out / "results" / f"{run.id}.json").write_text(run.results_json, encoding="utf-8")
    results_file = out / "results" / f"{entry.id}.json"
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


__all__ = ["render_html"]
