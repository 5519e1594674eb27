"""The Table 5-style summary of an explanation (madrl §3.4.3), as Markdown and JSON.

Per episode set: the fault-window RMSE of the method and of the reference (``uniform``,
the standard CEKF), the mean trust on attacked (labelled) and on normal channels inside
the fault window — normal: present, unlabelled channels of the attacked channels' kinds,
as ``swarmloc reproduce madrl`` counts them — and the feature groups ranked by mean
|attribution|: on the attacked channels inside the window, at its onset (its first
second), outside it, and on the normal channels inside it. The signed means say which
way a feature pushed α (negative: it lowered the trust).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from swarmloc.bench.reports.markdown import markdown_table, write_report
from swarmloc.bench.scoring import metrics as M
from swarmloc.bench.explain.attributions import Explanation
from swarmloc.bench.explain.episode import Episode
from swarmloc.bench.explain.features import GROUP_NAMES

#: madrl Table 5 (Experiment 4, 20–30 s): fault RMSE of the standard EKF and MADRL-CEKF [m], mean α
PAPER_TABLE5 = {"ekf_fault_rmse": 3.0906, "madrl_fault_rmse": 0.8675, "alpha_normal": 0.6456,
                "alpha_attacked": 0.0875}
#: the onset: the first this-many seconds of the fault window
ONSET_S = 1.0
#: recovery: the attacked channels' mean trust over this many seconds after the window (madrl: back within 2 s)
RECOVERY_S = 5.0


def fault_window(episode: Episode) -> tuple[float, float] | None:
    """The task's ``scoring.fault_window``, else the span of the labelled steps, else None."""
    window = episode.spec.scoring.fault_window
    if window is not None:
        return float(window[0]), float(window[1])
    labelled = np.nonzero(episode.label.any(axis=(1, 2, 3)))[0]
    if not len(labelled):
        return None
    return float(episode.times[labelled[0]]), float(episode.times[labelled[-1]] + episode.spec.dt)


def window_rmse(episode: Episode, window: tuple[float, float] | None) -> float | None:
    """RMSE of the scored UAVs' errors inside the window (all episodes pooled), None without one."""
    inside = M.window_steps(episode.times, window)
    return M.fault_rmse(episode.error[:, episode.scored], inside)


def _mean(values: np.ndarray) -> float | None:
    values = values[np.isfinite(values)]
    return float(values.mean()) if values.size else None


def _ranking(grouped: np.ndarray, select: np.ndarray) -> list[dict[str, Any]]:
    """Feature groups by mean |attribution| over the selected (step, episode, UAV, channel) cells."""
    rows = grouped[select]
    rows = rows[np.isfinite(rows).all(axis=-1)]
    if not len(rows):
        return []
    mean_abs, mean = np.abs(rows).mean(axis=0), rows.mean(axis=0)
    order = np.argsort(-mean_abs, kind="stable")
    return [{"feature": GROUP_NAMES[g], "mean_abs": float(mean_abs[g]), "mean": float(mean[g])} for g in order]


def summarize(ex: Explanation) -> dict[str, Any]:
    """The summary's numbers (JSON-ready)."""
    ep, attr = ex.episode, ex.attributions
    window = fault_window(ep)
    inside = M.window_steps(ep.times, window)[:, None, None, None]
    onset = M.window_steps(ep.times, None if window is None else (window[0], window[0] + ONSET_S))[:, None, None, None]
    attacked_channel = ep.label.any(axis=0)[None]  # (1, B, N, L): channels labelled at some step
    kinds = np.unique(ep.layout.kind[ep.label.any(axis=(0, 1))])
    same_kind = np.isin(ep.layout.kind, kinds)[None, None]
    attacked = ep.valid & ep.label & inside
    normal = ep.valid & ~ep.label & inside & same_kind
    grouped = attr.grouped()
    rmse = window_rmse(ep, window)
    ref = window_rmse(ex.reference, window) if ex.reference is not None else None
    alpha_attacked, alpha_normal = _mean(attr.trust[attacked]), _mean(attr.trust[normal])
    after = M.window_steps(ep.times, None if window is None else (window[1], window[1] + RECOVERY_S))
    recovered = ep.valid & attacked_channel & after[:, None, None, None]
    return {
        "method": ep.method, "task": ep.spec.task_id, "duration_s": float(ep.spec.duration),
        "seeds": [int(s) for s in ep.seeds], "fault_window_s": window,
        "explainer": attr.explainer, "baseline": attr.baseline, "settings": attr.settings,
        "channels_explained": [int(j) for j in np.nonzero(attr.explained.any(axis=0))[0]],
        "completeness_gap": attr.completeness_gap, "faithfulness_gap": attr.faithfulness_gap,
        "attribution_seconds": attr.seconds,
        "fault_rmse": rmse, "reference": None if ex.reference is None else ex.reference.method,
        "reference_fault_rmse": ref,
        "gain_vs_reference": None if rmse is None or not ref else (ref - rmse) / ref,
        "alpha_attacked": alpha_attacked, "alpha_normal": alpha_normal,
        "suppression": None if not alpha_attacked or alpha_normal is None else alpha_normal / alpha_attacked,
        "alpha_attacked_after": _mean(attr.trust[recovered]), "recovery_s": RECOVERY_S,
        "attacked_channel_steps": int(attacked.sum()), "normal_channel_steps": int(normal.sum()),
        "top_features": {
            "attacked_inside": _ranking(grouped, attacked),
            "attacked_onset": _ranking(grouped, attacked & onset),
            "attacked_outside": _ranking(grouped, ep.valid & attacked_channel & ~inside),
            "normal_inside": _ranking(grouped, normal),
        },
        "paper_table5": PAPER_TABLE5,
    }


