"""Plots of evaluation results (matplotlib, Agg backend): PNGs per task.

For every task, from the per-step trace of the first seed (``<results>.traces.npz``,
written by ``swarmloc evaluate``; when it is missing, that episode is re-run):

* ``error_<task>.png`` — mean position error of the scored UAVs vs time, one line per
  method, the fault window (or the steps with labelled faults) shaded;
* ``cdf_<task>.png`` — empirical CDF of the error (scored UAVs, every step);
* ``trust_<task>.png`` — trust each method applied to the first scored UAV's channels vs
  time, coloured by channel kind, labelled faults marked;
* ``trajectory_<task>.png`` — truth and estimated x–y trajectories per method.

Lines of a method have its colour and line style from
:func:`swarmloc.bench.reports.method_style.method_styles`, the same in every figure.

Several results files (one per method) share the figures, so methods are compared.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from swarmloc.agents.registry import load_method  # noqa: E402
from swarmloc.bench.reports.method_style import method_styles  # noqa: E402
from swarmloc.bench.evaluation.results import load_results  # noqa: E402
from swarmloc.bench.evaluation.runner import Trace, read_traces, rollout, traces_path  # noqa: E402
from swarmloc.envs.tasks.channels import KIND_NAMES  # noqa: E402
from swarmloc.envs.tasks.catalogue import get_spec  # noqa: E402

#: one colour per channel kind, in ``KIND_NAMES`` order
_KIND_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown", "tab:cyan")
assert len(_KIND_COLOURS) == len(KIND_NAMES), "every channel kind needs a colour"
_DPI = 90
#: at most this many channels per trust panel and UAVs per trajectory panel (large swarms)
MAX_CHANNELS, MAX_UAVS = 12, 8
#: points of a drawn CDF
CDF_POINTS = 400


def short_name(task: str) -> str:
    """``swarmloc/NLOS-v0`` → ``NLOS-v0``."""
    return task.removeprefix("swarmloc/")


def load_traces(results_path: str | os.PathLike[str]) -> list[Trace]:
    """The first-seed traces of a results file: from its sidecar, else by re-running them.

    Args:
        results_path: a results file written by ``swarmloc evaluate``.

    Returns:
        One trace per task, in the results' task order.
    """
    results = load_results(results_path)
    sidecar = traces_path(results_path)
    if sidecar.is_file():
        return read_traces(sidecar)
    first: dict[str, int] = {}
    for episode in results.episodes:
        if episode.metrics.rmse is not None:  # tasks the method could not run have no trace
            first.setdefault(episode.task, episode.seed)
    traces = []
    for task, seed in first.items():
        spec = get_spec(task)
        _, trace = rollout(load_method(results.method.entry_point, version=spec.version), spec, [seed], trace=True)
        assert trace is not None
        trace.method = results.method.name
        traces.append(trace)
    return traces


def _fault_spans(trace: Trace) -> list[tuple[float, float]]:
    """Shaded spans: the fault window if the task has one, else runs of labelled steps."""
    if np.all(np.isfinite(trace.fault_window)):
        return [(float(trace.fault_window[0]), float(trace.fault_window[1]))]
    labelled = trace.label[:, trace.scored].any(axis=(1, 2))
    spans, start = [], None
    dt = float(trace.times[1] - trace.times[0]) if len(trace.times) > 1 else 1.0
    for t, on in zip(trace.times, labelled):
        if on and start is None:
            start = t - dt
        elif not on and start is not None:
            spans.append((float(start), float(t - dt)))
            start = None
    if start is not None:
        spans.append((float(start), float(trace.times[-1])))
    return spans


def _shade(ax: plt.Axes, spans: list[tuple[float, float]]) -> None:
    for i, (a, b) in enumerate(spans):
        ax.axvspan(a, b, color="0.85", zorder=0, label="fault" if i == 0 else None)


def _save(fig: plt.Figure, path: Path, margins: dict[str, float] | None = None) -> Path:
    """Lay out (``tight_layout``, or ``_panel_margins(**margins)`` for a grid of panels), write, close."""
    if margins is None:
        fig.tight_layout()
    else:
        _panel_margins(fig, **margins)
    fig.savefig(path, dpi=_DPI)
    plt.close(fig)
    return path


def _panel_margins(fig: plt.Figure, left: float = 0.55, right: float = 0.15, top: float = 0.6, bottom: float = 0.4,
                   wspace: float = 0.3, hspace: float = 0.45) -> None:
    """Margins of a grid of panels, fixed in inches (left, right, top, bottom).

    ``tight_layout`` measures every tick label of every panel: on a figure of 13 panels it
    took a third of the drawing time. Panels of the same kind need the same room, so
    fixed margins lay them out as well, at no cost.
    """
    w, h = fig.get_size_inches()
    fig.subplots_adjust(left=left / w, right=1.0 - right / w, top=1.0 - top / h, bottom=bottom / h,
                        wspace=wspace, hspace=hspace)


def plot_error_vs_time(traces: Sequence[Trace], path: Path) -> Path:
    """Mean error of the scored UAVs vs time, one line per method (same task)."""
    fig, ax = plt.subplots(figsize=(8, 4))
    _shade(ax, _fault_spans(traces[0]))
    styles = method_styles(tr.method for tr in traces)
    for tr in traces:
        ax.plot(tr.times, tr.errors[:, tr.scored].mean(axis=1), lw=1.2, label=tr.method, **styles[tr.method].line())
    ax.set(xlabel="time [s]", ylabel="mean position error [m]", yscale="log",
           title=f"{short_name(traces[0].task)} — error vs time (seed {traces[0].seed})")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    return _save(fig, path)


def plot_error_cdf(traces: Sequence[Trace], path: Path) -> Path:
    """Empirical CDF of the error of the scored UAVs over every step, per method."""
    fig, ax = plt.subplots(figsize=(6, 4))
    styles = method_styles(tr.method for tr in traces)
    for tr in traces:
        e = np.sort(tr.errors[:, tr.scored].ravel())
        q = np.linspace(0.0, 1.0, min(CDF_POINTS, e.size))
        ax.plot(np.quantile(e, q), q, lw=1.2, label=tr.method, **styles[tr.method].line())
    ax.axhline(0.9, color="0.5", lw=0.8, ls="--")
    ax.set(xlabel="position error [m]", ylabel="fraction of UAV-steps", xscale="log",
           title=f"{short_name(traces[0].task)} — error CDF (seed {traces[0].seed})")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    return _save(fig, path)


def plot_trust(traces: Sequence[Trace], path: Path) -> Path | None:
    """Trust applied to the first scored UAV's channels vs time, one panel per method.

    At most ``MAX_CHANNELS`` channels are drawn per panel, the labelled ones first.
    """
    with_trust = [tr for tr in traces if tr.applied is not None]
    if not with_trust:
        return None
    cols = min(3, len(with_trust))
    rows = -(-len(with_trust) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(max(4.2 * cols, 8.0), 2.6 * rows + 0.6), sharex=True, sharey=True, squeeze=False)
    for ax, tr in zip(axes.flat, with_trust):
        i = int(np.flatnonzero(tr.scored)[0])
        if np.all(np.isfinite(tr.fault_window)):  # labelled faults are marked per channel instead
            _shade(ax, [(float(tr.fault_window[0]), float(tr.fault_window[1]))])
        assert tr.applied is not None
        present = [l for l in range(tr.applied.shape[2]) if tr.valid[:, i, l].any()]
        # the labelled channels first, then the rest, up to MAX_CHANNELS
        present.sort(key=lambda l: not tr.label[:, i, l].any())
        for l in present[:MAX_CHANNELS]:
            valid = tr.valid[:, i, l]
            alpha = np.where(valid, tr.applied[:, i, l], np.nan)
            ax.plot(tr.times, alpha, lw=0.7, color=_KIND_COLOURS[int(tr.kind[i, l])], alpha=0.8)
            bad = tr.label[:, i, l]
            if bad.any():
                ax.plot(tr.times[bad], tr.applied[bad, i, l], "x", ms=2, color="red")
        ax.set_title(f"{tr.method} (UAV {i})", fontsize=8)
        ax.set_ylim(-0.05, 1.05)
        ax.grid(alpha=0.3)
    for ax in axes.flat[len(with_trust):]:
        ax.axis("off")
    handles = [plt.Line2D([], [], color=c, label=n) for c, n in zip(_KIND_COLOURS, KIND_NAMES)]
    handles.append(plt.Line2D([], [], marker="x", ls="", color="red", label="labelled fault"))
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=7, frameon=False)
    fig.suptitle(f"{short_name(traces[0].task)} — applied trust α vs time [s]", fontsize=9)
    return _save(fig, path, {"bottom": 0.75, "hspace": 0.35, "wspace": 0.08})  # the legend of channel kinds below


def plot_trajectories(traces: Sequence[Trace], path: Path) -> Path:
    """Truth (black) and estimated x–y trajectories of the first ``MAX_UAVS`` UAVs, one panel per method."""
    cols = min(3, len(traces))
    rows = -(-len(traces) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4 * cols, 3.6 * rows), squeeze=False)
    truth = traces[0].truth
    lo, hi = truth[..., :2].min(axis=(0, 1)), truth[..., :2].max(axis=(0, 1))
    pad = 0.15 * max(float((hi - lo).max()), 1.0)
    for ax, tr in zip(axes.flat, traces):
        for i in range(min(tr.truth.shape[1], MAX_UAVS)):
            ax.plot(tr.truth[:, i, 0], tr.truth[:, i, 1], color="black", lw=0.8)
            ax.plot(tr.estimate[:, i, 0], tr.estimate[:, i, 1], lw=0.8, alpha=0.8)
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
        ax.set_aspect("equal", adjustable="box")
        ax.set_title(tr.method, fontsize=8)
        ax.grid(alpha=0.3)
    for ax in axes.flat[len(traces):]:
        ax.axis("off")
    fig.suptitle(f"{short_name(traces[0].task)} — x–y [m], truth black", fontsize=9)
    return _save(fig, path, {"top": 0.8})


def plot_task(traces: Sequence[Trace], out: Path) -> list[Path]:
    """The four figures of one task (traces of several methods on the same episode)."""
    name = short_name(traces[0].task)
    written = [plot_error_vs_time(traces, out / f"error_{name}.png"),
               plot_error_cdf(traces, out / f"cdf_{name}.png")]
    trust = plot_trust(traces, out / f"trust_{name}.png")
    if trust is not None:
        written.append(trust)
    written.append(plot_trajectories(traces, out / f"trajectory_{name}.png"))
    return written


def plot_results(results_paths: str | os.PathLike[str] | Sequence[str | os.PathLike[str]],
                 out_dir: str | os.PathLike[str], workers: int = 1) -> list[Path]:
    """Write the PNGs of one or several results files (methods compared per task).

    Args:
        results_paths: one results file or several (one per method).
        out_dir: output folder (created if missing).
        workers: processes drawing tasks in parallel (1 = here).

    Returns:
        The written PNG paths.
    """
    if isinstance(results_paths, (str, os.PathLike)):
        results_paths = [results_paths]
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    by_task: dict[str, list[Trace]] = {}
    for path in results_paths:
        for tr in load_traces(path):
            by_task.setdefault(tr.task, []).append(tr)
    if workers <= 1 or len(by_task) <= 1:
        return [path for traces in by_task.values() for path in plot_task(traces, out)]
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
        parts = pool.map(plot_task, list(by_task.values()), [out] * len(by_task))
        return [path for part in parts for path in part]
