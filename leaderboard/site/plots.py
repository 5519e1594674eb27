"""The leaderboard site's suite plots, drawn with matplotlib when the site is built.

Per suite (one :class:`~swarmloc.leaderboard.site.ranking.SuiteBoard`):

* ``score.png`` — ``2^S`` with its 95 % CI per method (ranked, then partial coverage, then
  privileged), uniform at 1 (log scale when the CIs span more than ``LOG_SPAN``);
* ``gain_heatmap.png`` — method × task ``2^G_t`` (× lower error than uniform per task);
* ``gap_heatmap.png`` — method × task gap closed ``G_t / A_t``, only when some task of the
  suite has a defined gap (an information bound in the results, ``A_t ≥ log2 1.25``);
* ``profiles.png`` — performance profiles: the fraction of episodes whose gain exceeds τ.

Every method keeps its look (:func:`swarmloc.bench.reports.method_style.method_styles`)
across the plots. Method names are data: drawn as plain text (no mathtext), shortened to
``MAX_LABEL`` characters.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib import ticker

from swarmloc.bench.reports.method_style import method_styles
from swarmloc.bench.scoring.families import group_by_family, task_label
from swarmloc.bench.scoring.profiles import performance_profile
from swarmloc.leaderboard.site.ranking import Standing, SuiteBoard, fmt_pct, fmt_times

_DPI = 90
MAX_LABEL = 28
#: the score plot's axis is logarithmic when the CIs span more than this ratio
LOG_SPAN = 4.0
#: heatmap colours saturate at this many log2 units (16× better or worse than uniform)
GAIN_LIMIT = 4.0
#: profile thresholds span at most this range of gains (log2 units)
PROFILE_RANGE = (-4.0, 6.0)


@dataclass(frozen=True)
class SitePlot:
    """A drawn figure: its file, alt text and caption."""

    path: Path
    alt: str
    caption: str


def method_label(standing: Standing, n_tasks: int) -> str:
    """A method's label: its name, shortened, plain text, with its coverage or privilege noted."""
    name = standing.entry.name
    if len(name) > MAX_LABEL:
        name = name[: MAX_LABEL - 1] + "…"
    name = name.replace("$", r"\$")  # no mathtext from submitted names
    if standing.entry.privileged:
        return f"{name} (privileged)"
    k, n = standing.coverage(n_tasks)
    return name if k == n else f"{name} ({k}/{n})"


def scored(board: SuiteBoard) -> list[Standing]:
    return [s for s in board.standings if s.score is not None]


def _ordered_tasks(board: SuiteBoard) -> list[str]:
    return [t for members in group_by_family(board.tasks).values() for t in members]


#: what makes an SVG the same bytes on every build: a fixed salt for its element ids, glyphs drawn as
#: paths (no font lookup in the browser), and no creation date
_SVG_RC = {"svg.hashsalt": "swarmloc-leaderboard", "svg.fonttype": "path"}


def save_figure(fig: plt.Figure, path: Path) -> Path:
    """Lay out, write (PNG, or reproducible SVG by the suffix) and close a figure."""
    fig.tight_layout()
    if path.suffix == ".svg":
        with plt.rc_context(_SVG_RC):
            fig.savefig(path, format="svg", metadata={"Date": None})
    else:
        fig.savefig(path, dpi=_DPI)
    plt.close(fig)
    return path


def draw_intervals(ax: plt.Axes, board: SuiteBoard, rows: Sequence[Standing], centres: Sequence[float | None],
                   intervals: Sequence[tuple[float, float]], styles: Mapping[str, Any], *, reference: float) -> None:
    """One row per method: its value and interval in its own look, the reference dashed, tables ruled apart.

    Args:
        ax: where to draw (rows at y = 0, 1, ...).
        board: the board the rows come from (ranked, partial, privileged: a rule between them).
        rows, centres, intervals: the methods, their values (None: the row stays empty) and their ``(low, high)``.
        styles: method name → its ``MethodStyle``.
        reference: where uniform stands (a dashed line).
    """
    for y, (standing, centre, (low, high)) in enumerate(zip(rows, centres, intervals, strict=True)):
        if centre is None:
            continue
        style = styles[standing.entry.name]
        bars = ax.errorbar([centre], [y], xerr=[[centre - low], [high - centre]],
                           fmt=style.marker, color=style.colour, ecolor=style.colour, capsize=3,
                           markersize=6, markeredgecolor="black", markeredgewidth=0.5, elinewidth=1.6)
        bars[2][0].set_linestyle(style.linestyle)
    ax.axvline(reference, color="0.4", lw=0.8, ls="--", zorder=0)
    for y in (len(board.ranked) - 0.5, len(board.ranked) + len(board.partial) - 0.5):
        if 0 < y < len(rows) - 1:
            ax.axhline(y, color="0.75", lw=0.8)


