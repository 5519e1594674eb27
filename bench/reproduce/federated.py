"""``swarmloc reproduce federated``: federated Tables 2–3 on GradualFault (follower UAV 1, per axis).

``version`` picks the task: GradualFault-v1 (default; the paper's 3-axis drift, a 3 m GPS
and a UWB range + angle-of-arrival link) or the frozen GradualFault-v0.

Table 2 without the fault (``faults.gps_drifts = ()``) for Scheme 1 (GPS/IMU only),
Scheme 2 (``federated-fdi``) and the proposed filter (``federated``); Table 3 in the
drift window (100–200 s here, 500–600 s in the paper) for Scheme 2 and the proposed
filter; the ordering federated < federated-fdi inside the fault window, for the printed
sub-filter-2 noise (the registered default) and the consistent one
(``leader_cov_in_R=True``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from swarmloc.agents.estimators.federated import federated, federated_fdi, gps_ins
from swarmloc.bench.reproduce.common import (
    Factory,
    episode_errors,
    ordering_table,
    paired,
    runner_metrics,
    seeds_from,
    write_paper_report,
)
from swarmloc.envs.tasks.catalogue import get_spec

#: federated Table 2 (no fault, follower UAV 1): scheme → (RMSE E, N, U), (mean E, N, U) [m]
PAPER_FED_TABLE2 = {"scheme 1 (gps-ins)": ((2.10, 2.43, 1.85), (1.68, 1.99, 1.44)),
                    "scheme 2 (federated-fdi)": ((0.45, 0.45, 0.27), (0.35, 0.36, 0.20)),
                    "proposed (federated)": ((0.41, 0.40, 0.25), (0.33, 0.32, 0.20))}
#: federated Table 3 (500–600 s, gradual GPS fault of follower UAV 1)
PAPER_FED_TABLE3 = {"scheme 2 (federated-fdi)": ((1.84, 1.34, 1.77), (0.54, 0.49, 0.49)),
                    "proposed (federated)": ((0.95, 0.76, 0.50), (0.40, 0.36, 0.26))}


_FED_SCHEMES: dict[str, Factory] = {"scheme 1 (gps-ins)": gps_ins, "scheme 2 (federated-fdi)": federated_fdi,
                                    "proposed (federated)": federated}


def _axis_stats(err: np.ndarray, times: np.ndarray, window: tuple[float, float], node: int) -> dict:
    """Per-axis (E, N, U) RMSE and mean |error| of one UAV in a window, per seed: (B, 3) each."""
    m = (times >= window[0] - 1e-9) & (times < window[1] - 1e-9)
    e = err[m][:, :, node]  # (T_w, B, 3)
    return {"rmse": np.sqrt((e**2).mean(axis=0)), "mean": np.abs(e).mean(axis=0)}


def reproduce_federated(out: Path, seeds: int = 16, version: int = 1) -> Path:
    """federated Tables 2–3 on GradualFault-v<version>; writes markdown (+ .json) and returns its path."""
    if version not in _READING:
        raise ValueError(f"version must be one of {sorted(_READING)}, got {version!r}")
    S = seeds_from(seeds)
    task = f"GradualFault-v{version}"
    faulty = get_spec(task)
    clean = get_spec(task, faults={"gps_drifts": ()})
    drift = (100.0, 200.0)
    raw: dict[str, Any] = {"version": version, "seeds": S, "table2": {}, "table3": {}, "orderings": [], "rmse": {}}
    variants: dict[str, Factory] = dict(_FED_SCHEMES)
    variants["scheme 2, consistent R₂"] = lambda: federated_fdi(leader_cov_in_R=True)
    variants["proposed, consistent R₂"] = lambda: federated(leader_cov_in_R=True)
    for label, make in variants.items():
        e_clean = episode_errors(make, clean, S)
        e_fault = episode_errors(make, faulty, S)
        t2 = _axis_stats(e_clean["err"], e_clean["times"], (0.0, clean.duration + 1.0), 1)
        t3 = _axis_stats(e_fault["err"], e_fault["times"], drift, 1)
        raw["table2"][label] = {k: v.tolist() for k, v in t2.items()}
        raw["table3"][label] = {k: v.tolist() for k, v in t3.items()}
    for window in (drift, faulty.scoring.fault_window):
        spec = get_spec(task, scoring={"fault_window": window})
        makers: dict[str, Factory] = {
            "federated": federated, "federated-fdi": federated_fdi,
            "federated (consistent R₂)": lambda: federated(leader_cov_in_R=True),
            "federated-fdi (consistent R₂)": lambda: federated_fdi(leader_cov_in_R=True)}
        got = {label: np.array([m["fault_rmse"] for m in runner_metrics(label, make, spec, S)])
               for label, make in makers.items()}
        for label, v in got.items():
            raw["rmse"][f"{label}|{window[0]:g}-{window[1]:g}"] = v.tolist()
        w = f"{window[0]:g}–{window[1]:g} s"
        raw["orderings"].append(paired(got["federated"], got["federated-fdi"], f"federated < federated-fdi, {w}"))
        raw["orderings"].append(paired(got["federated (consistent R₂)"], got["federated-fdi (consistent R₂)"],
                                       f"same with the consistent R₂, {w}"))
    return write_paper_report(out, "federated", _render_federated(raw), raw)


def _render_federated(raw: dict) -> str:
    def row(label: str, st: dict, paper: tuple | None) -> str:
        r, m = np.asarray(st["rmse"]), np.asarray(st["mean"])
        ours = " | ".join(f"{r[:, i].mean():.2f}" for i in range(3)) + " | " + " | ".join(
            f"{m[:, i].mean():.2f}" for i in range(3))
        pap = " | ".join(f"{v:.2f}" for v in paper[0] + paper[1]) if paper else "— | — | — | — | — | —"
        return f"| {label} | {ours} | {pap} |"

    head = ("| scheme | RMSE E | RMSE N | RMSE U | mean E | mean N | mean U | paper RMSE E | N | U | paper mean E "
            "| N | U |")
    sep = "|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    n = len(raw["seeds"])
    version = raw.get("version", 0)
    lines = [f"# federated-filter reproduction on swarmloc/GradualFault-v{version}", "",
             (f"{n} test seeds ({raw['seeds'][0]} …), 300 s at 1 Hz; follower UAV 1 (our node 1), per axis (E, N, U), "
             "RMSE and mean |error| [m], averaged over seeds. Paper: one PSINS run, 1000 s, fault 500–600 s."), "",
             "## Table 2 — no fault (whole episode)", "", head, sep]
    lines += [row(k, v, PAPER_FED_TABLE2.get(k)) for k, v in raw["table2"].items()]
    lines += ["", "## Table 3 — gradual GPS fault, drift window 100–200 s (paper: 500–600 s)", "", head, sep]
    lines += [row(k, v, PAPER_FED_TABLE3.get(k)) for k, v in raw["table3"].items() if not k.startswith("scheme 1")]
    lines += ["", "### The paper's ordering (runner fault-window RMSE of both followers, paired per seed)", ""]
    lines += ordering_table(raw["orderings"])
    lines += ["", "### Reading", "", _READING[version](raw), ""]
    return "\n".join(lines)


def _reading_v0(raw: dict) -> str:
    return ("'consistent R₂' adds the leader's broadcast position covariance to sub-filter 2's noise (the "
            "paper's R₂ is the UWB noise alone, 0.03² m², although the leader's position is a 1 m GPS "
            "estimate). With the printed R₂, sub-filter 2 fails the χ² test at about half of the steps and the "
            "adaptive allocation coefficient is what keeps the global estimate usable — there the paper's "
            "ordering appears. With the consistent R₂ both schemes follow the leader's estimate to within its "
            "own error, the 10 m GPS barely matters, and the adaptive coefficient has nothing to win: the "
            "schemes agree to within a centimetre, the adaptive one a few millimetres worse (its coefficients "
            "follow the residual noise). Both are more accurate than either scheme with the printed R₂. "
            "In our world the follower GPS drift (10 m over 100 s against a 10 m GPS σ) is also "
            "too small for the χ² test to see (λ stays near its 3-dof mean), so Scheme 2's FDI rarely fires.")


def _reading_v1(raw: dict) -> str:
    verdicts = "; ".join(f"{r['claim']}: {r['mean_diff']:+.3f} m [{r['ci'][0]:+.3f}, {r['ci'][1]:+.3f}]"
                         for r in raw["orderings"])
    return ("v1 gives the drift the paper's size (0.1 m/s on each axis for 100 s, 17 m at its end) against a "
            "3 m GPS, and the leader link the accuracy a UWB range with angle of arrival has at 30 m (1.5 m per "
            "axis), so neither the GPS nor the link can be trusted blindly. 'consistent R₂' adds the leader's "
            "broadcast position covariance to sub-filter 2's noise. The paper's ordering, paired per seed on the "
            f"runner's fault-window RMSE of both followers: {verdicts}.")


_READING = {0: _reading_v0, 1: _reading_v1}
