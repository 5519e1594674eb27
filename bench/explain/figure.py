"""The madrl Figure 6 chain for one UAV: perception → decision → result, and why.

Four panels over time, the fault window shaded: (a) the innovation ‖y‖ of the attacked
channel and of a normal one; (b) the trust α the method gave both; (c) the UAV's
position error, with the reference method's (the standard CEKF) for comparison; (d) the
attributions of the attacked channel's trust, stacked by feature group (positive parts
up, negative down) with their sum α(x) − α(x̄). Drawn on a bare ``matplotlib.figure.Figure``
(no pyplot state, any backend).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from swarmloc.bench.common.files import atomic_path
from swarmloc.envs.tasks.channels import KIND_NAMES

from swarmloc.bench.explain.attributions import Explanation
from swarmloc.bench.explain.features import GROUP_NAMES
from swarmloc.bench.explain.report import fault_window


def pick_channels(ex: Explanation, uav: int | None = None) -> tuple[int, int, int]:
    """``(uav, attacked, normal)`` channel indices of episode 0 for the figure.

    The attacked channel is the explained channel with the most labelled steps (on
    ``uav``, or on the UAV that has the most); the normal one is the explained channel of
    the same UAV and kind with no label that is present most often (any kind if none).
    Without labels, the channel with the lowest mean trust stands in for the attacked one.

    Raises:
        ValueError: ``uav`` out of range, or fewer than two channels explained on it.
    """
    ep, explained = ex.episode, ex.attributions.explained
    n = explained.shape[0]
    if uav is not None and not 0 <= uav < n:
        raise ValueError(f"uav {uav} is out of range: {ep.spec.task_id} has UAVs 0 … {n - 1}")
    labels = np.where(explained, ep.label[:, 0].sum(axis=0), -1)  # (N, L)
    if labels.max() <= 0:
        labels = np.where(explained, -ex.attributions.trust[:, 0].mean(axis=0), -np.inf)
    i = int(np.argmax(labels.max(axis=1))) if uav is None else uav
    if explained[i].sum() < 2:
        raise ValueError(f"the figure needs two explained channels on UAV {i}; explained: "
                         f"{np.nonzero(explained[i])[0].tolist()}")
    attacked = int(np.argmax(labels[i]))
    never = explained[i] & ~ep.label[:, 0, i].any(axis=0)
    never[attacked] = False
    same = never & (ep.layout.kind[i] == ep.layout.kind[i, attacked])
    pool = same if same.any() else (never if never.any() else explained[i] & (np.arange(len(never)) != attacked))
    presence = np.where(pool, ep.valid[:, 0, i].sum(axis=0), -1)
    return i, attacked, int(np.argmax(presence))


def _channel_name(ex: Explanation, i: int, j: int) -> str:
    lay = ex.episode.layout
    return f"{KIND_NAMES[lay.kind[i, j]]} {lay.target[i, j]} (ch {j})"


def plot_chain(ex: Explanation, path: str | Path, uav: int | None = None) -> Path:
    """Draw the chain of episode 0 to a PNG (written atomically).

    Args:
        ex: the explanation.
        path: the image file.
        uav: the UAV to show (default: the one whose channel is attacked longest).

    Returns:
        The path written.
    """
    ep, attr = ex.episode, ex.attributions
    i, bad, good = pick_channels(ex, uav)
    t = ep.times
    fig = Figure(figsize=(12.5, 11), layout="constrained")
    axes = fig.subplots(4, 1, sharex=True, height_ratios=(1, 1, 1, 1.5))
    bad_name, good_name = _channel_name(ex, i, bad), _channel_name(ex, i, good)
    axes[0].plot(t, ep.resid[:, 0, i, good], color="0.55", lw=1.0, label=f"normal: {good_name}")
    axes[0].plot(t, ep.resid[:, 0, i, bad], color="tab:orange", lw=2.0, label=f"attacked: {bad_name}")
    axes[0].set_ylabel("innovation ‖y‖ [m]")
    axes[0].set_title("(a) perception: innovation of the attacked and a normal channel", loc="left")
    axes[1].plot(t, attr.trust[:, 0, i, good], color="0.55", lw=1.0, label=good_name)
    axes[1].plot(t, attr.trust[:, 0, i, bad], color="tab:orange", lw=2.0, label=bad_name)
    axes[1].set_ylim(-0.03, 1.05)
    axes[1].set_ylabel("trust α")
    axes[1].set_title(f"(b) decision: trust given by {ep.method}", loc="left")
    if ex.reference is not None:
        axes[2].plot(t, ex.reference.error[:, 0, i], color="tab:blue", ls="--", lw=1.2,
                     label=f"{ex.reference.method} (standard CEKF)" if ex.reference.method == "uniform"
                     else ex.reference.method)
    axes[2].plot(t, ep.error[:, 0, i], color="goldenrod", lw=1.6, label=ep.method)
    axes[2].set_ylabel("position error [m]")
    axes[2].set_title(f"(c) result: position error of UAV {i}", loc="left")
    grouped = attr.grouped()[:, 0, i, bad]  # (T, G)
    colors = [f"C{g}" for g in range(len(GROUP_NAMES))]
    axes[3].stackplot(t, np.clip(grouped, 0.0, None).T, colors=colors, labels=GROUP_NAMES, alpha=0.85)
    axes[3].stackplot(t, np.clip(grouped, None, 0.0).T, colors=colors, alpha=0.85)
    axes[3].plot(t, grouped.sum(axis=1), color="k", lw=1.0, label="sum = α(x) − α(x̄)")
    axes[3].axhline(0.0, color="k", lw=0.5)
    axes[3].set_ylabel("attribution to α")
    axes[3].set_title(f"(d) why: {attr.explainer} attributions of the attacked channel's α "
                      f"(baseline: {attr.baseline})", loc="left")
    axes[3].set_xlabel("time [s]")
    window = fault_window(ep)
    for ax in axes:
        if window is not None:
            ax.axvspan(*window, color="tab:red", alpha=0.08, lw=0)
        ax.grid(alpha=0.3)
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    fig.suptitle(f"{ep.method} on {ep.spec.task_id}, seed {int(ep.seeds[0])}"
                 + ("" if window is None else f" — fault window {window[0]:g}–{window[1]:g} s shaded"))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110)
    return path