def log_ratio_axis(ax: plt.Axes) -> None:
    """A logarithmic x axis labelled in plain ratios (1, 2, 5, 10, ...)."""
    ax.set_xscale("log")
    ax.xaxis.set_major_locator(ticker.LogLocator(base=10.0, subs=(1.0, 2.0, 5.0)))
    ax.xaxis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{v:g}"))
    ax.xaxis.set_minor_formatter(ticker.NullFormatter())


def plot_scores(board: SuiteBoard, path: Path) -> Path:
    """``2^S`` and its 95 % CI per method, best at the top, on a log axis (uniform = 1)."""
    rows = scored(board)
    styles = method_styles(s.entry.name for s in rows)
    fig, ax = plt.subplots(figsize=(8.0, 1.2 + 0.32 * len(rows)))
    draw_intervals(ax, board, rows, [s.score.times for s in rows if s.score],
                   [s.score.times_ci for s in rows if s.score], styles, reference=1.0)
    ax.set_yticks(range(len(rows)), [method_label(s, len(board.tasks)) for s in rows], fontsize=8)
    ax.invert_yaxis()
    lows, highs = zip(*(s.score.times_ci for s in rows if s.score))
    if max(highs) / min(lows) > LOG_SPAN:  # a log axis when ratios span a wide range, else plain
        log_ratio_axis(ax)
    ax.set_xlabel("2^S: × lower error than uniform (geometric mean over tasks; 95% CI)")
    ax.set_title(f"{board.name} v{board.version} — score (2^S)", fontsize=10)
    ax.grid(axis="x", alpha=0.3, which="both")
    return save_figure(fig, path)


def heatmap(board: SuiteBoard, path: Path, values: np.ndarray, text: list[list[str]], *, cmap: str,
            vmin: float, vmax: float, colourbar: str, title: str, columns: Sequence[str] | None = None) -> Path:
    """Method × column values coloured, each cell with its text, the methods' markers beside their names.

    Args:
        board: the board whose scored standings are the rows.
        path: the file to write.
        values: ``(methods, columns)``, NaN drawn grey.
        text: the cell texts.
        cmap, vmin, vmax: the colours.
        colourbar, title: labels.
        columns: the column labels (default: the board's tasks, by family).
    """
    rows = scored(board)
    labels = [task_label(t) for t in _ordered_tasks(board)] if columns is None else list(columns)
    fig, ax = plt.subplots(figsize=(max(6.0, 2.6 + 0.55 * len(labels)), 1.6 + 0.32 * len(rows)))
    colours = plt.get_cmap(cmap).with_extremes(bad="0.88")
    image = ax.imshow(np.ma.masked_invalid(values), cmap=colours, vmin=vmin, vmax=vmax, aspect="auto")
    for i, row in enumerate(text):
        for j, cell in enumerate(row):
            r, g, b, _ = colours(image.norm(values[i, j])) if np.isfinite(values[i, j]) else (1, 1, 1, 1)
            dark = 0.299 * r + 0.587 * g + 0.114 * b < 0.5  # white text on dark cells
            ax.text(j, i, cell, ha="center", va="center", fontsize=6.5, color="white" if dark else "black")
    ax.set_xticks(range(len(labels)), labels, rotation=50, ha="right", fontsize=7.5)
    ax.set_yticks(range(len(rows)), [method_label(s, len(board.tasks)) for s in rows], fontsize=7.5)
    # each row's method marker between its name and the map, as in the other plots
    styles = method_styles(s.entry.name for s in rows)
    ax.tick_params(axis="y", pad=13)
    for i, standing in enumerate(rows):
        style = styles[standing.entry.name]
        ax.plot([-0.012], [i], style.marker, color=style.colour, markeredgecolor="black", markeredgewidth=0.4,
                markersize=5, clip_on=False, transform=ax.get_yaxis_transform())
    bar = fig.colorbar(image, ax=ax, fraction=0.03, pad=0.02)
    bar.set_label(colourbar, fontsize=8)
    ax.set_title(title, fontsize=10)
    return save_figure(fig, path)


def _task_matrix(board: SuiteBoard, value: Callable[[Any], float | None],
                 label: Callable[[float], str]) -> tuple[np.ndarray, list[list[str]]]:
    """Method × task values (NaN where undefined or not covered) and their cell texts."""
    rows, tasks = scored(board), _ordered_tasks(board)
    values = np.full((len(rows), len(tasks)), np.nan)
    text = [["" for _ in tasks] for _ in rows]
    for i, standing in enumerate(rows):
        assert standing.score is not None
        for j, task in enumerate(tasks):
            t = standing.score.tasks.get(task)
            v = None if t is None else value(t)
            if v is not None:
                values[i, j], text[i][j] = v, label(v)
    return values, text


