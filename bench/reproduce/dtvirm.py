"""``swarmloc reproduce dtvirm``: dtvirm Tables 1, 5 and 6 on AnchorFree-v0.

Table 1 (MDS-MAP vs NLS, ``bench/reproduce/mdsmap_compare.py``), Table 5 (per-UAV RMSE:
``ci-ekf`` = COO_OUR, ``ci-ekf-no-aa`` = without UWB_AA, plus our ablations), Table 6
(anomaly statistics of the χ² UWB adjustment) and the ordering ci-ekf < ci-ekf-no-aa.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from swarmloc.agents.estimators.ci_ekf import ci_ekf, ci_ekf_no_aa
from swarmloc.agents.protocols import Measurements, TaskFacts, episode_keys
from swarmloc.bench.evaluation.runner import single_threaded_kernels
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
from swarmloc.envs.world.sim import World

#: dtvirm Table 5 (UWB abnormality): per UAV 1–6 and average RMSE [m]
PAPER_DTVIRM_TABLE5 = {"COO_VIR": (8.23, 11.12, 10.89, 12.01, 12.34, 13.76, 11.39),
                       "COO_OUR (ci-ekf)": (4.12, 6.56, 6.34, 7.11, 7.67, 7.03, 6.47),
                       "COO_OUR without_UWB_AA (ci-ekf-no-aa)": (5.89, 8.43, 8.12, 9.26, 9.87, 8.75, 8.39)}
#: dtvirm Table 6: anomaly ratio in raw UWB data, correctly identified ratio, detection rate [%]
PAPER_DTVIRM_TABLE6 = (20.0, 18.6, 93.0)
ABNORMAL_RANGE_M = 1.0  # dtvirm §4.4: a range more than 1 m off the truth is abnormal


def init_study(seeds: list[int], windows: tuple[float, ...] = (1.0, 2.0, 3.0)) -> dict[str, dict]:
    """MDS-MAP initializer on AnchorFree-v0 per window length: mirror failures, yaw and shape errors."""
    from swarmloc.agents.estimators.init.initializer import InitConfig, MdsMapInitializer
    from swarmloc.bench.evaluation.alignment import yaw_translation_fit

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
    from swarmloc.bench.reproduce.mdsmap_compare import compare_mdsmap_nls

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
    return write_paper_report(out, "dtvirm", _render_dtvirm(raw), raw)


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
    lines += ["", f"{s['trials']} trials, seed {s['seed']}, the scenario of `bench/reproduce/mdsmap_compare.py` "
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
                     + f" | {mean_sd(raw['rmse'][label]['rmse'], 2)} |")
    for label, row in PAPER_DTVIRM_TABLE5.items():
        lines.append(f"| {label} (paper) | " + " | ".join(f"{x:.2f}" for x in row) + " |")
    lines += ["", "Ablations (runner RMSE, mean ± std over seeds):", "", "| variant | RMSE (m) |", "|---|---|"]
    for label, v in raw["rmse"].items():
        if label not in raw["table5"]:
            lines.append(f"| {label} | {mean_sd(v['rmse'], 2)} |")
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
    lines += ordering_table(raw["orderings"])
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
