"""``swarmloc reproduce peer-update``: the CEKF's peer update as registered, against covariance intersection.

Every registered task's CEKF fuses a peer measurement with the neighbour's broadcast prior
position taken as a known point (madrl §2.3, ``FilterSettings.peer_update = "point"``). A
UAV and its neighbour then count each other's information again at every step, and the
filters' covariances shrink below their errors. ``"ci"`` fuses the same measurement by
covariance intersection, which stays consistent whatever the correlation (``envs/filter/cekf.py``).

For each standard-v1 task with peer channels, the same test episodes under both updates:
the trust policies that probe a task's calibration (``uniform``, the privileged ``oracle``,
the shortcut probe ``non-cooperative``, the one-step gates ``chi2-gate`` and ``chi2-soft``)
and the information bound, which does not depend on the filter. Per task and filter:
- whether the oracle is a ceiling (criterion 1 of docs/calibration.md: no non-privileged
  policy better by a paired 95 % CI of log2 RMSE ratios),
- whether the fault matters (criterion 2: uniform ≥ 2× the bound),
- whether ``chi2-gate`` does worse than doing nothing (uniform), the lock-outs of
  docs/methods.md, "Where a gate locks out without a fault".
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from swarmloc.agents.registry import load_method
from swarmloc.bench.scoring.bounds import episode_bounds
from swarmloc.bench.evaluation.runner import rollout
from swarmloc.bench.evaluation.suites import STANDARD_V1_TASKS
from swarmloc.bench.reproduce import calibration_criteria as C
from swarmloc.bench.reproduce.common import seeds_from, write_paper_report
from swarmloc.envs.tasks.channels import PEER, PEER_REL, build_layout
from swarmloc.envs.tasks.specs import TaskSpec
from swarmloc.envs.tasks.catalogue import get_spec

#: the trust policies compared (the oracle is privileged; the others are not)
METHODS: tuple[str, ...] = ("uniform", "oracle", "non-cooperative", "chi2-gate", "chi2-soft")
UPDATES: tuple[str, ...] = ("point", "ci")
#: a gate locks out when its RMSE is at least this × uniform's
LOCK_OUT = 2.0
#: spec variants a consistent-filter benchmark could start from (not registered): label → (task, overrides).
#: Scale with anchors ranged within 11 m (outer UAVs then need their peers); HybridNoise without peers
#: (is its heavy tail a trust problem once the peers cannot mask it?).
VARIANTS: dict[str, tuple[str, dict]] = {
    **{f"Scale{n}-v1, anchors within 11 m": (f"swarmloc/Scale{n}-v1", {"sensors": {"anchor_max_range": 11.0}})
       for n in (2, 4, 8, 32)},
    **{f"HybridNoise{p}-v1, no peers": (f"swarmloc/HybridNoise{p}-v1", {"sensors": {"peers": {"kind": "none"}}})
       for p in (30, 50)},
}


def peer_tasks(tasks: Sequence[str] = STANDARD_V1_TASKS) -> list[str]:
    """The tasks among ``tasks`` whose UAVs have peer channels (ranges or relative positions)."""
    return [t for t in tasks if np.isin(build_layout(get_spec(t)).kind, (PEER, PEER_REL)).any()]


def _ceiling_beaten_by(rmse: dict[str, np.ndarray]) -> list[str]:
    """The non-privileged policies better than the oracle by a paired 95 % CI (log2 RMSE ratio)."""
    return [m for m in METHODS if m != "oracle" and C.kind_rule(rmse, probe=m)["position"] == "above"]


def measure_task(task: str, seeds: list[int], duration: float | None = None, overrides: dict | None = None,
                 label: str | None = None) -> dict:
    """RMSE per seed of every method under both updates, and the bound, on one task (with spec
    ``overrides``, its episodes cut to ``duration`` seconds if given)."""
    over = {**(overrides or {}), **({"duration": duration} if duration else {})}
    base = get_spec(task, **over)
    bound = np.array([b.rmse for b in episode_bounds(base, seeds)], dtype=float)
    row: dict = {"task": label or task, "bound": bound.tolist(), "rmse": {}}
    for update in UPDATES:
        spec: TaskSpec = base if update == "point" else get_spec(task, **{**over, "filter": {"peer_update": update}})
        rmse = {}
        for m in METHODS:
            metrics, _ = rollout(load_method(m, version=spec.version), spec, seeds)
            rmse[m] = np.array([e["rmse"] for e in metrics], dtype=float)
        row["rmse"][update] = {m: v.tolist() for m, v in rmse.items()}
        row[update] = {"ceiling_beaten_by": _ceiling_beaten_by(rmse),
                       "uniform_over_bound": float(rmse["uniform"].mean() / bound.mean()),
                       "gate_over_uniform": float(rmse["chi2-gate"].mean() / rmse["uniform"].mean())}
    return row


def _cell(values: list[float]) -> str:
    v = float(np.mean(values))
    return f"{v:.3f}" if v < 10 else f"{v:.1f}" if v < 100 else f"{v:.0f}"


def render(rows: list[dict], n_seeds: int, variants: Sequence[dict] = ()) -> str:
    """The markdown report: the registered tasks, then the ``VARIANTS`` measured (if any)."""
    lines = ["# The CEKF's peer update: a known point (registered) against covariance intersection", "",
             f"Standard-v1 tasks with peer channels, {n_seeds} test seeds each (1000000 …). RMSE [m], task "
             "mean; each cell is *point* / *ci* on the same episodes. `point` is the registered filter "
             "(madrl §2.3); `ci` is `get_spec(task, filter={\"peer_update\": \"ci\"})`. The bound does not "
             "depend on the filter.", ""]
    lines += _tables(rows)
    lines += _scale_lines(rows)
    if variants:
        lines += ["", "## Variants a consistent filter could start from (not registered)", "",
                  "The same measurements on spec variants of the registered tasks (`VARIANTS` in "
                  "`swarmloc.bench.reproduce.peer_update`): the Scale tasks with the anchors ranged within 11 m "
                  "(`sensors={\"anchor_max_range\": 11.0}`), the HybridNoise tasks without peer links "
                  "(`sensors={\"peers\": {\"kind\": \"none\"}}`; both updates are then the same filter).", ""]
        lines += _tables(list(variants))
    return "\n".join(lines) + "\n"


def _tables(rows: list[dict]) -> list[str]:
    """The RMSE table, the per-task verdicts and their counts."""
    lines = ["| task | bound | " + " | ".join(f"`{m}`" for m in METHODS) + " |",
             "|---|---:|" + "---:|" * len(METHODS)]
    for r in rows:
        cells = [f"{_cell(r['rmse']['point'][m])} / {_cell(r['rmse']['ci'][m])}" for m in METHODS]
        name = r["task"].removeprefix("swarmloc/")
        lines.append(f"| {name} | {np.mean(r['bound']):.3f} | " + " | ".join(cells) + " |")
    lines += ["", "What each filter makes of the task. Oracle beaten: the non-privileged policies better than the oracle by a paired 95 % CI "
              "(criterion 1 fails). uniform/bound ≥ 2: the fault matters (criterion 2). chi2-gate/uniform ≥ 2: "
              "the one-step gate locks channels out (docs/methods.md).", "",
              "| task | oracle beaten (point) | oracle beaten (ci) | uniform/bound point | ci | "
              "chi2-gate/uniform point | ci |", "|---|---|---|---:|---:|---:|---:|"]
    for r in rows:
        p, c = r["point"], r["ci"]
        lines.append(f"| {r['task'].removeprefix('swarmloc/')} | {', '.join(p['ceiling_beaten_by']) or '—'} "
                     f"| {', '.join(c['ceiling_beaten_by']) or '—'} | {p['uniform_over_bound']:.2f} "
                     f"| {c['uniform_over_bound']:.2f} | {p['gate_over_uniform']:.2f} | {c['gate_over_uniform']:.2f} |")
    count = {u: {"beaten": sum(bool(r[u]["ceiling_beaten_by"]) for r in rows),
                 "matters": sum(r[u]["uniform_over_bound"] >= C.FAULT_MATTERS_RATIO for r in rows),
                 "lock_out": sum(r[u]["gate_over_uniform"] >= LOCK_OUT for r in rows)} for u in UPDATES}
    lines += ["", "| filter | oracle beaten | uniform ≥ 2× bound | chi2-gate ≥ 2× uniform |",
              "|---|---:|---:|---:|"]
    for u in UPDATES:
        lines.append(f"| `{u}` | {count[u]['beaten']}/{len(rows)} | {count[u]['matters']}/{len(rows)} "
                     f"| {count[u]['lock_out']}/{len(rows)} |")
    return lines


def _scale_lines(rows: list[dict]) -> list[str]:
    """Uniform's growth with the swarm size under each filter (the Scale family's phenomenon,
    docs/calibration.md)."""
    by_n = {int(r["task"].removeprefix("swarmloc/Scale").removesuffix("-v1")): r for r in rows
            if r["task"].removeprefix("swarmloc/Scale").removesuffix("-v1").isdigit()}
    if len(by_n) < 2:
        return []
    ns = sorted(by_n)
    out = ["", f"Scale{ns[0]}…{ns[-1]}-v1, uniform's RMSE by swarm size N (the Scale phenomenon: it grows with N):", "",
           "| filter | " + " | ".join(f"N = {n}" for n in ns) + f" | N = {ns[-1]} / N = {ns[0]} |",
           "|---|" + "---:|" * (len(ns) + 1)]
    for u in UPDATES:
        v = [float(np.mean(by_n[n]["rmse"][u]["uniform"])) for n in ns]
        out.append(f"| `{u}` | " + " | ".join(f"{x:.3f}" for x in v) + f" | {v[-1] / v[0]:.2f} |")
    return out


def reproduce_peer_update(out: Path, seeds: int = 32, tasks: Sequence[str] | None = None,
                          duration: float | None = None, variants: bool = True) -> Path:
    """Measure and write ``<out>`` (markdown, + .json beside it); returns its path.

    ``tasks`` None: every standard-v1 task with peers; ``variants``: also the ``VARIANTS``.
    """
    chosen = peer_tasks() if tasks is None else [get_spec(t).task_id for t in tasks]
    S = seeds_from(seeds)
    rows = [measure_task(t, S, duration) for t in chosen]
    extra = [measure_task(t, S, duration, over, label) for label, (t, over) in VARIANTS.items()] if variants else []
    return write_paper_report(out, "peer-update", render(rows, len(S), extra),
                              {"seeds": S, "tasks": rows, "variants": extra})


__all__ = ["METHODS", "UPDATES", "VARIANTS", "measure_task", "peer_tasks", "render", "reproduce_peer_update"]