def plot_gain_heatmap(board: SuiteBoard, path: Path) -> Path:
    """Method × task ``2^G_t``, coloured by ``G_t`` (log2; blue better than uniform, red worse)."""
    values, text = _task_matrix(board, lambda t: t.mean, lambda g: fmt_times(2.0**g))
    return heatmap(board, path, values, text, cmap="RdBu", vmin=-GAIN_LIMIT, vmax=GAIN_LIMIT,
                    colourbar="G_t = mean log2(RMSE_uniform / RMSE)",
                    title=f"{board.name} v{board.version} — × uniform per task")


def plot_gap_heatmap(board: SuiteBoard, path: Path) -> Path:
    """Method × task gap closed ``G_t / A_t`` (grey where undefined or not covered)."""
    values, text = _task_matrix(board, lambda t: t.gap_closed, fmt_pct)
    return heatmap(board, path, values, text, cmap="viridis", vmin=0.0, vmax=1.0,
                    colourbar="gap closed G_t / A_t", title=f"{board.name} v{board.version} — gap closed per task")


def plot_profiles(board: SuiteBoard, path: Path) -> Path:
    """Performance profiles: fraction of episodes (tasks weigh equally) with gain above τ."""
    rows = scored(board)
    styles = method_styles(s.entry.name for s in rows)
    gains = np.concatenate([t.gains for s in rows if s.score for t in s.score.tasks.values()])
    low = max(PROFILE_RANGE[0], float(np.floor(gains.min())))
    high = min(PROFILE_RANGE[1], float(np.ceil(gains.max())))
    taus = np.linspace(low, high if high > low else low + 1.0, 241)
    fig, ax = plt.subplots(figsize=(10.0, 4.8))
    for standing in rows:
        assert standing.score is not None
        profile = performance_profile({t: s.gains for t, s in standing.score.tasks.items()}, taus)
        ax.plot(taus, profile, lw=1.4, label=method_label(standing, len(board.tasks)), **styles[standing.entry.name].line())
    ax.axvline(0.0, color="0.4", lw=0.8, ls="--", zorder=0)
    ax.set(xlabel="τ: gain g = log2(RMSE_uniform / RMSE) of an episode", ylim=(-0.02, 1.02),
           ylabel="fraction of episodes with g > τ", title=f"{board.name} v{board.version} — performance profiles")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    return save_figure(fig, path)


def suite_plots(board: SuiteBoard, out_dir: Path) -> list[SitePlot]:
    """Draw a suite's plots into ``out_dir`` (created); none when no method has a score.

    Returns:
        The figures with their alt text and captions, in page order.
    """
    if not scored(board):
        return []
    out_dir.mkdir(parents=True, exist_ok=True)
    plots = [
        SitePlot(plot_scores(board, out_dir / "score.png"), "score per method with 95% CI",
                 "2^S per method with its stratified-bootstrap 95% CI (uniform = 1, dashed). Ranked methods "
                 "first, then partial coverage (k/T: over the covered tasks only), then privileged methods."),
    ]
    has_gap = any(t.gap_closed is not None for s in scored(board) for t in s.score.tasks.values())  # type: ignore[union-attr]
    if has_gap:
        plots.append(SitePlot(plot_gap_heatmap(board, out_dir / "gap_heatmap.png"), "gap closed per method and task",
                              "Gap closed per method and task: G_t / A_t, the share of the achievable gain (uniform to "
                              "the information bound) the method closes; grey where the bound is undefined or within "
                              "25% of uniform, or the method does not cover the task."))
    plots.append(SitePlot(
        plot_gain_heatmap(board, out_dir / "gain_heatmap.png"), "gain over uniform per method and task",
        "Per method and task: 2^G_t, × lower error than uniform (G_t the mean over seeds of log2(RMSE_uniform / "
        "RMSE)); blue better, red worse, grey not covered."
        + ("" if has_gap else " Gap closed is undefined on every task of this suite (its results carry no "
                              "information bound, bound_rmse), so this heatmap shows G_t instead.")))
    plots.append(SitePlot(
        plot_profiles(board, out_dir / "profiles.png"), "performance profiles",
        "Performance profiles (rliable): the fraction of a method's episodes whose gain g exceeds τ, tasks weighing "
        "equally; higher is better, τ = 0 is uniform. Partial-coverage methods over their covered tasks."))
    return plots


__all__ = ["SitePlot", "draw_intervals", "heatmap", "log_ratio_axis", "method_label", "plot_gain_heatmap", "plot_gap_heatmap",
           "plot_profiles", "plot_scores", "save_figure", "scored", "suite_plots"]
