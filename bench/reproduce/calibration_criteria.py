"""The calibration criteria of the v1 tasks, as pure functions of per-seed numbers.

Every v1 task must pass five criteria (``swarmloc reproduce calibration`` reports them,
``swarmloc.bench.reproduce.calibration`` feeds them):

1. **ceiling valid** — no method's task-mean RMSE is below the task-mean information bound
   (``bound_rmse``) beyond its CI, and the privileged oracle is no worse than any
   non-privileged method within CI (both on paired per-seed differences, 95 % bootstrap);
2. **the fault matters** (fault tasks) — uniform ≥ 2× the bound (task means);
3. **headroom** — single-step gating (``chi2-soft``, ``chi2-gate``) closes ≤ 70 % of the
   achievable gap (the score, ``swarmloc.bench.scoring.score``), on at least half of the
   fault tasks;
4. **the paper's phenomenon** — one row per family (``calibration_phenomena``);
5. **nothing degenerate** — ``random`` trust ≥ 10 % worse (RMSE) than the best method.

Each criterion returns ``{"pass": bool | None, "measured": str, ...numbers}``; ``pass`` is
None where the criterion does not apply or cannot be computed (the ``measured`` text says
why). Thresholds are the module's constants.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from typing import Any

import numpy as np

from swarmloc.bench.scoring.score import suite_score
from swarmloc.bench.scoring.stats import bootstrap_ci
from swarmloc.bench.reproduce.common import paired

#: criterion 2: uniform at least this many times the bound on a fault task
FAULT_MATTERS_RATIO = 2.0
#: criterion 3: single-step gating closes at most this fraction of the achievable gap …
GAP_CLOSED_MAX = 0.70
#: … on at least this fraction of the fault tasks
HEADROOM_TASK_FRACTION = 0.5
#: criterion 3's single-step gating methods
GATING = ("chi2-soft", "chi2-gate")
#: criterion 5: random at least this many times the best method's RMSE
RANDOM_MIN_RATIO = 1.10
RANDOM = "random"

Verdict = dict[str, Any]


def mean_ci(values: Sequence[float] | np.ndarray) -> dict[str, Any]:
    """Mean and 95 % percentile-bootstrap CI (``stats.bootstrap_ci``) of per-seed values."""
    x = np.asarray(values, dtype=float)
    lo, hi = bootstrap_ci(x)
    return {"mean": float(x.mean()), "ci": [lo, hi], "n": int(x.size)}


def means(rmse: Mapping[str, np.ndarray]) -> dict[str, float]:
    """Task-mean RMSE of every method."""
    return {m: float(np.mean(v)) for m, v in rmse.items()}


def best_of(rmse: Mapping[str, np.ndarray], exclude: Collection[str] = ()) -> str | None:
    """The method with the lowest task-mean RMSE, ``exclude`` left out (None if none is left)."""
    m = {k: v for k, v in means(rmse).items() if k not in exclude}
    return min(m, key=m.get) if m else None


# --------------------------------------------------------------------------- criterion 1


def ceiling_valid(rmse: Mapping[str, np.ndarray], bound: np.ndarray | None, privileged: Collection[str],
                  oracle: str = "oracle") -> Verdict:
    """Criterion 1: nothing beats the bound, and the oracle is the best trust policy, within CI.

    Args:
        rmse: method → ``(n,)`` per-seed RMSE (the same seeds for every method).
        bound: ``(n,)`` per-seed ``bound_rmse``, or None where the bound is undefined.
        privileged: the privileged methods (never compared with the oracle).
        oracle: the privileged ceiling of the trust policies.

    Returns:
        ``below_bound``: methods whose paired RMSE − bound has its 95 % CI below 0;
        ``oracle_worse_than``: methods the oracle is worse than (paired CI of oracle − m above 0);
        ``min_ratio`` / ``min_ratio_method``: the lowest task-mean RMSE over the bound's mean;
        ``pass``: both lists empty (the bound half is skipped where the bound is undefined).
    """
    below, ratio_m, ratio = [], None, None
    if bound is not None:
        for m, v in rmse.items():
            if paired(v, bound, f"{m} < bound")["significant"]:
                below.append(m)
        ratios = {m: float(np.mean(v) / np.mean(bound)) for m, v in rmse.items()}
        ratio_m = min(ratios, key=ratios.get)
        ratio = ratios[ratio_m]
    worse: list[str] = []
    if oracle in rmse:
        worse = [m for m, v in rmse.items() if m not in privileged and m != oracle
                 and paired(rmse[oracle], v, f"{oracle} < {m}")["contradicted"]]
    parts = []
    if bound is None:
        parts.append("no bound")
    else:
        parts.append(f"min RMSE/bound {ratio:.2f} ({ratio_m})")
        parts += [f"below bound: {', '.join(below)}"] if below else []
    if oracle not in rmse:
        parts.append("no oracle")
    elif worse:
        parts.append(f"oracle worse than {', '.join(worse)}")
    return {"pass": not below and not worse, "measured": "; ".join(parts), "below_bound": below,
            "oracle_worse_than": worse, "min_ratio": ratio, "min_ratio_method": ratio_m}


# --------------------------------------------------------------------------- criterion 2


def fault_matters(uniform: np.ndarray, bound: np.ndarray | None, fault_task: bool) -> Verdict:
    """Criterion 2: on a fault task, uniform's task mean ≥ ``FAULT_MATTERS_RATIO`` × the bound's."""
    if not fault_task:
        return {"pass": None, "measured": "no fault", "ratio": None}
    if bound is None:
        return {"pass": None, "measured": "no bound", "ratio": None}
    ratio = float(np.mean(uniform) / np.mean(bound))
    return {"pass": ratio >= FAULT_MATTERS_RATIO, "measured": f"uniform/bound {ratio:.2f}", "ratio": ratio}


# --------------------------------------------------------------------------- criterion 3


def gap_closed(task: str, metrics: Sequence[Mapping[str, Any]]) -> dict[str, float | None]:
    """The score of one method on one task: ``G_t``, ``A_t`` and the gap closed ``G_t / A_t``.

    Args:
        task: the task ID.
        metrics: per-seed metric dicts (``rmse``, ``uniform_rmse``, ``bound_rmse``).

    Returns:
        ``{"gain", "achievable", "gap_closed"}`` (None where the score leaves them undefined).
    """
    s = suite_score([{"task": task, "seed": i, "metrics": m} for i, m in enumerate(metrics)], [task])
    t = s.tasks.get(task) if s is not None else None
    if t is None:
        return {"gain": None, "achievable": None, "gap_closed": None}
    return {"gain": t.mean, "achievable": t.achievable, "gap_closed": t.gap_closed}


def headroom(task: str, episodes: Mapping[str, Sequence[Mapping[str, Any]]], fault_task: bool) -> Verdict:
    """Criterion 3 on one task: every gating method closes ≤ ``GAP_CLOSED_MAX`` of the gap.

    A fault task without a gap (``A_t`` < log2 1.25) has no headroom: it fails; one without a
    bound is not judged.

    Args:
        task: the task ID.
        episodes: method → per-seed metric dicts.
        fault_task: the task has faults (criterion 3 is judged on fault tasks only).
    """
    closed = {m: gap_closed(task, episodes[m]) for m in GATING if m in episodes}
    values = {m: c["gap_closed"] for m, c in closed.items()}
    achievable = next((c["achievable"] for c in closed.values() if c["achievable"] is not None), None)
    text = ", ".join(f"{m} {'—' if v is None else f'{v:.2f}'}" for m, v in values.items()) or "no gating method"
    if values and achievable is None:
        text += " (no bound)"
    if not fault_task or not values or achievable is None:  # not judged: no fault, no gating run, or no bound
        return {"pass": None, "measured": text, "gap_closed": values, "achievable": achievable}
    if any(v is None for v in values.values()):
        return {"pass": False, "measured": text + " (no gap)", "gap_closed": values, "achievable": achievable}
    return {"pass": max(values.values()) <= GAP_CLOSED_MAX, "measured": text, "gap_closed": values,
            "achievable": achievable}


def headroom_overall(verdicts: Sequence[Verdict]) -> Verdict:
    """Criterion 3 over the suite: it holds on at least ``HEADROOM_TASK_FRACTION`` of the fault tasks.

    Args:
        verdicts: the per-task ``headroom`` verdicts of the fault tasks (``pass`` None: not judged).
    """
    judged = [v for v in verdicts if v["pass"] is not None]
    held = sum(bool(v["pass"]) for v in judged)
    if not judged:
        return {"pass": None, "measured": "no fault task", "held": 0, "judged": 0}
    ok = held >= HEADROOM_TASK_FRACTION * len(judged)
    return {"pass": ok, "measured": f"{held}/{len(judged)} fault tasks", "held": held, "judged": len(judged)}


# --------------------------------------------------------------------------- criterion 5


def not_degenerate(rmse: Mapping[str, np.ndarray]) -> Verdict:
    """Criterion 5: ``random``'s task mean ≥ ``RANDOM_MIN_RATIO`` × the best other method's."""
    best = best_of(rmse, exclude=(RANDOM,))
    if RANDOM not in rmse or best is None:
        return {"pass": None, "measured": "random not run", "ratio": None, "best": best}
    ratio = float(np.mean(rmse[RANDOM]) / np.mean(rmse[best]))
    return {"pass": ratio >= RANDOM_MIN_RATIO, "measured": f"random/{best} {ratio:.2f}", "ratio": ratio,
            "best": best}


# --------------------------------------------------------------------------- beside the criteria

#: the shortcut probe: a constant rule by channel kind that detects nothing (every peer channel skipped)
KIND_RULE = "non-cooperative"


def kind_rule(rmse: Mapping[str, np.ndarray], oracle: str = "oracle", probe: str = KIND_RULE) -> Verdict | None:
    """How the kind rule ``probe`` stands against the oracle: per seed d = log2(RMSE_oracle / RMSE_probe).

    Not a criterion: where the rule is level with the oracle (the 95 % CI of the mean of d
    contains 0) the task's gain is there for a method that drops a channel kind without
    finding a faulty link; where it is above (CI above 0) the oracle is not the ceiling of
    the trust policies, which criterion 1 also reports.

    Returns:
        ``{"position": "above" | "level" | "below", "log2": mean d, "ci": [lo, hi], "measured"}``,
        or None when either method did not run.
    """
    if probe not in rmse or oracle not in rmse:
        return None
    d = np.log2(np.asarray(rmse[oracle], dtype=float) / np.asarray(rmse[probe], dtype=float))
    lo, hi = bootstrap_ci(d)
    position = "above" if lo > 0 else "below" if hi < 0 else "level"
    return {"position": position, "log2": float(d.mean()), "ci": [lo, hi],
            "measured": f"{probe} vs {oracle} {d.mean():+.3f} log2 [{lo:+.3f}, {hi:+.3f}]"}


__all__ = ["FAULT_MATTERS_RATIO", "GAP_CLOSED_MAX", "GATING", "HEADROOM_TASK_FRACTION", "KIND_RULE",
           "RANDOM_MIN_RATIO", "best_of", "ceiling_valid", "fault_matters", "gap_closed", "headroom",
           "headroom_overall", "kind_rule", "mean_ci", "means", "not_degenerate"]
