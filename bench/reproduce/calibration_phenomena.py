"""Criterion 4 of the v1 calibration: the paper's phenomenon of each task family.

One function per family returns ``{"measured": str, "pass": bool | None}`` from a task's
:class:`Evidence` (``pass`` None: reported, not judged). ``PHENOMENA`` maps a task's base
name (``swarmloc.bench.scoring.families.task_base``: ``NLOSStep`` is its own row) to its
target and function; Scale is judged across the family's tasks (:func:`scale_phenomenon`).
A task whose base has no row reports "—".

| base | target (source) |
|---|---|
| Ideal | control, no faults: uniform ≤ 1.3× the bound |
| NLOS | biases across the detectability range, several links at once (reported: uniform/oracle, ≥ 2 faulty links) |
| NLOSStep | uniform fault RMSE 2–5 m (madrl Table 5: 3.09) |
| Scale | uniform Scale8/Scale2 ≥ 1.4 and Scale32 ≥ Scale8 (madrl Table 4: 1.56); oracle flat, max/min ≤ 1.15 |
| CascadedFault | uniform healthy-node peak error ≥ 10 m (madrl Table 6: 121.7); faulty nodes' recovery time |
| VisionLoss | outage RMSE ≥ 2× outside it; CEKF RMSE 0.3–0.8 m (pf-nn Table 3: 0.61–0.69) |
| Indoor | CEKF RMSE 0.3–0.8 m (pf-nn Table 3) |
| HybridNoise | imm-arkf < imm-kf, paired 95 % CI below 0 (imm-arkf Table 2) |
| GradualFault | uniform fault RMSE ≥ 2× the bound over the fault window; FDI better than uniform (federated Table 3) |
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from itertools import pairwise
from typing import Any

import numpy as np

from swarmloc.bench.scoring import metrics as M
from swarmloc.bench.evaluation.traces import Trace
from swarmloc.bench.reproduce.calibration_criteria import best_of
from swarmloc.bench.reproduce.common import paired
from swarmloc.envs.tasks.specs import TaskSpec

IDEAL_MAX_RATIO = 1.3
NLOS_STEP_FAULT_RMSE = (2.0, 5.0)
SCALE_MIN_GROWTH = 1.4
ORACLE_FLAT_MAX = 1.15
CASCADED_MIN_PEAK_M = 10.0
OUTAGE_MIN_RATIO = 2.0
CEKF_RMSE = (0.3, 0.8)
GRADUAL_MIN_RATIO = 2.0
#: the classical fault detection and isolation methods of the GradualFault row
FDI = ("federated-coef", "chi2-gate", "chi2-soft")

Phenomenon = dict[str, Any]


@dataclass(frozen=True)
class Evidence:
    """What one task's calibration reads.

    Attributes:
        task: task ID; spec: its spec (as evaluated); seeds: the seeds, in order.
        episodes: method → per-seed metric dicts (only methods that ran on every seed).
        privileged: the privileged methods among them.
        uniform_traces: per-seed traces of ``uniform`` (only for the tasks whose phenomenon reads them).
        healthy_nodes: per seed, ``(N,)`` bool healthy UAVs (IMU-cascade tasks), aligned with the traces.
        window_bound: ``(n,)`` the bound over the fault window per seed [m] (GradualFault), or None.
    """

    task: str
    spec: TaskSpec
    seeds: tuple[int, ...]
    episodes: Mapping[str, Sequence[Mapping[str, Any]]]
    privileged: frozenset[str] = frozenset()
    uniform_traces: Sequence[Trace] = ()
    healthy_nodes: Sequence[np.ndarray] = ()
    window_bound: np.ndarray | None = None

    def values(self, method: str, metric: str = "rmse") -> np.ndarray | None:
        """``(n,)`` per-seed values of a metric, or None when the method did not run or a seed lacks it."""
        rows = self.episodes.get(method)
        if rows is None or any(r.get(metric) is None for r in rows):
            return None
        return np.array([r[metric] for r in rows], dtype=float)

    @property
    def rmse(self) -> dict[str, np.ndarray]:
        """Method → per-seed RMSE."""
        return {m: v for m in self.episodes if (v := self.values(m)) is not None}

    @property
    def bound(self) -> np.ndarray | None:
        """Per-seed ``bound_rmse`` (None where the bound is undefined on some seed)."""
        return self.values("uniform", "bound_rmse")


def _within(x: float, low_high: tuple[float, float]) -> bool:
    return low_high[0] <= x <= low_high[1]


def _missing(*what: str) -> Phenomenon:
    return {"measured": f"needs {', '.join(what)}", "pass": None}


# --------------------------------------------------------------------------- one task


def ideal(ev: Evidence) -> Phenomenon:
    """Uniform within ``IDEAL_MAX_RATIO`` × the bound (task means)."""
    u, b = ev.values("uniform"), ev.bound
    if u is None or b is None:
        return _missing("uniform", "the bound")
    r = float(u.mean() / b.mean())
    return {"measured": f"uniform/bound {r:.2f}", "pass": r <= IDEAL_MAX_RATIO, "ratio": r}


def nlos(ev: Evidence) -> Phenomenon:
    """Reported only: uniform/oracle and the fraction of scored steps where ≥ 2 channels of the scored UAVs
    carry an injected fault (the fault labels of uniform's traces), averaged over the seeds."""
    u, o = ev.values("uniform"), ev.values("oracle")
    parts = [] if u is None or o is None else [f"uniform/oracle {u.mean() / o.mean():.1f}"]
    frac = None
    if ev.uniform_traces:
        steps = ev.spec.dt * np.arange(1, ev.spec.n_steps + 1) >= ev.spec.scoring.start - 1e-9
        per_seed = []
        for tr in ev.uniform_traces:
            labelled = (tr.label & tr.valid)[:, tr.scored].reshape(tr.label.shape[0], -1).sum(axis=1)
            per_seed.append(float((labelled[steps] >= 2).mean()))
        frac = float(np.mean(per_seed))
        parts.append(f"steps with ≥2 faulty links {frac:.0%}")
    return {"measured": "; ".join(parts) or "—", "pass": None, "multi_link_fraction": frac}


def nlos_step(ev: Evidence) -> Phenomenon:
    """Uniform's fault-window RMSE in ``NLOS_STEP_FAULT_RMSE``."""
    f = ev.values("uniform", "fault_rmse")
    if f is None:
        return _missing("uniform fault_rmse")
    return {"measured": f"uniform fault RMSE {f.mean():.2f} m", "pass": _within(float(f.mean()), NLOS_STEP_FAULT_RMSE),
            "fault_rmse": float(f.mean())}


def cascaded(ev: Evidence) -> Phenomenon:
    """Uniform's peak healthy-node error ≥ ``CASCADED_MIN_PEAK_M`` (mean over seeds of each episode's peak
    over the scored steps); the faulty nodes' ``recovery_s`` reported where the metric exists."""
    if not ev.uniform_traces or len(ev.healthy_nodes) != len(ev.uniform_traces):
        return _missing("uniform traces")
    peaks = []
    for tr, healthy in zip(ev.uniform_traces, ev.healthy_nodes):
        steps = tr.times >= ev.spec.scoring.start - 1e-9
        peaks.append(float(tr.errors[steps][:, healthy].max()))
    peak = float(np.mean(peaks))
    out = {"measured": f"uniform healthy peak {peak:.1f} m (min {min(peaks):.1f})",
           "pass": peak >= CASCADED_MIN_PEAK_M, "healthy_peak": peak, "healthy_peaks": peaks, "recovery_s": None}
    rec = ev.values("uniform", "recovery_s")
    if rec is not None:
        out["recovery_s"] = float(rec.mean())
        out["measured"] += f"; faulty recovery {rec.mean():.1f} s"
    return out


def outside_window_rmse(rmse: np.ndarray, fault: np.ndarray, spec: TaskSpec) -> np.ndarray:
    """Per-seed RMSE of the scored steps outside ``scoring.fault_window``, from ``rmse`` and ``fault_rmse``.

    Every scored step weighs the same, so ``rmse² · n = fault² · n_in + outside² · n_out``
    (n_in, n_out: scored steps inside and outside the window).
    """
    times = spec.dt * np.arange(1, spec.n_steps + 1)
    scored = times >= spec.scoring.start - 1e-9
    n_in = int((M.window_steps(times, spec.scoring.fault_window) & scored).sum())
    n = int(scored.sum())
    if n_in == n:
        raise ValueError(f"{spec.task_id}: every scored step is inside the fault window; nothing is outside it")
    return np.sqrt(np.maximum(rmse**2 * n - fault**2 * n_in, 0.0) / (n - n_in))


def vision_loss(ev: Evidence) -> Phenomenon:
    """Outage RMSE ≥ ``OUTAGE_MIN_RATIO`` × the RMSE outside it (task means), and uniform RMSE in ``CEKF_RMSE``.

    "Outside" is every scored step outside ``scoring.fault_window``, so it includes any other
    outage window of the task (which makes the ratio smaller, not larger).
    """
    u, f = ev.values("uniform"), ev.values("uniform", "fault_rmse")
    if u is None or f is None or ev.spec.scoring.fault_window is None:
        return _missing("uniform fault_rmse and a fault window")
    out = outside_window_rmse(u, f, ev.spec)
    ratio = float(f.mean() / out.mean())
    ok = ratio >= OUTAGE_MIN_RATIO and _within(float(u.mean()), CEKF_RMSE)
    return {"measured": f"outage/outside {ratio:.2f}; uniform {u.mean():.2f} m", "pass": ok, "ratio": ratio,
            "uniform_rmse": float(u.mean()), "outside_rmse": float(out.mean())}


def indoor(ev: Evidence) -> Phenomenon:
    """Uniform RMSE in ``CEKF_RMSE``."""
    u = ev.values("uniform")
    if u is None:
        return _missing("uniform")
    return {"measured": f"uniform {u.mean():.2f} m", "pass": _within(float(u.mean()), CEKF_RMSE),
            "uniform_rmse": float(u.mean())}


def hybrid_noise(ev: Evidence) -> Phenomenon:
    """imm-arkf < imm-kf with the paired 95 % CI of the difference below 0."""
    a, k = ev.values("imm-arkf"), ev.values("imm-kf")
    if a is None or k is None:
        return _missing("imm-arkf", "imm-kf")
    d = paired(a, k, "imm-arkf < imm-kf")
    return {"measured": f"imm-arkf − imm-kf {d['mean_diff']:+.3f} m [{d['ci'][0]:+.3f}, {d['ci'][1]:+.3f}]",
            "pass": d["significant"], "paired": d}


def gradual_fault(ev: Evidence) -> Phenomenon:
    """Uniform fault RMSE ≥ ``GRADUAL_MIN_RATIO`` × the bound over the fault window, and the best of ``FDI``
    better than uniform (paired 95 % CI of its RMSE − uniform's below 0).

    Without a window bound (``Evidence.window_bound``) the episode's ``bound_rmse`` stands in, as said.
    """
    u, f = ev.values("uniform"), ev.values("uniform", "fault_rmse")
    if u is None or f is None:
        return _missing("uniform fault_rmse")
    bound, over = ev.window_bound, "window"
    if bound is None:
        bound, over = ev.bound, "episode"
    if bound is None:
        return _missing("the bound")
    ratio = float(f.mean() / bound.mean())
    fdi = {m: v for m, v in ev.rmse.items() if m in FDI}
    best = best_of(fdi)
    if best is None:
        return {"measured": f"fault RMSE/bound ({over}) {ratio:.2f}; no FDI method", "pass": None, "ratio": ratio}
    d = paired(fdi[best], u, f"{best} < uniform")
    return {"measured": f"fault RMSE/bound ({over}) {ratio:.2f}; {best} − uniform {d['mean_diff']:+.3f} m "
                        f"[{d['ci'][0]:+.3f}, {d['ci'][1]:+.3f}]",
            "pass": ratio >= GRADUAL_MIN_RATIO and d["significant"], "ratio": ratio, "bound_over": over,
            "fdi": best, "paired": d}


#: base name → (target, function); Scale is judged across its tasks (``scale_phenomenon``)
PHENOMENA: dict[str, tuple[str, Callable[[Evidence], Phenomenon] | None]] = {
    "Ideal": (f"uniform ≤ {IDEAL_MAX_RATIO:g}× bound", ideal),
    "NLOS": ("biases across the detectability range, several links at once (reported)", nlos),
    "NLOSStep": (f"uniform fault RMSE {NLOS_STEP_FAULT_RMSE[0]:g}–{NLOS_STEP_FAULT_RMSE[1]:g} m "
                 "(madrl Table 5: 3.09)", nlos_step),
    "Scale": (f"uniform Scale8/Scale2 ≥ {SCALE_MIN_GROWTH:g}, Scale32 ≥ Scale8 (madrl Table 4: 1.56); "
              f"oracle max/min ≤ {ORACLE_FLAT_MAX:g}", None),
    "CascadedFault": (f"uniform healthy peak ≥ {CASCADED_MIN_PEAK_M:g} m (madrl Table 6: 121.7); recovery time",
                      cascaded),
    "VisionLoss": (f"outage ≥ {OUTAGE_MIN_RATIO:g}× outside; uniform {CEKF_RMSE[0]:g}–{CEKF_RMSE[1]:g} m "
                   "(pf-nn Table 3: 0.61–0.69)", vision_loss),
    "Indoor": (f"uniform {CEKF_RMSE[0]:g}–{CEKF_RMSE[1]:g} m (pf-nn Table 3)", indoor),
    "HybridNoise": ("imm-arkf < imm-kf, paired CI < 0 (imm-arkf Table 2)", hybrid_noise),
    "GradualFault": (f"uniform fault RMSE ≥ {GRADUAL_MIN_RATIO:g}× window bound; FDI beats uniform "
                     "(federated Table 3)", gradual_fault),
}
#: bases whose phenomenon also holds for the randomized variants (the rest report "—" there)
RANDOMIZED_TOO = ("CascadedFault",)


# --------------------------------------------------------------------------- across a family


def scale_phenomenon(uniform: Mapping[int, np.ndarray], oracle: Mapping[int, np.ndarray]) -> Phenomenon:
    """The Scale row across swarm sizes N.

    Args:
        uniform, oracle: N → per-seed RMSE of the fixed ``Scale<N>`` tasks.

    Returns:
        ``growth`` uniform(8)/uniform(2), ``rising`` uniform(32) ≥ uniform(8), ``monotone``
        uniform non-decreasing in N, ``oracle_spread`` oracle max/min over N; ``pass`` needs
        N = 2 and 8 (and 32 where present) and an oracle at every N.
    """
    u = {n: float(np.mean(v)) for n, v in sorted(uniform.items())}
    o = {n: float(np.mean(v)) for n, v in sorted(oracle.items())}
    if 2 not in u or 8 not in u:
        return {"measured": f"needs Scale2 and Scale8 (have N = {sorted(u)})", "pass": None}
    growth = u[8] / u[2]
    rising = u[32] >= u[8] if 32 in u else None
    values = list(u.values())
    monotone = all(b >= a for a, b in pairwise(values))
    spread = max(o.values()) / min(o.values()) if o else None
    text = f"uniform Scale8/Scale2 {growth:.2f}"
    text += "" if rising is None else f", Scale32/Scale8 {u[32] / u[8]:.2f}" + (" (monotone)" if monotone else "")
    text += "" if spread is None else f"; oracle max/min {spread:.2f}"
    ok = growth >= SCALE_MIN_GROWTH and rising is not False and spread is not None and spread <= ORACLE_FLAT_MAX
    return {"measured": text, "pass": ok, "growth": growth, "rising": rising, "monotone": monotone,
            "oracle_spread": spread, "uniform": u, "oracle": o}


__all__ = ["CASCADED_MIN_PEAK_M", "CEKF_RMSE", "FDI", "GRADUAL_MIN_RATIO", "IDEAL_MAX_RATIO", "NLOS_STEP_FAULT_RMSE",
           "ORACLE_FLAT_MAX", "OUTAGE_MIN_RATIO", "PHENOMENA", "RANDOMIZED_TOO", "SCALE_MIN_GROWTH", "Evidence",
           "outside_window_rmse", "scale_phenomenon"]
