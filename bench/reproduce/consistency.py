"""``swarmloc reproduce consistency``: is the cooperative filter consistent, and does cooperating pay?

A filter is consistent when its errors are as large as its covariance says: the position
NEES eᵀ P_pp⁻¹ e (e the posterior position error, P_pp the filter's position covariance) is
χ² with 3 degrees of freedom, mean 3 (Bar-Shalom, Li and Kirubarajan, *Estimation with
Applications to Tracking and Navigation*, 2001, §5.4). A filter that counts a neighbour's
information again at every step reports a covariance far below its errors (mean NEES in the
hundreds on the v1 tasks), and then fusing peers can be worse than ignoring them.

For one task of every simulated family (the family's base task; AnchorFree is left out: with no
absolute reference its position is defined only up to a gauge, so a NEES of its absolute
positions means nothing), with its faults on (as registered) and with every fault removed
(``Faults()``: no NLOS, no IMU or GPS fault, no heavy-tailed noise, no vision outage), and for
each peer update of the CEKF (``FilterSettings.peer_update``: ``point``, the papers' and v1's;
``ci``; ``split_ci``, the v2 default), on the same dev-seed episodes:

- ``uniform`` (trust 1 on every channel): mean and median NEES over every UAV and update,
  and its RMSE (the runner's metric: the scored UAVs and interval);
- ``non-cooperative`` (trust 0 on the peer channels, 1 elsewhere): its RMSE, the shortcut a
  cooperative filter must beat.

Plus the Scale family's swarm sizes N = 2 … 32 with the faults removed. The JSON's ``rows`` have
one entry per (task, faults, peer update, method): ``task``, ``peer_update``, ``faults``
(``"on"``/``"off"``), ``method``, ``nees_mean``, ``nees_median`` (None for ``non-cooperative``, whose
NEES is not the question), ``rmse``, ``default`` (the row's update is the v2 default).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from swarmloc.agents.registry import load_method
from swarmloc.bench.evaluation.episode import EpisodeBatch, StepRecord, fly_episodes
from swarmloc.bench.evaluation.recorder import MetricsObserver
from swarmloc.bench.reproduce.common import write_paper_report
from swarmloc.envs.tasks.catalogue import get_spec
from swarmloc.envs.tasks.seeds import DEV_SEED_START
from swarmloc.envs.tasks.specs import Faults

#: one task per simulated family with absolute references (its base task)
FAMILY_TASKS: tuple[str, ...] = (
    "swarmloc/Ideal-v1", "swarmloc/NLOS-v1", "swarmloc/NLOSStep-v1", "swarmloc/Scale8-v1",
    "swarmloc/CascadedFault-v1", "swarmloc/VisionLoss-v1", "swarmloc/Indoor-v1", "swarmloc/HybridNoise30-v1",
    "swarmloc/GradualFault-v1", "swarmloc/TDOA-v1",
)
#: the Scale family's swarm sizes, measured with the faults removed
SCALE_SIZES: tuple[int, ...] = (2, 4, 6, 8, 16, 32)
UPDATES: tuple[str, ...] = ("point", "ci", "split_ci")
#: the peer update every v2 task fuses its peers with
V2_DEFAULT_UPDATE = "split_ci"
METHODS: tuple[str, ...] = ("uniform", "non-cooperative")
#: a consistent filter's mean NEES lies in this range (the issue's band around 3)
NEES_RANGE = (1.5, 4.5)
#: non-cooperative "no better than uniform": its RMSE at least this × uniform's
NO_BETTER = 0.98


class NeesObserver:
    """Posterior position NEES eᵀ P_pp⁻¹ e of every UAV at every update (a ``StepObserver``)."""

    def __init__(self) -> None:
        self.values: list[np.ndarray] = []

    def begin(self, batch: EpisodeBatch) -> None:
        """Start a batch (drops what an earlier batch left)."""
        self.values = []

    def observe(self, r: StepRecord) -> None:
        """The NEES of update ``r.k`` (the method must report its covariance)."""
        if r.covariance is None:
            raise ValueError("the NEES needs the method's position covariance; this method reports none")
        e = r.estimate - r.truth
        self.values.append(np.einsum("bni,bni->bn", e, np.linalg.solve(r.covariance, e[..., None])[..., 0]))

    def summary(self) -> tuple[float, float]:
        """(mean, median) over every episode, UAV and update."""
        v = np.concatenate([a.ravel() for a in self.values])
        return float(np.mean(v)), float(np.median(v))


def measure(task: str, faults: str, update: str, seeds: Sequence[int], duration: float | None = None,
            label: str | None = None) -> list[dict]:
    """The rows of one task, faults setting and peer update: ``uniform`` with its NEES, ``non-cooperative``."""
    over: dict = {"filter": {"peer_update": update}}
    if faults == "off":
        over["faults"] = Faults().model_dump()
    if duration:
        over["duration"] = duration
    spec = get_spec(task, **over)
    rows = []
    for method in METHODS:
        metrics, nees = MetricsObserver(), NeesObserver()
        fly_episodes(load_method(method, version=spec.version), spec, seeds,
                     [metrics, nees] if method == "uniform" else [metrics])
        rmse = float(np.mean([m["rmse"] for m in metrics.episode_metrics()]))
        mean, median = nees.summary() if method == "uniform" else (None, None)
        rows.append({"task": label or task, "peer_update": update, "faults": faults, "method": method,
                     "nees_mean": mean, "nees_median": median, "rmse": rmse, "default": update == V2_DEFAULT_UPDATE})
    return rows


def _num(v: float | None) -> str:
    if v is None:
        return "—"
    return f"{v:.2f}" if v < 100 else f"{v:.0f}"


def _index(rows: list[dict]) -> dict[tuple[str, str, str, str], dict]:
    return {(r["task"], r["faults"], r["peer_update"], r["method"]): r for r in rows}


def _table(rows: list[dict], tasks: list[str], faults: str) -> list[str]:
    """One line per task: uniform's mean (median) NEES and RMSE under each update, and non-cooperative's RMSE."""
    at = _index(rows)
    head = ("| task | " + " | ".join(f"NEES `{u}`" for u in UPDATES) + " | " + " | ".join(f"RMSE `{u}`" for u in UPDATES)
            + f" | non-coop. RMSE (`{V2_DEFAULT_UPDATE}`) | non-coop. / uniform |")
    lines = [head, "|---|" + "---:|" * (2 * len(UPDATES) + 2)]
    for t in tasks:
        uni = [at[(t, faults, u, "uniform")] for u in UPDATES]
        nc = at[(t, faults, V2_DEFAULT_UPDATE, "non-cooperative")]
        ref = at[(t, faults, V2_DEFAULT_UPDATE, "uniform")]
        nees = [f"{_num(r['nees_mean'])} ({_num(r['nees_median'])})" for r in uni]
        lines.append(f"| {t.removeprefix('swarmloc/')} | " + " | ".join(nees) + " | "
                     + " | ".join(f"{r['rmse']:.3f}" for r in uni) + f" | {nc['rmse']:.3f} | {nc['rmse'] / ref['rmse']:.2f} |")
    return lines


def verdict(rows: list[dict]) -> dict:
    """The v2 default update, faults off: the tasks whose uniform NEES leaves ``NEES_RANGE`` and those where
    ``non-cooperative`` beats uniform (RMSE below ``NO_BETTER`` × uniform's)."""
    at = _index(rows)
    off = [r for r in rows if r["default"] and r["faults"] == "off" and r["method"] == "uniform"]
    lo, hi = NEES_RANGE
    return {"tasks": len(off),
            "nees_outside": [r["task"] for r in off if not lo <= r["nees_mean"] <= hi],
            "non_cooperative_better": [
                r["task"] for r in off
                if at[(r["task"], "off", r["peer_update"], "non-cooperative")]["rmse"] < NO_BETTER * r["rmse"]]}


def render(rows: list[dict], seeds: Sequence[int]) -> str:
    """The markdown report."""
    family = [t for t in FAMILY_TASKS if any(r["task"] == t for r in rows)]
    scale = [f"swarmloc/Scale{n}-v1" for n in SCALE_SIZES if any(r["task"] == f"swarmloc/Scale{n}-v1" for r in rows)]
    v = verdict(rows)
    lo, hi = NEES_RANGE
    lines = [
        "# Consistency of the cooperative filter, and what cooperating pays", "",
        f"Uniform trust's posterior position NEES (mean, median in brackets; 3 for a consistent filter) and RMSE [m] "
        f"under each peer update of the CEKF, beside the RMSE of `non-cooperative` (peers dropped), on "
        f"{len(seeds)} dev seeds ({seeds[0]} …). `point` is the papers' and v1's update, `{V2_DEFAULT_UPDATE}` the "
        "v2 default (docs/world.md, \"The peer update\"). Faults off: the task with `faults=Faults()` (no "
        "NLOS, no IMU/GPS fault, no heavy tail, no vision outage). AnchorFree is left out (no absolute "
        "reference: its positions are defined up to a gauge).", "",
        f"**v2 default, faults off**: {v['tasks']} tasks; uniform's mean NEES outside [{lo}, {hi}] on "
        f"{len(v['nees_outside'])} ({', '.join(t.removeprefix('swarmloc/') for t in v['nees_outside']) or 'none'}); "
        f"`non-cooperative` better than uniform by more than {round((1 - NO_BETTER) * 100)} % on "
        f"{len(v['non_cooperative_better'])} "
        f"({', '.join(t.removeprefix('swarmloc/') for t in v['non_cooperative_better']) or 'none'}).", "",
        "## Faults removed", ""]
    lines += _table(rows, family, "off")
    lines += ["", "## Faults on (as registered)", ""]
    lines += _table(rows, family, "on")
    if scale:
        lines += ["", "## Scale, N = 2 … 32, faults removed", ""]
        lines += _table(rows, scale, "off")
    return "\n".join(lines) + "\n"


def reproduce_consistency(out: Path, seeds: int = 8, tasks: Sequence[str] | None = None,
                          duration: float | None = None, scale: bool = True) -> Path:
    """Measure and write ``<out>`` (``consistency.md``, and ``consistency.json`` beside it); returns its path.

    Args:
        out: a markdown file or a folder.
        seeds: dev seeds per task (2_000_000 …), at least 2.
        tasks: the family tasks (default ``FAMILY_TASKS``).
        duration: cut every episode to this many seconds (tests).
        scale: also the Scale sizes ``SCALE_SIZES``, faults removed.
    """
    if seeds < 2:
        raise ValueError(f"seeds must be at least 2, got {seeds}")
    chosen = [get_spec(t).task_id for t in (tasks or FAMILY_TASKS)]
    S = list(range(DEV_SEED_START, DEV_SEED_START + seeds))
    rows: list[dict] = []
    for task in chosen:
        for faults in ("off", "on"):
            for update in UPDATES:
                rows += measure(task, faults, update, S, duration)
    if scale:
        for n in SCALE_SIZES:
            task = f"swarmloc/Scale{n}-v1"
            if task in chosen:
                continue
            for update in UPDATES:
                rows += measure(task, "off", update, S, duration)
    return write_paper_report(out, "consistency", render(rows, S), {"seeds": S, "rows": rows, "verdict": verdict(rows)})


__all__ = ["FAMILY_TASKS", "METHODS", "NEES_RANGE", "NeesObserver", "SCALE_SIZES", "UPDATES", "V2_DEFAULT_UPDATE",
           "measure", "render", "reproduce_consistency", "verdict"]
