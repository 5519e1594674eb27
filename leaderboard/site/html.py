"""The static HTML leaderboard site: ``render_html(store, out_dir)``.

Self-contained: vanilla JS and CSS from ``swarmloc.leaderboard/static`` are copied next to
the pages, a Content-Security-Policy forbids anything but the site's own files, and every
submitted string goes through ``html.escape``.
"""

from __future__ import annotations

import shutil
import warnings
from collections.abc import Sequence
from dataclasses import replace
from datetime import datetime, timezone
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING
from urllib.parse import quote

from swarmloc.bench.scoring.families import group_by_family
from swarmloc.bench.scoring.score import SuiteScore, score_version
from swarmloc.leaderboard.site.compute import DELAY_BUDGET_MS, compute_rows, place
from swarmloc.leaderboard.site.markup import escape, made_marks, num_cell, page
from swarmloc.leaderboard.site.method_page import write_method
from swarmloc.leaderboard.site.ranking import (
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
    fmt_times,
    privileged_training,
    runs_note,
    status,
    suite_board,
    track_boards,
)
from swarmloc.leaderboard.store.database import LeaderboardStore

if TYPE_CHECKING:
    from swarmloc.leaderboard.site.plots import SitePlot
    from swarmloc.leaderboard.site.track_plots import TrackSection

_STATIC_FILES = ("leaderboard.css", "leaderboard.js")
#: the track whose tables carry the cooperation gain (each UAV alone is the other track's setting)
COOPERATIVE_TRACK = "cooperative"
_COOPERATION_TIP = ("cooperation gain: × lower error than each UAV localizing alone (non-cooperative), score v2, "
                    "hierarchical-bootstrap 95% CI")
def _column_cell(standing: Standing, column: Column) -> str:
    """A family (or task) cell: 2^G over its covered tasks; the worst task on hover."""
    cs = column_score(standing.score, column)
    if cs is None:
        return num_cell(None, "—", f"{column.title}: not covered")
    tip = f"worst task: {cs.worst_task} ({fmt_times(cs.worst_times)}× uniform)"
    if cs.covered < cs.total:
        tip += f"; {cs.covered} of {cs.total} tasks covered"
    return num_cell(cs.times, fmt_times(cs.times) + ("" if cs.covered == cs.total else "*"), tip)


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
        return num_cell(None, "—", "no cooperation gain: the suite has no stored non-cooperative entry")
    low, high = 2.0**gain.ci_low, 2.0**gain.ci_high
    return num_cell(2.0**gain.S, f"{fmt_times(2.0 ** gain.S)} [{fmt_times(low)}, {fmt_times(high)}]",
                    f"C = {gain.S:.3f}: × lower error than each UAV localizing alone (non-cooperative), "
                    "hierarchical-bootstrap 95% CI")


def _made_notes(board: SuiteBoard) -> str:
    """The notes under a board's tables on ‡ and on standings of several runs ('' where it has neither)."""
    notes = [PRIVILEGED_TRAINING_NOTE] if any(privileged_training(s) for s in board.standings) else []
    notes += [runs_note(board)] if runs_note(board) else []
    return "".join(f"<p class=\"meta\">{escape(note)}</p>" for note in notes)


