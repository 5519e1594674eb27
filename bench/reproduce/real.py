"""The sim-to-real report: every registered method on suite ``real-v1`` (``swarmloc reproduce real``).

Per real flight (the TWR flight with Vicon-frame anchors and the eight UTIL TDOA flights)
the RMSE of every registered Track A and Track B method (mean over the suite's seeds; the
seed moves only the initial prior), the privileged oracle (labels from the truth
residuals) and each method's gap to it; the filtering rules' counts; an error-vs-time plot
of the line-of-sight and the metal-obstacle flight of the same circle (TDOA2 and TDOA3);
and what simulation training buys on real data: the learned methods (trained in simulation
only) against ``chi2-gate``, on the real flights and on their simulated twin ``TDOA-v1``.

Numbers come from the runner (``evaluate_methods``, the leaderboard's metrics). Nothing of
the data set is written, only metrics of estimates.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from swarmloc.agents.registry import LoadedMethod
from swarmloc.bench.evaluation.episode import EpisodeBatch, StepRecord, fly_episodes
from swarmloc.bench.evaluation.suites import REAL_V1_TASKS, TEST_SEED_START, Suite, get_suite
from swarmloc.bench.reports.markdown import markdown_table, report_path
from swarmloc.bench.reproduce.common import write_paper_report

#: the simulated twin of the TDOA flights (what a TDOA method would train on)
TDOA_SIM = "swarmloc/TDOA-v1"
#: line-of-sight and metal-obstacle flights of the same commanded circle, per mode
PLOT_PAIRS = (("swarmloc/UTILC0426Tdoa2NoLabel-v1", "swarmloc/UTILC0426Tdoa2WoodCardPlasticMetal-v1"),
              ("swarmloc/UTILC0426Tdoa3NoObs-v1", "swarmloc/UTILC0426Tdoa3WoodCardPlasticMetal-v1"))
PLOT_METHODS = ("uniform", "chi2-gate", "mappo", "mappo-set-gru", "oracle")
HEADLINE = ("uniform", "chi2-gate", "oracle", "mappo", "mappo-set-gru")
#: the issue's two criteria: uniform on a line-of-sight TDOA flight, oracle gain on a metal one
LOS_LIMIT, METAL_GAIN = 0.30, 0.20
#: |residual| beyond which a real range difference counts as a gross error (README's outlier count)
GROSS = 0.5


def _short(task: str) -> str:
    """``swarmloc/UTILC0426Tdoa2Wood-v1`` → ``C0426Tdoa2Wood``; ``swarmloc/UTILFlight-v1`` → ``UTILFlight-v1``."""
    name = task.removeprefix("swarmloc/")
    return name.removesuffix("-v1").removeprefix("UTIL") if "Tdoa" in name else name


def _is_los(task: str) -> bool:
    low = task.lower()
    return "tdoa" in low and any(k in low for k in ("los", "noobs", "nolabel"))


def _mean(values: list[float | None]) -> float | None:
    got = [v for v in values if v is not None]
    return float(np.mean(got)) if got else None


def _fmt(v: float | None, digits: int = 3) -> str:
    if v is None:
        return "—"
    return "∞" if not math.isfinite(v) else f"{v:.{digits}f}"


def _task_rmse(runs: dict, tasks: list[str]) -> dict[str, dict[str, float | None]]:
    """method → task → mean episode RMSE (None where the method did not run)."""
    out: dict[str, dict[str, float | None]] = {}
    for m, run in runs.items():
        out[m] = {t: _mean([e["metrics"]["rmse"] for e in run.episodes if e["task"] == t]) for t in tasks}
    return out


def _subset(name: str, tasks: tuple[str, ...], seeds: int) -> Suite:
    episodes = tuple((t, TEST_SEED_START + i) for t in tasks for i in range(seeds))
    return Suite(name, "1", episodes, f"{name}: {len(tasks)} task(s) × {seeds} test seed(s)")


class _WithoutGross:
    """The line-of-sight diagnosis flown through the episode loop: a Track A trust and an observer of its updates.

    Trust 0 for the range differences whose systematic error (the world's: the truth
    decides, so a diagnosis, never a method) exceeds ``GROSS``, 1 elsewhere; keeps the
    squared position error of every update.
    """

    flops_per_channel = 0.0

    def begin(self, batch: EpisodeBatch) -> None:
        self.world, self.sq = batch.world, []

    def reset(self, batch_size: int, layout: Any, keys: np.ndarray) -> None:
        pass

    def act(self, inp: Any) -> np.ndarray:
        gross = np.abs(self.world.buffers.systematic[..., 0]) > GROSS
        return np.where(gross, 0.0, 1.0)

    def observe(self, r: StepRecord) -> None:
        self.sq.append(float(np.sum((r.estimate - r.truth) ** 2)))


def flight_diagnostics(task: str, overrides: dict | None = None) -> dict[str, Any]:
    """The filtering rules' counts and the residual statistics of one real TDOA flight (privileged: truth).

    Also the diagnosis behind the line-of-sight criterion: the uniform CEKF's RMSE on the
    first test seed when the range differences whose residual exceeds ``GROSS`` are left
    out (the truth decides: a diagnosis, not a method).
    """
    from swarmloc.envs.tasks.catalogue import get_spec

    spec = get_spec(task, **(overrides or {}))
    diagnosis = _WithoutGross()
    loaded = LoadedMethod(name="uniform-without-gross", entry_point="uniform-without-gross", track="A",
                          privileged=False, deterministic=True, method=diagnosis)
    rec = fly_episodes(loaded, spec, [TEST_SEED_START], [diagnosis]).world.recording
    e = rec.residual[1:][rec.valid[1:]]
    c = rec.counts
    return {"logged": c.logged, "impossible": c.impossible, "outside": c.outside, "off_layout": c.off_layout,
            "superseded": c.superseded, "used": c.used,
            "robust_std": float(1.4826 * np.median(np.abs(e - np.median(e)))) if e.size else None,
            "gross_share": float(np.mean(np.abs(e) > GROSS)) if e.size else None,
            "fault_label_share": float(rec.label[1:].sum() / max(rec.valid[1:].sum(), 1)),
            "uniform_without_gross": float(np.sqrt(np.mean(diagnosis.sq))), "sigma": spec.sensors.tdoa.sigma,
            "imu_sigma": spec.sensors.imu_sigma, "channels": spec.n_channels}


def plot_error_vs_time(runs: dict, path: Path) -> Path | None:
    """Error vs time of ``PLOT_METHODS`` on the LOS and metal flights of ``PLOT_PAIRS`` (first seed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from swarmloc.bench.reports.method_style import method_styles

    styles = method_styles(PLOT_METHODS)
    traces = {(m, tr.task): tr for m in PLOT_METHODS if m in runs for tr in runs[m].traces}
    if not traces:
        return None
    fig, axes = plt.subplots(len(PLOT_PAIRS), 2, figsize=(11, 3.2 * len(PLOT_PAIRS)), sharey=True, squeeze=False)
    for row, pair in enumerate(PLOT_PAIRS):
        for col, task in enumerate(pair):
            ax = axes[row, col]
            for m in PLOT_METHODS:
                tr = traces.get((m, task))
                if tr is None:
                    continue
                err = tr.errors[:, tr.scored].mean(axis=1)
                ax.plot(tr.times, err, label=m, lw=0.8, **styles[m].line())
            ax.set_title(_short(task), fontsize=9)
            ax.set_xlabel("time since take-off [s]")
            ax.grid(alpha=0.3)
            if col == 0:
                ax.set_ylabel("position error [m]")
    axes[0, 0].legend(fontsize=8, loc="upper right")
    axes[0, 0].set_ylim(0, 1.5)
    fig.suptitle("real UTIL TDOA flights, same circle: line of sight (left) vs metal obstacles (right)", fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def reproduce_real(out: str | Path, methods: list[str] | None = None, *, workers: int = 2, seeds: int = 4,
                   tasks: tuple[str, ...] = REAL_V1_TASKS, overrides: dict | None = None,
                   progress: bool = True) -> Path:
    """Run every method on ``real-v1`` (and ``TDOA-v1``) and write the report.

    Args:
        out: the Markdown file, or a folder (``<out>/real.md``); the numbers go beside it as
            ``.json``, the plot as ``real_error_vs_time.png``.
        methods: method names (default: every registered one).
        workers: worker processes.
        seeds: test seeds per task, 1 … 4 (the suite's 4 by default).
        tasks: the real-v1 tasks to run (default: all).
        overrides: task-spec overrides (shortened episodes in tests; then not the suite's numbers).
        progress: progress bars.

    Returns:
        The report path.

    Raises:
        FileNotFoundError: the real flights' data is not here (the message says where it comes from).
        ValueError: ``seeds`` outside 1 … 4, or a task outside real-v1.
    """
    from swarmloc.agents.registry import method_names
    from swarmloc.bench.evaluation.runner import evaluate_methods
    from swarmloc.bench.evaluation.suites import require_data
    from swarmloc.envs.tasks.catalogue import get_spec

    full = get_suite("real-v1")
    if not 1 <= seeds <= 4:
        raise ValueError(f"seeds must be in 1 … 4 (the suite's), got {seeds}")
    unknown = [t for t in tasks if t not in full.tasks]
    if unknown:
        raise ValueError(f"tasks {unknown} are not in real-v1; choose from {full.tasks}")
    suite = full if (seeds == 4 and tuple(tasks) == tuple(full.tasks)) else _subset("real-v1-subset", tasks, seeds)
    require_data(suite)
    methods = list(methods or method_names())
    sim = _subset("tdoa-sim", (TDOA_SIM,), seeds)
    real_runs = evaluate_methods(methods, suite, workers=workers, progress=progress, overrides=overrides)
    sim_runs = evaluate_methods(methods, sim, workers=workers, progress=progress, trace=False, overrides=overrides)
    twr_v0 = None
    if "swarmloc/UTILFlight-v1" in tasks and "uniform" in methods:
        v0 = _subset("real-v0-subset", ("swarmloc/UTILFlight-v0",), seeds)
        twr_v0 = _task_rmse(evaluate_methods(["uniform"], v0, workers=1, progress=False, trace=False,
                                             overrides=overrides), list(v0.tasks))["uniform"]["swarmloc/UTILFlight-v0"]
    real = _task_rmse(real_runs, list(suite.tasks))
    simulated = {m: v[TDOA_SIM] for m, v in _task_rmse(sim_runs, [TDOA_SIM]).items()}
    tdoa_tasks = [t for t in suite.tasks if "Tdoa" in t]
    diagnostics = {t: flight_diagnostics(t, overrides) for t in tdoa_tasks}
    path = report_path(out, "real")
    plot = plot_error_vs_time(real_runs, path.with_name("real_error_vs_time.png"))
    reasons = {m: {**run.unsupported, **run.failed} for m, run in real_runs.items()}
    text = _render(suite, methods, real, simulated, diagnostics, reasons, twr_v0, plot, seeds, overrides)
    raw = {"suite": suite.name, "suite_sha256": suite.sha256, "seeds": seeds, "overrides": overrides or {},
           "rmse": real, "tdoa_sim_rmse": simulated, "diagnostics": diagnostics, "not_run": reasons,
           "twr_v0_uniform_rmse": twr_v0, "specs": {t: get_spec(t).model_dump(mode="json") for t in suite.tasks}}
    return write_paper_report(path, "real", text, raw)


def _privileged(method: str) -> bool:
    from swarmloc.agents.registry import REGISTRY

    return method in REGISTRY and REGISTRY[method].privileged


def _gain(u: float | None, m: float | None) -> float | None:
    """log2(u / m): doublings of accuracy over ``u`` (None when either is missing or not positive)."""
    if u is None or m is None or not (u > 0 and m > 0) or not (math.isfinite(u) and math.isfinite(m)):
        return None
    return math.log2(u / m)


def _render(suite: Suite, methods: list[str], real: dict, simulated: dict, diagnostics: dict, reasons: dict,
            twr_v0: float | None, plot: Path | None, seeds: int, overrides: dict | None) -> str:
    from swarmloc.agents.registry import REGISTRY

    tasks = list(suite.tasks)
    tdoa = [t for t in tasks if "Tdoa" in t]
    col = {m: real.get(m, {}) for m in methods}
    lines = ["# Real flights: every method on `real-v1` (the sim-to-real report)", "",
             ("Generated by `swarmloc reproduce real` (`bench/reproduce/real.py`) from the runner's metrics: RMSE "
             f"over the airborne window, mean over {seeds} test seed(s) (the seed moves only the initial prior; "
             "every seed replays the same recording). The UTIL data set [util] is not shipped; the numbers are "
             "ours. The oracle is privileged: it skips the range differences whose error labels are set "
             "(|residual against the truth| > k·σ, the TWR flight's rule)."), ""]
    if overrides:
        lines += [f"**Not the suite's numbers: task overrides {overrides}.**", ""]

    # ---- headline per flight
    lines += ["## Per flight", ""]
    rows = []
    for t in tasks:
        u, o = col.get("uniform", {}).get(t), col.get("oracle", {}).get(t)
        check = ""
        if _is_los(t) and u is not None:
            check = f"LOS: uniform ≤ {LOS_LIMIT:.2f} m {'yes' if u <= LOS_LIMIT else '**no**'}"
        elif "metal" in t.lower() and u is not None and o is not None:
            check = f"metal: oracle −{(1 - o / u):.0%} {'yes' if o <= (1 - METAL_GAIN) * u else '**no**'}"
        fair = {m: v[t] for m, v in col.items() if not _privileged(m) and v.get(t) is not None}
        best = min(fair, key=fair.get) if fair else None
        rows.append([f"`{_short(t)}`"] + [_fmt(col.get(m, {}).get(t)) for m in HEADLINE]
                    + [f"`{best}` {_fmt(fair[best])}" if best else "—", check])
    lines += markdown_table(["flight"] + [f"{m} [m]" for m in HEADLINE] + ["best non-privileged [m]", "criterion"],
                            rows, "l" + "r" * len(HEADLINE) + "ll")
    if twr_v0 is not None and "swarmloc/UTILFlight-v1" in tasks:
        v1 = col.get("uniform", {}).get("swarmloc/UTILFlight-v1")
        lines += ["", (f"The TWR flight with Vicon-frame anchors (`UTILFlight-v1`): uniform {_fmt(v1)} m, beside "
                  f"{_fmt(twr_v0)} m with the raw total-station anchors (`UTILFlight-v0`).")]

    # ---- the data rules
    if tdoa:
        lines += ["", "## The TDOA flights' filtering rules and residuals", "",
                  ("Rows of `tdoa.csv.gz` per rule (`envs/recorded/tdoa_flight.py`): impossible (|tdoa| > the "
                  "pair's anchor baseline, dropped), outside the airborne window (on the floor), off the "
                  "task's pairs, superseded by a later arrival in the same 10 ms step, used. Residuals of the "
                  "used rows against the truth (the UWB tag): pooled robust std (1.4826·MAD), share beyond "
                  f"{GROSS} m, share with a fault label (|residual| > 3σ). Noise settings of each task (measured: "
                  "`envs/tasks/catalogue.py`)."), ""]
        rows = []
        for t in tdoa:
            d = diagnostics[t]
            rows.append([f"`{_short(t)}`", str(d["channels"]), str(d["logged"]), str(d["impossible"]),
                         str(d["outside"]), str(d["off_layout"]), str(d["superseded"]), str(d["used"]),
                         _fmt(d["robust_std"]), f"{d['gross_share']:.1%}", f"{d['fault_label_share']:.1%}",
                         f"{d['sigma']:g}", f"{d['imu_sigma']:g}"])
        lines += markdown_table(["flight", "L", "logged", "impossible", "outside", "off-layout", "superseded",
                                 "used", "robust std [m]", f"> {GROSS} m", "fault label", "σ [m]", "σ_imu [m/s²]"],
                                rows, "lrrrrrrrrrrrr")
        los = [t for t in tdoa if _is_los(t)]
        if los:
            lines += ["", (f"**Line of sight.** Uniform against {LOS_LIMIT:.2f} m and the diagnosis: the uniform "
                      f"CEKF with the range differences beyond {GROSS} m left out (the truth decides; first seed)."),
                      ""]
            rows = [[f"`{_short(t)}`", _fmt(col.get("uniform", {}).get(t)),
                     _fmt(diagnostics[t]["uniform_without_gross"]), f"{diagnostics[t]['gross_share']:.1%}"]
                    for t in los]
            lines += markdown_table(["flight", "uniform [m]", f"uniform without > {GROSS} m [m]",
                                     f"share > {GROSS} m"], rows, "lrrr")

    # ---- every method
    lines += ["", "## Every registered method", "",
              ("RMSE [m] per flight; `—`: the method cannot run the task (reason below). Last columns: the mean "
              "gap to the oracle over the flights it ran, and the simulated TDOA room `TDOA-v1`."), ""]
    rows = []
    oracle = col.get("oracle", {})
    for m in methods:
        gaps = [col[m][t] - oracle[t] for t in tasks
                if col[m].get(t) is not None and oracle.get(t) is not None and math.isfinite(col[m][t])]
        track = REGISTRY[m].track if m in REGISTRY else "?"
        rows.append([f"`{m}` ({track})"] + [_fmt(col[m].get(t)) for t in tasks]
                    + [_fmt(float(np.mean(gaps)) if gaps else None), _fmt(simulated.get(m))])
    lines += markdown_table(["method"] + [f"`{_short(t)}`" for t in tasks] + ["gap to oracle", "`TDOA-v1`"],
                            rows, "l" + "r" * (len(tasks) + 2))

    # ---- learned vs chi2-gate
    learned = [m for m in methods if "mappo" in m or m == "pf-nn"]
    if "chi2-gate" in col and learned:
        lines += ["", "## What simulation training buys on real data", "",
                  ("The learned methods are trained in simulation only: `mappo`, its ablations and `mappo-set-gru` "
                   "on the v1 randomized families (the weights of the flight's benchmark version), `pf-nn` on the "
                   "Indoor task of the flight's version (none saw TDOA). "
                  "Gain over chi2-gate = log2(RMSE_chi2-gate / RMSE): +1 is half the error, −1 twice it. "
                  "Mean over the real TDOA flights beside the same on the simulated twin `TDOA-v1` and against "
                  "uniform."), ""]
        rows = []
        for m in learned + ["chi2-gate", "uniform"]:
            real_g = [g for t in tdoa if (g := _gain(col["chi2-gate"].get(t), col[m].get(t))) is not None]
            real_u = [g for t in tdoa if (g := _gain(col.get("uniform", {}).get(t), col[m].get(t))) is not None]
            sim_g = _gain(simulated.get("chi2-gate"), simulated.get(m))
            sim_u = _gain(simulated.get("uniform"), simulated.get(m))
            rows.append([f"`{m}`", _fmt(float(np.mean(real_g)) if real_g else None, 2), f"{len(real_g)}/{len(tdoa)}",
                         _fmt(sim_g, 2), _fmt(float(np.mean(real_u)) if real_u else None, 2), _fmt(sim_u, 2)])
        lines += markdown_table(["method", "real: gain over chi2-gate", "flights", "sim TDOA-v1: over chi2-gate",
                                 "real: over uniform", "sim: over uniform"], rows, "lrrrrr")
    if plot is not None:
        lines += ["", "## Error vs time", "", f"![error vs time]({plot.name})", "",
                  ("First test seed; the same commanded circle (r 1.5 m, ω 0.6 rad/s, 4 rounds) with and without "
                  "the metal obstacles, TDOA2 (top) and TDOA3 (bottom).")]
    shown = {m: r for m, r in reasons.items() if r}
    if shown:
        lines += ["", "## Not run", ""]
        for m, r in shown.items():
            # one line per distinct reason: the task's own ID is replaced by "the task"
            why = sorted({w.splitlines()[0].replace(f"{m} cannot run {t}: ", "").replace(f"task {t}", "the task")
                          .replace(t, "the task") for t, w in r.items()})
            lines.append(f"- `{m}` ({len(r)} task(s)): " + "; ".join(w[:200] for w in why))
    return "\n".join(lines) + "\n"


__all__ = ["flight_diagnostics", "plot_error_vs_time", "reproduce_real"]
