"""A benchmark v2 track's figures on the front page: rliable's plots and a family heat map.

A v2 suite has one board per track (:func:`swarmloc.leaderboard.site.ranking.track_boards`);
for each the site draws, as reproducible SVG (``plots.save_figure``):

* ``score.svg`` — ``2^S`` per method with its hierarchical-bootstrap 95 % CI (score v2), and on
  the cooperative track beside it the cooperation gain ``2^C`` (× lower error than each UAV
  localizing alone) with its CI;
* ``profiles.svg`` — performance profiles: the fraction of a method's runs (task, seed) whose gain
  exceeds τ, families weighing equally, with a pointwise 95 % band;
* ``improvement.svg`` — P(method > uniform): the chance that a run of the method has the lower
  error, with its 95 % CI;
* ``improvement_pairs.svg`` — P(row > column) for every pair of methods (rliable's definition:
  over all pairs of runs of a task, averaged over tasks, families weighing equally);
* ``family_heatmap.svg`` — method × family ``2^(mean G_t over the family's tasks)``.

The numbers come from :mod:`swarmloc.bench.scoring.profiles` and the standings' score v2; here
only the drawing. Every method keeps its look across the plots, as on a v1 board.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from swarmloc.bench.reports.method_style import method_styles
from swarmloc.bench.scoring.families import group_by_family
from swarmloc.bench.scoring.profiles import (
    improvement_matrix,
    improvement_over_uniform,
    performance_profile,
    profile_interval,
)
from swarmloc.leaderboard.site.plots import (
    GAIN_LIMIT,
    LOG_SPAN,
    PROFILE_RANGE,
    SitePlot,
    draw_intervals,
    heatmap,
    log_ratio_axis,
    method_label,
    save_figure,
    scored,
)
from swarmloc.leaderboard.site.ranking import SuiteBoard, column_score, family_columns, fmt_times

#: how each track is headed on the page
TRACK_TITLES: dict[str, str] = {
    "cooperative": "Cooperative track (the headline)",
    "robust-ranging": "Robust-ranging track (one UAV)",
}

#: thresholds of a profile (its band is resampled at each)
PROFILE_POINTS = 121


@dataclass(frozen=True)
class TrackSection:
    """A track's part of a suite's section: the track, its board and its figures in page order."""

    track: str
    board: SuiteBoard
    plots: tuple[SitePlot, ...]

    @property
    def title(self) -> str:
        """The track's heading (``TRACK_TITLES``, else its name)."""
        return TRACK_TITLES.get(self.track, self.track)


def _gains(board: SuiteBoard) -> list[dict[str, np.ndarray]]:
    """Per scored standing, task → its per-seed gains."""
    return [{t: s.gains for t, s in st.score.tasks.items()} for st in scored(board) if st.score]


def _ticks(ax: plt.Axes, board: SuiteBoard) -> None:
    rows = scored(board)
    ax.set_yticks(range(len(rows)), [method_label(s, len(board.tasks)) for s in rows], fontsize=8)
    ax.invert_yaxis()


def plot_track_scores(board: SuiteBoard, track: str, path: Path) -> Path:
    """``2^S`` per method with its CI; on the cooperative track, the cooperation gain ``2^C`` beside it."""
    rows = scored(board)
    styles = method_styles(s.entry.name for s in rows)
    scores = [s.score for s in rows if s.score]
    cooperation = [s.cooperation for s in scores]
    both = track == "cooperative" and any(c is not None for c in cooperation)
    fig, axes = plt.subplots(1, 2 if both else 1, figsize=(11.0 if both else 8.0, 1.4 + 0.32 * len(rows)),
                             sharey=True, squeeze=False)
    panels = [(axes[0, 0], [s.times for s in scores], [s.times_ci for s in scores],
               "2^S: × lower error than uniform (95% CI)")]
    if both:
        panels.append((axes[0, 1], [None if c is None else 2.0**c.S for c in cooperation],
                       [(np.nan, np.nan) if c is None else (2.0**c.ci_low, 2.0**c.ci_high) for c in cooperation],
                       "2^C: × lower error than non-cooperative (95% CI)"))
    for ax, centres, intervals, label in panels:
        draw_intervals(ax, board, rows, centres, intervals, styles, reference=1.0)
        shown = [v for pair in intervals for v in pair if np.isfinite(v)]
        if shown and max(shown) / min(shown) > LOG_SPAN:
            log_ratio_axis(ax)
        ax.set_xlabel(label, fontsize=8.5)
        ax.grid(axis="x", alpha=0.3, which="both")
    _ticks(axes[0, 0], board)
    fig.suptitle(f"{board.name}, {track} track — score v2 (families weigh equally)", fontsize=10)
    return save_figure(fig, path)


