"""``swarmloc reproduce immarkf | federated | dtvirm``: our numbers beside the papers' tables.

- **immarkf** — imm-arkf Table 2 on HybridNoise{10,30,50}-v0: RMSE of ``imm-arkf``,
  ``imm-kf``, ``imm-ekf`` at the filter noise settings R = 0.5, 1.5, 8 (the paper's
  columns) and at the registered default (the task's nominal σ²), mean step time; the
  paper's ordering (IMM-ARKF below both others) as paired per-seed differences with 95 %
  bootstrap CIs; ablations of the ARKF (no fading factor; the printed, unnormalized Γ).
- **federated** — federated Tables 2–3 on GradualFault-v0 (follower UAV 1, per axis):
  Table 2 without the fault (``faults.gps_drifts = ()``) for Scheme 1 (GPS/IMU only),
  Scheme 2 (``federated-fdi``) and the proposed filter (``federated``); Table 3 in the
  drift window (100–200 s here, 500–600 s in the paper) for Scheme 2 and the proposed
  filter; the ordering federated < federated-fdi inside the fault window, for the printed
  sub-filter-2 noise (the registered default) and the consistent one
  (``leader_cov_in_R=True``).
- **dtvirm** — Table 1 (MDS-MAP vs NLS, ``bench/mdsmap_compare.py``), Table 5 (per-UAV
  RMSE on AnchorFree-v0: ``ci-ekf`` = COO_OUR, ``ci-ekf-no-aa`` = without UWB_AA, plus
  our ablations), Table 6 (anomaly statistics of the χ² UWB adjustment) and the
  ordering ci-ekf < ci-ekf-no-aa.

Headline RMSEs and every ordering come from the runner (``bench.runner.rollout``, the
leaderboard's metrics). Per-axis and per-UAV breakdowns and the raw-range anomaly
statistics need per-step errors and the truth, so ``episode_errors`` replays the runner's
loop (same world, measurements, alignment) and keeps them. Our worlds are not the
papers' simulators: compare orderings and magnitudes, not digits.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

from swarmloc.agents.ci_ekf import ci_ekf, ci_ekf_no_aa
from swarmloc.agents.federated import federated, federated_fdi, gps_ins
from swarmloc.agents.imm import make_imm
from swarmloc.agents.protocols import Measurements, TaskFacts, episode_keys
from swarmloc.agents.registry import LoadedMethod
from swarmloc.bench.alignment import align_estimates
from swarmloc.bench.runner import rollout, single_threaded_kernels
from swarmloc.bench.stats import bootstrap_ci
from swarmloc.bench.suites import TEST_SEED_START
from swarmloc.envs.channels import PEER
from swarmloc.envs.specs import TaskSpec
from swarmloc.envs.tasks import get_spec
from swarmloc.envs.world import World

Factory = Callable[[], Any]

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
#: federated Table 2 (no fault, follower UAV 1): scheme → (RMSE E, N, U), (mean E, N, U) [m]
PAPER_FED_TABLE2 = {"scheme 1 (gps-ins)": ((2.10, 2.43, 1.85), (1.68, 1.99, 1.44)),
                    "scheme 2 (federated-fdi)": ((0.45, 0.45, 0.27), (0.35, 0.36, 0.20)),
                    "proposed (federated)": ((0.41, 0.40, 0.25), (0.33, 0.32, 0.20))}
#: federated Table 3 (500–600 s, gradual GPS fault of follower UAV 1)
PAPER_FED_TABLE3 = {"scheme 2 (federated-fdi)": ((1.84, 1.34, 1.77), (0.54, 0.49, 0.49)),
                    "proposed (federated)": ((0.95, 0.76, 0.50), (0.40, 0.36, 0.26))}
#: dtvirm Table 5 (UWB abnormality): per UAV 1–6 and average RMSE [m]
PAPER_DTVIRM_TABLE5 = {"COO_VIR": (8.23, 11.12, 10.89, 12.01, 12.34, 13.76, 11.39),
                       "COO_OUR (ci-ekf)": (4.12, 6.56, 6.34, 7.11, 7.67, 7.03, 6.47),
                       "COO_OUR without_UWB_AA (ci-ekf-no-aa)": (5.89, 8.43, 8.12, 9.26, 9.87, 8.75, 8.39)}
#: dtvirm Table 6: anomaly ratio in raw UWB data, correctly identified ratio, detection rate [%]
PAPER_DTVIRM_TABLE6 = (20.0, 18.6, 93.0)
ABNORMAL_RANGE_M = 1.0  # dtvirm §4.4: a range more than 1 m off the truth is abnormal


# --------------------------------------------------------------------------- running


def seeds_from(n: int) -> list[int]:
    """The first ``n`` test seeds (1_000_000 …)."""
    if n < 2:
        raise ValueError(f"need at least 2 seeds for confidence intervals, got {n}")
    return list(range(TEST_SEED_START, TEST_SEED_START + n))


def runner_metrics(label: str, make: Factory, spec: TaskSpec, seeds: list[int]) -> list[dict]:
    """Per-seed runner metrics of a configured estimator (``rollout``, as ``swarmloc evaluate``)."""
    loaded = LoadedMethod(name=label, entry_point=label, track="B", privileged=False, deterministic=True,
                          method=make())
    metrics, _ = rollout(loaded, spec, seeds)
    return metrics


def episode_errors(make: Factory, spec: TaskSpec, seeds: list[int]) -> dict[str, np.ndarray]:
    """The runner's Track B loop, keeping per-step errors, trust and the raw range errors.

    Returns:
        ``err`` (T, B, N, 3) estimate − truth after the task's scoring alignment,
        ``times`` (T,), ``weights`` (T, B, N, L) applied trust (ones if none reported),
        ``range_err`` (T, B, N, L) |measured − true range| on peer channels (NaN elsewhere),
        ``valid`` (T, B, N, L), ``step_ms`` mean wall time of ``step`` [ms].
    """
    world = World(spec, len(seeds))
    x0 = world.reset(seeds).copy()
    facts = TaskFacts.from_spec(spec, world.layout, x0, episode_keys(seeds))
    est = make()
    est.reset(facts, facts.x0)
    peer = world.layout.kind == PEER
    target = np.where(peer, world.layout.target, 0)
    T = spec.n_steps
    pos, truth = np.zeros((T, len(seeds), spec.n_uav, 3)), np.zeros((T, len(seeds), spec.n_uav, 3))
    weights = np.ones((T, len(seeds)) + peer.shape)
    range_err = np.full((T, len(seeds)) + peer.shape, np.nan)
    valid = np.zeros((T, len(seeds)) + peer.shape, dtype=bool)
    spent = 0.0
    with single_threaded_kernels():
        for k in range(T):
            buf = world.sense()
            meas = Measurements.capture(buf.imu, buf.z, buf.valid, (k + 1) * spec.dt, k + 1, buf.velocity)
            t0 = time.perf_counter()
            out = est.step(meas)
            spent += time.perf_counter() - t0
            pos[k], truth[k], valid[k] = out.positions, buf.pos, buf.valid
            if out.weights is not None:
                weights[k] = out.weights
            d = np.linalg.norm(buf.pos[:, :, None, :] - buf.pos[:, target, :], axis=-1)
            range_err[k] = np.where(peer, np.abs(buf.z[..., 0] - d), np.nan)
    times = spec.dt * np.arange(1, T + 1)
    err = align_estimates(spec, times, pos, truth) - truth
    return {"err": err, "times": times, "weights": weights, "range_err": range_err, "valid": valid,
            "step_ms": 1e3 * spent / T}


def paired(a: np.ndarray, b: np.ndarray, claim: str) -> dict:
    """The claim "a < b" on paired per-seed values: mean difference a − b and its 95 % bootstrap CI."""
    d = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
    lo, hi = bootstrap_ci(d)
    return {"claim": claim, "mean_diff": float(d.mean()), "ci": [lo, hi], "holds": bool(d.mean() < 0),
            "significant": bool(hi < 0), "contradicted": bool(lo > 0), "wins": int((d < 0).sum()), "n": int(d.size)}


def _verdict(row: dict) -> str:
    if row["significant"]:
        return "holds (CI < 0)"
    if row["contradicted"]:
        return "reversed (CI > 0)"
    return "not resolved (CI ∋ 0)"


def _ordering_table(rows: list[dict]) -> list[str]:
    out = ["| claim | mean difference (m) | 95 % CI | verdict | seeds won |", "|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['claim']} | {r['mean_diff']:+.4f} | [{r['ci'][0]:+.4f}, {r['ci'][1]:+.4f}] "
                   f"| {_verdict(r)} | {r['wins']}/{r['n']} |")
    return out


def _ms(values: np.ndarray, digits: int = 3) -> str:
    v = np.asarray(values, dtype=float)
    return f"{v.mean():.{digits}f} ± {v.std(ddof=1):.{digits}f}"


def _write(out: Path, name: str, text: str, raw: dict) -> Path:
    """Write ``<out>`` (or ``<out>/<name>.md``) and the raw numbers beside it, atomically.

    The report ends with its provenance (package version and git commit).
    """
    from swarmloc.bench.results import collect_provenance

    prov = collect_provenance()
    raw = {**raw, "provenance": prov.model_dump(mode="json")}
    text += (f"\n---\nGenerated by `swarmloc reproduce {name}` with swarmloc {prov.package_version}, commit "
             f"{(prov.git_commit or 'unknown')[:10]}.\n")
    path = out / f"{name}.md" if out.is_dir() or not out.suffix else out
    path.parent.mkdir(parents=True, exist_ok=True)
    for target, content in ((path, text), (path.with_suffix(".json"), json.dumps(raw, indent=1, default=float))):
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", dir=target.parent)
        with os.fdopen(fd, "w") as handle:
            handle.write(content)
        os.replace(tmp, target)
    return path


# --------------------------------------------------------------------------- imm-arkf


_IMM_VARIANTS = {"imm-arkf": "arkf", "imm-kf": "kf", "imm-ekf": "ekf"}


def _imm(name: str, **overrides: Any) -> Factory:
    return lambda: make_imm(_IMM_VARIANTS[name], **overrides)  # type: ignore[arg-type]


def reproduce_immarkf(out: Path, seeds: int = 16, duration: float | None = None) -> Path:
    """imm-arkf Table 2 on HybridNoise{10,30,50}-v0; writes markdown (+ .json) and returns its path."""
    S = seeds_from(seeds)
    over = {"duration": duration} if duration else {}
    rmse: dict[str, list[float]] = {}
    orderings: list[dict] = []
    ablations: dict[str, list[float]] = {}
    for p in (10, 30, 50):
        spec = get_spec(f"HybridNoise{p}-v0", **over)
        for r in (None,) + IMM_R:
            col = "nominal" if r is None else f"R={r:g}"
            got = {f: np.array([m["rmse"] for m in runner_metrics(f, _imm(f, r=r), spec, S)]) for f in _IMM_VARIANTS}
            for f, v in got.items():
                rmse[f"{f}|{p}|{col}"] = v.tolist()
            for other in ("imm-kf", "imm-ekf"):
                orderings.append(paired(got["imm-arkf"], got[other], f"imm-arkf < {other} at {p} %, {col}"))
        for label, kw in (("imm-arkf without fading (λ = 1)", {"fading": False}),
                          ("imm-arkf with the printed Γ (eq. 27, unnormalized)", {"normalize_gamma": False})):
            ablations[f"{label}|{p}"] = [m["rmse"] for m in runner_metrics(label, _imm("imm-arkf", **kw), spec, S)]
    timing = {f: episode_errors(_imm(f), get_spec("HybridNoise30-v0", duration=20.0), [S[0]])["step_ms"]
              for f in _IMM_VARIANTS}
    raw = {"seeds": S, "rmse": rmse, "ablations": ablations, "orderings": orderings, "step_ms": timing}
    return _write(out, "immarkf", _render_imm(raw, duration), raw)


def _render_imm(raw: dict, duration: float | None) -> str:
    n = len(raw["seeds"])
    lines = ["# imm-arkf reproduction on swarmloc/HybridNoise{10,30,50}-v0", "",
             f"{n} test seeds ({raw['seeds'][0]} …), {duration or 60:g} s episodes, 9 UAVs, followers 1–8 scored; "
             "ours: RMSE mean ± std over seeds (runner metric: pooled over follower-steps); paper: mean ± std over "
             "100 Monte Carlo runs (Table 2). Columns are the filter's measurement noise R·I; 'nominal' is the "
             "registered default (the task's σ² = 1 m² for the followers).", "",
             "## Table 2 — RMSE (m) and time per step", "",
             "| filter | t-ratio | R=0.5 ours | paper | R=1.5 ours | paper | R=8 ours | paper | nominal ours "
             "| ms/step ours (9 UAVs) | paper avg time (ms) |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for f in _IMM_VARIANTS:
        for p in (10, 30, 50):
            pap = PAPER_IMM_TABLE2[(f, p)]
            cells = []
            for i, r in enumerate(IMM_R):
                cells += [_ms(raw["rmse"][f"{f}|{p}|R={r:g}"]), f"{pap[i][0]:.4f} ± {pap[i][1]:.4f}"]
            lines.append(f"| {f} | {p} % | " + " | ".join(cells) + f" | {_ms(raw['rmse'][f'{f}|{p}|nominal'])} "
                         f"| {raw['step_ms'][f]:.2f} | {pap[3][0]:.3f} ± {pap[3][1]:.3f} |")
    lines += ["", "### Ablations of the ARKF (nominal R)", "", "| variant | 10 % | 30 % | 50 % |", "|---|---|---|---|"]
    for label in dict.fromkeys(k.split("|")[0] for k in raw["ablations"]):
        lines.append(f"| {label} | " + " | ".join(_ms(raw["ablations"][f"{label}|{p}"]) for p in (10, 30, 50)) + " |")
    lines += ["", "### The paper's ordering (paired per-seed RMSE differences, 95 % bootstrap CI)", ""]
    lines += _ordering_table(raw["orderings"])
    lines += ["", "### Reading", "",
              "The paper's ordering does not appear in our world; the ARKF is 1–3 cm *worse* than the KF and the "
              "EKF at every ratio and R except R = 0.5 at 50 %, where they tie. Our hybrid noise is the paper's "
              "eq. 1 as printed, a weighted *sum* a·t_ν + (1 − a)·N(0, 1) with ν ∈ [25, 50]: nearly Gaussian, "
              "std 0.7–0.9 m, shrinking as a grows. There are no outliers to reject, and the correntropy weights "
              "can only lower the gain (Γ̃ ⪯ I), so ordinary residuals inflate R and the ARKF under-uses good "
              "fixes; the fading factor is not the cause (the λ = 1 ablation is as good as the full ARKF). The "
              "printed Γ (eq. 27) inflates R 11–27× and over-smooths our 2 m/s figure-eight; in the paper "
              "(0.4 m/s Crazyflies at 31 Hz) heavy smoothing pays — its RMSE falls as R grows, ours rises. The "
              "EKF on converted range/bearing tracks the KF to within 1 mm.", ""]
    return "\n".join(lines)


# --------------------------------------------------------------------------- federated


_FED_SCHEMES: dict[str, Factory] = {"scheme 1 (gps-ins)": gps_ins, "scheme 2 (federated-fdi)": federated_fdi,
                                    "proposed (federated)": federated}


def _axis_stats(err: np.ndarray, times: np.ndarray, window: tuple[float, float], node: int) -> dict:
    """Per-axis (E, N, U) RMSE and mean |error| of one UAV in a window, per seed: (B, 3) each."""
    m = (times >= window[0] - 1e-9) & (times < window[1] - 1e-9)
    e = err[m][:, :, node]  # (T_w, B, 3)
    return {"rmse": np.sqrt((e**2).mean(axis=0)), "mean": np.abs(e).mean(axis=0)}


def reproduce_federated(out: Path, seeds: int = 16) -> Path:
    """federated Tables 2–3 on GradualFault-v0; writes markdown (+ .json) and returns its path."""
    S = seeds_from(seeds)
    faulty = get_spec("GradualFault-v0")
    clean = get_spec("GradualFault-v0", faults={"gps_drifts": ()})
    drift = (100.0, 200.0)
    raw: dict[str, Any] = {"seeds": S, "table2": {}, "table3": {}, "orderings": [], "rmse": {}}
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
        spec = get_spec("GradualFault-v0", scoring={"fault_window": window})
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
    return _write(out, "federated", _render_federated(raw), raw)


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
    lines = ["# federated-filter reproduction on swarmloc/GradualFault-v0", "",
             f"{n} test seeds ({raw['seeds'][0]} …), 300 s at 1 Hz; follower UAV 1 (our node 1), per axis (E, N, U), "
             "RMSE and mean |error| [m], averaged over seeds. Paper: one PSINS run, 1000 s, fault 500–600 s.", "",
             "## Table 2 — no fault (whole episode)", "", head, sep]
    lines += [row(k, v, PAPER_FED_TABLE2.get(k)) for k, v in raw["table2"].items()]
    lines += ["", "## Table 3 — gradual GPS fault, drift window 100–200 s (paper: 500–600 s)", "", head, sep]
    lines += [row(k, v, PAPER_FED_TABLE3.get(k)) for k, v in raw["table3"].items() if not k.startswith("scheme 1")]
    lines += ["", "### The paper's ordering (runner fault-window RMSE of both followers, paired per seed)", ""]
    lines += _ordering_table(raw["orderings"])
    lines += ["", "### Reading", "",
              "'consistent R₂' adds the leader's broadcast position covariance to sub-filter 2's noise (the "
              "paper's R₂ is the UWB noise alone, 0.03² m², although the leader's position is a 1 m GPS "
              "estimate). With the printed R₂, sub-filter 2 fails the χ² test at about half of the steps and the "
              "adaptive allocation coefficient is what keeps the global estimate usable — there the paper's "
              "ordering appears. With the consistent R₂ both schemes follow the leader's estimate to within its "
              "own error, the 10 m GPS barely matters, and the adaptive coefficient has nothing to win: the "
              "schemes agree to within a centimetre, the adaptive one a few millimetres worse (its coefficients "
              "follow the residual noise). Both are more accurate than either scheme with the printed R₂. "
              "In our world the follower GPS drift (10 m over 100 s against a 10 m GPS σ) is also "
              "too small for the χ² test to see (λ stays near its 3-dof mean), so Scheme 2's FDI rarely fires.", ""]
    return "\n".join(lines)


# --------------------------------------------------------------------------- dtvirm


def init_study(seeds: list[int], windows: tuple[float, ...] = (1.0, 2.0, 3.0)) -> dict[str, dict]:
    """MDS-MAP initializer on AnchorFree-v0 per window length: mirror failures, yaw and shape errors."""
    from swarmloc.agents.init.initializer import InitConfig, MdsMapInitializer
    from swarmloc.bench.alignment import yaw_translation_fit

    out = {}
    spec = get_spec("AnchorFree-v0", duration=max(windows) + 0.5)
    for w in windows:
        world = World(spec, len(seeds))
        x0 = world.reset(seeds).copy()
        init = MdsMapInitializer(TaskFacts.from_spec(spec, world.layout, x0, episode_keys(seeds)), InitConfig(window=w))
        first, k = None, 0
        with single_threaded_kernels():
            while not init.ready:
                k += 1
                buf = world.sense()
                first = buf.pos[:, :1].copy() if first is None else first
                init.observe(Measurements.capture(buf.imu, buf.z, buf.valid, k * spec.dt, k, buf.velocity))
        x = init.solve()[..., :3]
        truth = buf.pos - first
        R, t = yaw_translation_fit(x, truth)
        shape = np.linalg.norm(np.einsum("bij,bnj->bni", R, x) + t[:, None] - truth, axis=-1).mean(axis=1)
        yaw = np.degrees(np.abs(np.arctan2(R[:, 1, 0], R[:, 0, 0])))
        out[f"{w:g} s"] = {"mirror_failures": int((shape > 2.0).sum()), "n": len(seeds),
                           "median_shape_m": float(np.median(shape)), "median_yaw_deg": float(np.median(yaw)),
                           "p90_yaw_deg": float(np.percentile(yaw, 90))}
    return out


def reproduce_dtvirm(out: Path, seeds: int = 16, trials: int = 200) -> Path:
    """dtvirm Tables 1, 5, 6 (MDS-MAP, AnchorFree-v0); writes markdown (+ .json) and returns its path."""
    from swarmloc.bench.mdsmap_compare import compare_mdsmap_nls

    S = seeds_from(seeds)
    spec = get_spec("AnchorFree-v0")
    raw: dict[str, Any] = {"seeds": S, "table1": compare_mdsmap_nls(trials=trials), "table5": {}, "rmse": {}}
    methods: dict[str, Factory] = {"ci-ekf": ci_ekf, "ci-ekf-no-aa": ci_ekf_no_aa,
                                   "ci-ekf, no CI (R with Pⱼ)": lambda: ci_ekf(ci=False),
                                   "ci-ekf, started from the 5 m prior": lambda: ci_ekf(init="prior")}
    runs = {}
    for label, make in methods.items():
        metrics = runner_metrics(label, make, spec, S)
        raw["rmse"][label] = {k: [m[k] for m in metrics] for k in ("rmse", "fault_rmse", "anomaly_detection_rate")}
        if label in ("ci-ekf", "ci-ekf-no-aa"):
            runs[label] = episode_errors(make, spec, S)
            r = runs[label]
            scored = r["times"] >= spec.scoring.start
            e2 = np.sum(r["err"][scored] ** 2, axis=-1)  # (T, B, N)
            raw["table5"][label] = np.sqrt(e2.mean(axis=0)).tolist()  # (B, N) per seed and UAV
    r = runs["ci-ekf"]
    scored = r["times"] >= spec.scoring.start
    ok = r["valid"][scored] & np.isfinite(r["range_err"][scored])
    abnormal = ok & (r["range_err"][scored] > ABNORMAL_RANGE_M)
    flagged = ok & (r["weights"][scored] < 1.0)
    raw["table6"] = {"abnormal_ratio": float(abnormal.sum() / ok.sum()),
                     "identified_ratio": float((abnormal & flagged).sum() / ok.sum()),
                     "detection_rate": float((abnormal & flagged).sum() / abnormal.sum()),
                     "false_alarm_ratio": float((flagged & ~abnormal).sum() / (ok & ~abnormal).sum())}
    a, b = (np.array(raw["rmse"][k]["rmse"]) for k in ("ci-ekf", "ci-ekf-no-aa"))
    fa, fb = (np.array(raw["rmse"][k]["fault_rmse"], dtype=float) for k in ("ci-ekf", "ci-ekf-no-aa"))
    raw["orderings"] = [paired(a, b, "ci-ekf < ci-ekf-no-aa (RMSE)"),
                        paired(fa, fb, "ci-ekf < ci-ekf-no-aa (RMSE at labelled-NLOS steps)")]
    raw["init_study"] = init_study(S)
    return _write(out, "dtvirm", _render_dtvirm(raw), raw)


def _render_dtvirm(raw: dict) -> str:
    t1 = raw["table1"]
    p1 = t1["paper"]
    n = len(raw["seeds"])
    lines = ["# dtvirm reproduction", "", "## Table 1 — swarm initialization (12 nodes, 0.5 m ranging error)", "",
             "| method | mean error ours (m) | 95 % CI | median ours (m) | ms/call ours | paper mean (m) "
             "| paper 95 % CI | paper ms |", "|---|---|---|---|---|---|---|---|"]
    for key, label in (("nls", "NLS (scipy LM, random start) / GTSAM"), ("mdsmap", "MDS-MAP (Algorithm 2)")):
        o, p = t1[key], p1[key]
        lines.append(f"| {label} | {o['mean_error_m']:.3f} | [{o['ci95_m'][0]:.3f}, {o['ci95_m'][1]:.3f}] "
                     f"| {o['median_error_m']:.3f} | {o['mean_ms']:.2f} | {p['mean_error_m']:.2f} "
                     f"| [{p['ci95_m'][0]:.2f}, {p['ci95_m'][1]:.2f}] "
                     f"| {p['mean_ms']:.1f} |")
    s = t1["scenario"]
    lines += ["", f"{s['trials']} trials, seed {s['seed']}, the scenario of `bench/mdsmap_compare.py` "
              f"({s['area_m']:g} m square, one {s['step_m']:g} m move; dtvirm does not state its own). The means "
              "carry the trials where the layout lands in the wrong mirror image or a local minimum; the medians "
              "show the typical accuracy.", "",
              "## Table 5 — UWB abnormality (swarmloc/AnchorFree-v0)", "",
              f"{n} test seeds ({raw['seeds'][0]} …); per-UAV RMSE [m] after the task's yaw + translation alignment "
              "(mean over seeds); 'avg' is the runner's pooled RMSE (mean ± std over seeds). Paper: AirSim, 50 m "
              "flights, VIO front end.", "",
              "| method | UAV1 | UAV2 | UAV3 | UAV4 | UAV5 | UAV6 | avg |", "|---|---|---|---|---|---|---|---|"]
    for label, per in raw["table5"].items():
        v = np.asarray(per).mean(axis=0)
        lines.append(f"| {label} (ours) | " + " | ".join(f"{x:.2f}" for x in v)
                     + f" | {_ms(raw['rmse'][label]['rmse'], 2)} |")
    for label, row in PAPER_DTVIRM_TABLE5.items():
        lines.append(f"| {label} (paper) | " + " | ".join(f"{x:.2f}" for x in row) + " |")
    lines += ["", "Ablations (runner RMSE, mean ± std over seeds):", "", "| variant | RMSE (m) |", "|---|---|"]
    for label, v in raw["rmse"].items():
        if label not in raw["table5"]:
            lines.append(f"| {label} | {_ms(v['rmse'], 2)} |")
    t6 = raw["table6"]
    p6 = PAPER_DTVIRM_TABLE6
    det = [x for x in raw["rmse"]["ci-ekf"]["anomaly_detection_rate"] if x is not None]
    lines += ["", "## Table 6 — UWB anomaly detection (ci-ekf, scored interval)", "",
              "| statistic | ours | paper |", "|---|---|---|",
              f"| anomaly ratio in raw UWB data (error > 1 m) | {100 * t6['abnormal_ratio']:.1f} % | {p6[0]:.1f} % |",
              f"| correctly identified anomaly ratio (χ² weight < 1) | {100 * t6['identified_ratio']:.1f} % "
              f"| {p6[1]:.1f} % |",
              f"| anomaly detection rate | {100 * t6['detection_rate']:.1f} % | {p6[2]:.0f} % |",
              f"| normal ranges flagged (false alarms) | {100 * t6['false_alarm_ratio']:.1f} % | — |",
              f"| runner `anomaly_detection_rate` (labelled channels, α < 0.5) | {100 * np.mean(det):.1f} % | — |",
              "", "### The paper's ordering (paired per-seed differences, 95 % bootstrap CI)", ""]
    lines += _ordering_table(raw["orderings"])
    lines += ["", "## Initializer window (MDS-MAP + odometry refinement, same seeds)", "",
              "| window | mirror failures | median shape error (m) | median yaw error (°) | 90th pct yaw (°) |",
              "|---|---|---|---|---|"]
    for w, st in raw["init_study"].items():
        lines.append(f"| {w} | {st['mirror_failures']}/{st['n']} | {st['median_shape_m']:.2f} "
                     f"| {st['median_yaw_deg']:.1f} | {st['p90_yaw_deg']:.1f} |")
    lines += ["", "In one second the other UAVs move less than ~1.2 m against 0.3 m ranging noise, so the yaw is "
              "poorly determined and the mirror image occasionally wrong; AnchorFree-v0 therefore scores from 2 s "
              "and `ci-ekf` initializes over 2 s. CI changes little here (all UAVs are about equally uncertain, "
              "and the CI bound lies between Pᵢ and Pⱼ); the adjustment is what matters. Our world's VO and IMU are world-frame (they stand in for dtvirm's "
              "compass), so after the alignment the error that remains is the drift of the swarm's common "
              "translation and the shape errors; absolute numbers are far below the paper's VIO-driven 5–9 m.", ""]
    return "\n".join(lines)


PAPERS = {"immarkf": reproduce_immarkf, "federated": reproduce_federated, "dtvirm": reproduce_dtvirm}