def _f(value: float | None, digits: int = 4) -> str:
    return "—" if value is None else f"{value:.{digits}f}"


def summary_markdown(summary: dict[str, Any], figure: str | None = None) -> str:
    """The summary as a Markdown report."""
    s, p = summary, summary["paper_table5"]
    window = s["fault_window_s"]
    span = "—" if window is None else f"{window[0]:g}–{window[1]:g} s"
    lines = [f"# Trust decisions of {s['method']} on {s['task']} (madrl Experiment 4)", "",
             (f"Seed(s) {', '.join(map(str, s['seeds']))}, {s['duration_s']:g} s; fault window {span}. "
              f"Explainer **{s['explainer']}**, baseline **{s['baseline']}**; attributions add up to "
              f"α(x) − α(baseline) within {s['completeness_gap']:.1e} and the explained function matches the "
              f"method's act() within {s['faithfulness_gap']:.1e}."), ""]
    if figure:
        lines += [f"![Figure 6 chain]({figure})", ""]
    ref = s["reference"] or "reference"
    gain = "—" if s["gain_vs_reference"] is None else f"{100 * s['gain_vs_reference']:.2f} %"
    ratio = "—" if s["suppression"] is None else f"{s['suppression']:.1f}×"
    lines += ["## Table 5 — inside the fault window", ""] + markdown_table(
        ["", f"{ref} fault RMSE [m]", f"{s['method']} fault RMSE [m]", "gain", "mean α attacked", "mean α normal",
         "suppression"],
        [["ours", _f(s["reference_fault_rmse"]), _f(s["fault_rmse"]), gain, _f(s["alpha_attacked"]),
          _f(s["alpha_normal"]), ratio],
         ["madrl Table 5", f"{p['ekf_fault_rmse']:.4f}", f"{p['madrl_fault_rmse']:.4f}",
          f"{100 * (p['ekf_fault_rmse'] - p['madrl_fault_rmse']) / p['ekf_fault_rmse']:.2f} %",
          f"{p['alpha_attacked']:.4f}", f"{p['alpha_normal']:.4f}",
          f"{p['alpha_normal'] / p['alpha_attacked']:.1f}×"]], "lrrrrrr")
    lines += ["", (f"Attacked: labelled channel-steps ({s['attacked_channel_steps']}); normal: present, unlabelled "
                   f"channels of the same kind ({s['normal_channel_steps']}). After the window the attacked "
                   f"channels' mean α over {s['recovery_s']:g} s is {_f(s['alpha_attacked_after'])} (madrl: back "
                   f"to normal within 2 s)."), "",
              "## Top features by mean |attribution|", "",
              "Signed mean in brackets: negative lowered α below the baseline's.", ""]
    names = {"attacked_inside": "attacked, inside the window", "attacked_onset": "attacked, first second",
             "attacked_outside": "attacked channels, outside", "normal_inside": "normal, inside the window"}
    rows = []
    for key, label in names.items():
        ranking = s["top_features"][key][:3]
        cells = [f"{r['feature']} {r['mean_abs']:.3f} ({r['mean']:+.3f})" for r in ranking]
        rows.append([label] + cells + ["—"] * (3 - len(cells)))
    lines += markdown_table(["channel-steps", "1st", "2nd", "3rd"], rows)
    return "\n".join(lines) + "\n"


def write_summary(summary: dict[str, Any], out_dir: str | Path, figure: str | None = None) -> Path:
    """Write ``summary.md`` and ``summary.json`` into ``out_dir``; returns the Markdown path."""
    from swarmloc.bench.common.provenance import collect_provenance

    raw = dict(summary, provenance=collect_provenance().model_dump(mode="json"))
    return write_report(Path(out_dir) / "summary.md", summary_markdown(summary, figure), raw)