def plot_track_profiles(board: SuiteBoard, track: str, path: Path) -> Path:
    """Performance profiles with their 95 % bands: fraction of runs with g > τ, families weighing equally."""
    rows = scored(board)
    styles = method_styles(s.entry.name for s in rows)
    every = np.concatenate([g for gains in _gains(board) for g in gains.values()])
    low = max(PROFILE_RANGE[0], float(np.floor(every.min())))
    high = min(PROFILE_RANGE[1], float(np.ceil(every.max())))
    taus = np.linspace(low, high if high > low else low + 1.0, PROFILE_POINTS)
    fig, ax = plt.subplots(figsize=(10.0, 4.8))
    for standing, gains in zip(rows, _gains(board), strict=True):
        assert standing.score is not None
        style = styles[standing.entry.name]
        families = standing.score.families
        ax.plot(taus, performance_profile(gains, taus, families=families), lw=1.4,
                label=method_label(standing, len(board.tasks)), **style.line())
        band_low, band_high = profile_interval(gains, taus, families=families)
        ax.fill_between(taus, band_low, band_high, color=style.colour, alpha=0.15, lw=0)
    ax.axvline(0.0, color="0.4", lw=0.8, ls="--", zorder=0)
    ax.set(xlabel="τ: gain g = log2(RMSE_uniform / RMSE) of a run (task, seed)", ylim=(-0.02, 1.02),
           ylabel="fraction of runs with g > τ",
           title=f"{board.name}, {track} track — performance profiles")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    return save_figure(fig, path)


def plot_improvement(board: SuiteBoard, track: str, path: Path) -> Path:
    """P(method > uniform) per method with its 95 % CI (0.5: no better than uniform)."""
    rows = scored(board)
    styles = method_styles(s.entry.name for s in rows)
    found = [improvement_over_uniform(gains, families=s.score.families)
             for s, gains in zip(rows, _gains(board), strict=True) if s.score]
    fig, ax = plt.subplots(figsize=(8.0, 1.4 + 0.32 * len(rows)))
    draw_intervals(ax, board, rows, [p.p for p in found], [(p.ci_low, p.ci_high) for p in found], styles,
                   reference=0.5)
    _ticks(ax, board)
    ax.set_xlim(-0.02, 1.02)
    ax.set_xlabel("P(method > uniform): chance that a run has the lower error (95% CI)", fontsize=8.5)
    ax.set_title(f"{board.name}, {track} track — probability of improvement over uniform", fontsize=10)
    ax.grid(axis="x", alpha=0.3)
    return save_figure(fig, path)


def plot_improvement_pairs(board: SuiteBoard, track: str, path: Path) -> Path:
    """P(row > column) for every pair of scored methods, on the tasks both cover."""
    rows = scored(board)
    values = improvement_matrix(_gains(board), families=group_by_family(board.tasks))
    text = [["" if np.isnan(v) else f"{v:.2f}" for v in row] for row in values]
    return heatmap(board, path, values, text, cmap="RdBu", vmin=0.0, vmax=1.0, colourbar="P(row > column)",
                   title=f"{board.name}, {track} track — P(row > column)",
                   columns=[method_label(s, len(board.tasks)) for s in rows])