def _compute_html(board: SuiteBoard, table_id: str) -> str:
    """The compute view of a board (:mod:`swarmloc.leaderboard.site.compute`), in the accuracy tables' order."""
    heads = [("#", "number", "the accuracy tables' rank (p: partial coverage; —: privileged)"),
             ("Method", "text", "method name"),
             ("2^S", "number", "× lower error than uniform (the accuracy ranking)"),
             ("Delay per update [ms]", "number", ("compute time per UAV-step, filter + method FLOPs on the processor "
                                                  "profile (delay_ms), mean over the tasks")),
             ("Worst task [ms]", "number", "the task of the highest mean delay"),
             (f"Over {DELAY_BUDGET_MS:g} ms", "number", (f"tasks whose mean delay exceeds the {DELAY_BUDGET_MS:g} ms "
                                                         "budget (the standard reward's T_max, madrl), of those "
                                                         "measured")),
             ("FLOPs per channel", "number", "declared by the method, per present channel and step")]
    head_html = "".join(f"<th scope=\"col\" data-type=\"{kind}\" title=\"{escape(tip)}\"><button type=\"button\">"
                        f"{escape(label)}</button></th>" for label, kind, tip in heads)
    rows = []
    for i, (standing, cost) in enumerate(compute_rows(board)):
        entry, score = standing.entry, standing.score
        worst = cost.worst_task
        cells = [
            num_cell(i, place(board, standing)),  # sorts back to the accuracy order
            (f"<td data-value=\"{escape(entry.name.casefold())}\"><a href=\"methods/{entry.id}.html\">"
             f"{escape(entry.name)}</a>{made_marks(standing)}</td>"),
            num_cell(score.times if score else None, fmt_times(score.times if score else None)),
            num_cell(cost.delay_ms, "not measured" if cost.delay_ms is None else fmt(cost.delay_ms, 2)),
            num_cell(None if worst is None else worst[1], "—" if worst is None else fmt(worst[1], 2),
                     None if worst is None else worst[0]),
            num_cell(cost.over_budget if cost.measured else None,
                     "—" if not cost.measured else f"{cost.over_budget}/{cost.measured}"),
            num_cell(cost.flops_per_channel,
                     "—" if cost.flops_per_channel is None else f"{cost.flops_per_channel:,.0f}"),
        ]
        rows.append(f"<tr data-method-id=\"{entry.id}\">{''.join(cells)}</tr>")
    return (f"<table class=\"sortable\" id=\"{escape(table_id)}\">\n<thead><tr>{head_html}</tr></thead>\n<tbody>\n"
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
        f"<th scope=\"col\" data-type=\"{kind}\" title=\"{escape(tip)}\">"
        f"<button type=\"button\">{escape(label)}</button></th>"
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
            f"<td data-value=\"{escape(entry.name.casefold())}\">"
            f"<a href=\"methods/{entry.id}.html\">{escape(entry.name)}</a>{made_marks(standing)}</td>",
            f"<td data-value=\"{escape(entry.track)}\">{escape(entry.track)}</td>",
            num_cell(score.times if score else None, fmt_times(score.times) if score else "—",
                     _score_tip(board, standing)),
            num_cell(low_high[0] if low_high else None,
                     "—" if low_high is None else f"[{fmt_times(low_high[0])}, {fmt_times(low_high[1])}]"),
            *([_cooperation_cell(score)] if cooperation else []),
            num_cell(score.gap_closed if score else None, fmt_pct(score.gap_closed if score else None)),
            num_cell(k, f"{k}/{n}"),
            *(_column_cell(standing, c) for c in columns),
            num_cell(entry.delay_ms, fmt(entry.delay_ms, 2)),
            num_cell(entry.energy_j, fmt(entry.energy_j, 3)),
            num_cell(entry.jitter, fmt(entry.jitter, 4)),
            f"<td data-value=\"{escape(status(entry))}\">{escape(status(entry))}</td>",
        ]
        rows.append(f"<tr data-method-id=\"{entry.id}\">{''.join(cells)}</tr>")
    return (
        f"<table class=\"sortable\" id=\"{escape(table_id)}\">\n<thead><tr>{head_html}</tr></thead>\n"
        f"<tbody>\n" + "\n".join(rows) + "\n</tbody>\n</table>"
    )


def _slug(*parts: str) -> str:
    text = "-".join(parts)
    return "".join(c if c.isalnum() else "-" for c in text).strip("-").lower() or "suite"


def _figure_list(plots: Sequence[SitePlot], root: Path) -> str:
    figures = "\n".join(
        f"<figure><img src=\"{escape(quote(p.path.relative_to(root).as_posix()))}\" alt=\"{escape(p.alt)}\">"
        f"<figcaption>{escape(p.caption)}</figcaption></figure>"
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
        parts.append(f"<section class=\"track\" id=\"track-{escape(slug)}-{escape(track_slug)}\">")
        parts.append(f"<h3>{escape(section.title)}</h3>")
        parts.append(f"<p class=\"meta\">{len(section.board.tasks)} tasks in {len(families)} families: "
                     f"{escape(listed)}.</p>")
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
        f"<p class=\"meta\">Generated {escape(generated)}. Methods are ranked by 2^S, how many "
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
        parts.append(f"<h2>Suite {escape(board.name)} <span class=\"version\">v{escape(board.version)}</span></h2>")
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
    return page("swarmloc leaderboard", "\n".join(parts), root="")


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
            for shown in standing.entries:  # a page per run; plots and the explanation on the table's run's
                on_tracks = [(track, on, len(tb.tasks)) for track, tb in per_track.items()
                             for on in tb.standings if any(e is shown for e in on.entries)]
                first = shown is standing.entry
                write_method(out, replace(standing, entry=shown), len(board.tasks), plots and first,
                             explain and first, on_tracks)
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


__all__ = ["render_html"]
