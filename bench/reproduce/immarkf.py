"""``swarmloc reproduce immarkf``: imm-arkf Table 2 on HybridNoise{10,30,50}, beside the paper's numbers.

``version`` picks the tasks: 1 (default) the v1 contamination mixture, 0 the frozen v0
weighted sum (imm-arkf eq. 1 as printed).

RMSE of ``imm-arkf``, ``imm-kf``, ``imm-ekf`` at the filter noise settings R = 0.5, 1.5, 8
(the paper's columns) and at the registered default (the task's nominal σ²), mean step
time; the paper's ordering (IMM-ARKF below both others) as paired per-seed differences
with 95 % bootstrap CIs; ablations of the ARKF (no fading factor; the printed,
unnormalized Γ).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from swarmloc.agents.estimators.imm import make_imm
from swarmloc.bench.reproduce.common import (
    Factory,
    episode_errors,
    mean_sd,
    ordering_table,
    paired,
    runner_metrics,
    seeds_from,
    write_paper_report,
)
from swarmloc.envs.tasks.catalogue import get_spec

#: imm-arkf Table 2: (filter, ratio %) → RMSE mean, std at R = 0.5, 1.5, 8 and avg time (ms)
PAPER_IMM_TABLE2: dict[tuple[str, int], tuple[tuple[float, float], ...]] = {
    ("imm-arkf", 10): ((0.2602, 0.026), (0.2121, 0.0114), (0.1925, 0.0138), (1.7087, 0.0717)),
    ("imm-arkf", 30): ((0.2232, 0.0137), (0.1825, 0.01), (0.1709, 0.0104), (1.6378, 0.129)),
    ("imm-arkf", 50): ((0.2066, 0.0198), (0.1765, 0.0091), (0.1579, 0.0114), (1.6402, 0.0975)),
    ("imm-ekf", 10): ((0.3763, 0.0512), (0.3781, 0.1361), (0.3224, 0.0596), (0.6297, 0.056)),
    ("imm-ekf", 30): ((0.3115, 0.0293), (0.3046, 0.0778), (0.2781, 0.0446), (0.6712, 0.0764)),
    ("imm-ekf", 50): ((0.2933, 0.0314), (0.3012, 0.0813), (0.2597, 0.0398), (0.689, 0.0986)),
    ("imm-kf", 10): ((0.3937, 0.0105), (0.3255, 0.0106), (0.2528, 0.0119), (0.9436, 0.0683)),
    ("imm-kf", 30): ((0.3394, 0.0093), (0.2778, 0.074), (0.2168, 0.009), (0.8472, 0.0572)),
    ("imm-kf", 50): ((0.3199, 0.0077), (0.2555, 0.07), (0.1995, 0.0079), (0.8991, 0.0673)),
}
IMM_R = (0.5, 1.5, 8.0)


_IMM_VARIANTS = {"imm-arkf": "arkf", "imm-kf": "kf", "imm-ekf": "ekf"}


def _imm(name: str, **overrides: Any) -> Factory:
    return lambda: make_imm(_IMM_VARIANTS[name], **overrides)  # type: ignore[arg-type]


def reproduce_immarkf(out: Path, seeds: int = 16, duration: float | None = None, version: int = 1) -> Path:
    """imm-arkf Table 2 on HybridNoise{10,30,50}-v<version>; writes markdown (+ .json) and returns its path."""
    if version not in _READING:
        raise ValueError(f"version must be one of {sorted(_READING)}, got {version!r}")
    S = seeds_from(seeds)
    over = {"duration": duration} if duration else {}
    rmse: dict[str, list[float]] = {}
    orderings: list[dict] = []
    ablations: dict[str, list[float]] = {}
    for p in (10, 30, 50):
        spec = get_spec(f"HybridNoise{p}-v{version}", **over)
        for r in (None,) + IMM_R:
            col = "nominal" if r is None else f"R={r:g}"
            got = {f: np.array([m["rmse"] for m in runner_metrics(f, _imm(f, r=r), spec, S)]) for f in _IMM_VARIANTS}
            for f, v in got.items():
                rmse[f"{f}|{p}|{col}"] = v.tolist()
            for other in ("imm-kf", "imm-ekf"):
                orderings.append(paired(got["imm-arkf"], got[other], f"imm-arkf < {other} at {p} %, {col}"))
        for label, kw in zip(_ABLATIONS, ({"fading": False}, {"normalize_gamma": False}), strict=True):
            ablations[f"{label}|{p}"] = [m["rmse"] for m in runner_metrics(label, _imm("imm-arkf", **kw), spec, S)]
    timing = {f: episode_errors(_imm(f), get_spec(f"HybridNoise30-v{version}", duration=20.0), [S[0]])["step_ms"]
              for f in _IMM_VARIANTS}
    raw = {"version": version, "seeds": S, "rmse": rmse, "ablations": ablations, "orderings": orderings,
           "step_ms": timing}
    return write_paper_report(out, "immarkf", _render_imm(raw, duration), raw)


def _reading_v0(raw: dict) -> str:
    return ("The paper's ordering does not appear in our world; the ARKF is 1–3 cm *worse* than the KF and the "
            "EKF at every ratio and R except R = 0.5 at 50 %, where they tie. Our hybrid noise is the paper's "
            "eq. 1 as printed, a weighted *sum* a·t_ν + (1 − a)·N(0, 1) with ν ∈ [25, 50]: nearly Gaussian, "
            "std 0.7–0.9 m, shrinking as a grows. There are no outliers to reject, and the correntropy weights "
            "can only lower the gain (Γ̃ ⪯ I), so ordinary residuals inflate R and the ARKF under-uses good "
            "fixes; the fading factor is not the cause (the λ = 1 ablation is as good as the full ARKF). The "
            "printed Γ (eq. 27) inflates R 11–27× and over-smooths our 2 m/s figure-eight; in the paper "
            "(0.4 m/s Crazyflies at 31 Hz) heavy smoothing pays — its RMSE falls as R grows, ours rises. The "
            "EKF on converted range/bearing tracks the KF to within 1 mm.")


def _reading_v1(raw: dict) -> str:
    def raw_get(key: str, p: int) -> np.ndarray:
        return np.asarray(raw["ablations"][f"{key}|{p}"] if key in _ABLATIONS else raw["rmse"][f"{key}|{p}|nominal"])

    def diff(a: str, b: str, p: int) -> float:
        return float(np.mean(raw_get(a, p) - raw_get(b, p)))

    full = ", ".join(f"{diff('imm-arkf', 'imm-kf', p):+.3f}" for p in (10, 30, 50))
    no_fading = ", ".join(f"{diff(_ABLATIONS[0], 'imm-kf', p):+.3f}" for p in (10, 30, 50))
    diverged = {p: int(np.sum(raw_get("imm-arkf", p) > 3.0 * raw_get("imm-kf", p))) for p in (10, 30, 50)}
    n = len(raw["seeds"])
    return ("With outliers in the data (v1: each fix is, with probability p, a trivariate Student-t draw, "
            "ν 3–8), the ARKF's robust update does what the paper says: without the fading factor (λ = 1) it "
            f"beats the KF at nominal R by {no_fading} m at 10 / 30 / 50 %. The full ARKF does not "
            f"({full} m). The fading factor's χ² test (eq. 29–32) runs on the robust-weighted residual, and the "
            "robust weights leave a gross outlier much of its weight: with h = 0.15 the cross-component kernel "
            "(eq. 24–26, σ₂ = 8) dominates Γ, and it sees only the differences between axes, so off the common "
            "direction Γ̃ keeps 0.4–0.7 of its weight (0.39 and 0.56 for a whitened residual (20, 15, 10)). "
            "Such a fix fails the test, λ inflates the predicted covariance on exactly that fix (up to a few "
            "hundred-fold), and the filter follows it. Once the estimate is several σ off, the next fixes look "
            "like outliers to the correntropy weights and are discounted, so it does not come back: episodes "
            "with ARKF "
            f"RMSE above 3× the KF's: {diverged[10]}/{n}, {diverged[30]}/{n}, {diverged[50]}/{n}. The paper's "
            "ordering (its Table 2) is therefore a property of its robust weights, not of the fading factor, "
            "in our world; we keep the method as printed and report the ablation.")


_READING = {0: _reading_v0, 1: _reading_v1}
_ABLATIONS = ("imm-arkf without fading (λ = 1)", "imm-arkf with the printed Γ (eq. 27, unnormalized)")


def _render_imm(raw: dict, duration: float | None) -> str:
    n = len(raw["seeds"])
    version = raw.get("version", 0)
    noise = ("the paper's eq. 1 as printed" if version == 0 else
             "a contamination mixture, Student-t with probability p")
    lines = [f"# imm-arkf reproduction on swarmloc/HybridNoise{{10,30,50}}-v{version}", "",
             f"GPS noise of the followers: {noise}.", "",
             (f"{n} test seeds ({raw['seeds'][0]} …), {duration or 60:g} s episodes, 9 UAVs, followers 1–8 scored; "
             "ours: RMSE mean ± std over seeds (runner metric: pooled over follower-steps); paper: mean ± std over "
             "100 Monte Carlo runs (Table 2). Columns are the filter's measurement noise R·I; 'nominal' is the "
             "registered default (the task's σ² = 1 m² for the followers)."), "",
             "## Table 2 — RMSE (m) and time per step", "",
             ("| filter | t-ratio | R=0.5 ours | paper | R=1.5 ours | paper | R=8 ours | paper | nominal ours "
             "| ms/step ours (9 UAVs) | paper avg time (ms) |"), "|---|---|---|---|---|---|---|---|---|---|---|"]
    for f in _IMM_VARIANTS:
        for p in (10, 30, 50):
            pap = PAPER_IMM_TABLE2[(f, p)]
            cells = []
            for i, r in enumerate(IMM_R):
                cells += [mean_sd(raw["rmse"][f"{f}|{p}|R={r:g}"]), f"{pap[i][0]:.4f} ± {pap[i][1]:.4f}"]
            lines.append(f"| {f} | {p} % | " + " | ".join(cells) + f" | {mean_sd(raw['rmse'][f'{f}|{p}|nominal'])} "
                         f"| {raw['step_ms'][f]:.2f} | {pap[3][0]:.3f} ± {pap[3][1]:.3f} |")
    lines += ["", "### Ablations of the ARKF (nominal R)", "", "| variant | 10 % | 30 % | 50 % |", "|---|---|---|---|"]
    for label in dict.fromkeys(k.split("|")[0] for k in raw["ablations"]):
        lines.append(f"| {label} | " + " | ".join(mean_sd(raw["ablations"][f"{label}|{p}"]) for p in (10, 30, 50)) + " |")
    lines += ["", "### The paper's ordering (paired per-seed RMSE differences, 95 % bootstrap CI)", ""]
    lines += ordering_table(raw["orderings"])
    lines += ["", "### Reading", "", _READING[version](raw), ""]
    return "\n".join(lines)