def plot_family_heatmap(board: SuiteBoard, track: str, path: Path) -> Path:
    """Method × family ``2^(mean G_t over the family's covered tasks)``, coloured by its log2 (blue better)."""
    rows, columns = scored(board), family_columns(board.tasks)
    values = np.full((len(rows), len(columns)), np.nan)
    text = [["" for _ in columns] for _ in rows]
    for i, standing in enumerate(rows):
        for j, column in enumerate(columns):
            cs = column_score(standing.score, column)
            if cs is not None:
                values[i, j] = np.log2(cs.times)
                text[i][j] = fmt_times(cs.times) + ("" if cs.covered == cs.total else "*")
    return heatmap(board, path, values, text, cmap="RdBu", vmin=-GAIN_LIMIT, vmax=GAIN_LIMIT,
                   colourbar="family score: mean over its tasks of G_t (log2)",
                   title=f"{board.name}, {track} track — × uniform per family",
                   columns=[f"{c.header} ({len(c.tasks)})" for c in columns])


def track_plots(board: SuiteBoard, track: str, out_dir: Path) -> TrackSection:
    """Draw a track's figures into ``out_dir`` (created); none when no method has a score there."""
    if not scored(board):
        return TrackSection(track, board, ())
    out_dir.mkdir(parents=True, exist_ok=True)
    plots = (
        SitePlot(plot_track_scores(board, track, out_dir / "score.svg"), "score per method with 95% CI",
                 "2^S per method: × lower error than uniform, score v2 (mean over seeds, then over a family's tasks, "
                 "then over families, each family weighing the same) with its hierarchical-bootstrap 95% CI "
                 "(families, then seeds); uniform = 1, dashed. On the cooperative track, the cooperation gain 2^C "
                 "beside it (× lower error than non-cooperative, each UAV alone), where the board has a "
                 "non-cooperative entry. Ranked methods first, then partial coverage (k/T), then privileged ones."),
        SitePlot(plot_track_profiles(board, track, out_dir / "profiles.svg"), "performance profiles",
                 "Performance profiles (rliable): the fraction of a method's runs (task, seed) whose gain g = "
                 "log2(RMSE_uniform / RMSE) exceeds τ, families weighing equally, with a pointwise 95% band from "
                 "the same bootstrap. Higher is better; a curve above another at every τ beats it on every quantile."),
        SitePlot(plot_improvement(board, track, out_dir / "improvement.svg"), "probability of improvement over uniform",
                 "Probability of improvement (rliable): P(method > uniform), the chance that a run of the method has "
                 "a lower error than uniform on the same episode (ties count half), averaged over tasks with "
                 "families weighing equally; 95% CI from the score's bootstrap. 0.5: no better than uniform."),
        SitePlot(plot_improvement_pairs(board, track, out_dir / "improvement_pairs.svg"),
                 "probability of improvement between every pair of methods",
                 "P(row > column): the chance that a run of the row's method beats a run of the column's "
                 "(Mann–Whitney over the pairs of runs of a task, averaged over the tasks both cover, families "
                 "weighing equally). Blue: the row is ahead."),
        SitePlot(plot_family_heatmap(board, track, out_dir / "family_heatmap.svg"), "score per method and family",
                 "Per method and family (task count in brackets): × lower error than uniform, 2^ of the mean over "
                 "the family's tasks of G_t; blue better, red worse, grey not covered, * some tasks not covered."),
    )
    return TrackSection(track, board, plots)


__all__ = [
    "PROFILE_POINTS",
    "TRACK_TITLES",
    "TrackSection",
    "plot_family_heatmap",
    "plot_improvement",
    "plot_improvement_pairs",
    "plot_track_profiles",
    "plot_track_scores",
    "track_plots",
]
