"""``swarmloc reproduce labels``: the calibration of the error labels (``swarmloc.envs.world.labels``).

The oracle on the error labels must be the ceiling of the trust policies and still an estimator.
On every standard-v0 task (its 32 test seeds) this report runs the oracle at several label
thresholds through the runner (``evaluate_methods``, the leaderboard's metrics) and compares
it, per seed, with

* the best shipped non-privileged Track A method (``bench/results``): the oracle must
  not be worse (paired 95 % bootstrap CI of the difference not above 0); on
  CascadedFault-v0 its healthy-node RMSE must be below mappo's;
* the information bound (``bound_rmse``): the oracle's task mean must not be below the
  bound's. A trust policy on the CEKF uses no more than the unlabelled measurements and the
  IMU, the bound's information; an oracle below it chooses the links by the truth of the
  neighbours' errors, i.e. it picks favourable noise rather than cutting faults.

Three tables: the scalar k (anchor and peer ranges) with the shipped 3-vector radius; the
3-vector radius (GPS, relative position) with the shipped k, on the tasks that have such
channels; and one k for every channel (the Mahalanobis norm of a 3-vector channel against k
itself). The shipped thresholds are ``LABEL_SIGMAS`` and ``VECTOR_LABEL_SIGMAS``.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from swarmloc.agents.trust.classical import ALPHA_MIN, OracleTrust
from swarmloc.bench.reports.markdown import markdown_table
from swarmloc.bench.reproduce.common import paired, write_paper_report
from swarmloc.envs.tasks.channels import GPS, PEER_REL, build_layout
from swarmloc.envs.world.labels import LABEL_SIGMAS, VECTOR_LABEL_SIGMAS, equivalent_radius
from swarmloc.envs.tasks.catalogue import get_spec

CASCADED = "swarmloc/CascadedFault-v0"
_HERE = "swarmloc.bench.reproduce.labels"


# ---------------------------------------------------------------------------- the oracle variants
# (module-level factories: the runner's worker processes load them as entry points)


def oracle_k1() -> OracleTrust:
    """k = 1 for ranges, the shipped 3-vector radius."""
    return OracleTrust(ALPHA_MIN, 1.0)


def oracle_k2() -> OracleTrust:
    """k = 2 for ranges, the shipped 3-vector radius."""
    return OracleTrust(ALPHA_MIN, 2.0)


def oracle_k3() -> OracleTrust:
    """k = 3 for ranges, the shipped 3-vector radius."""
    return OracleTrust(ALPHA_MIN, 3.0)


def oracle_vector_1sigma() -> OracleTrust:
    """The shipped k; 3-vector channels at the 1σ false-alarm radius (1.88)."""
    return OracleTrust(ALPHA_MIN, LABEL_SIGMAS, equivalent_radius(1.0, 3))


def oracle_vector_2sigma() -> OracleTrust:
    """The shipped k; 3-vector channels at the 2σ false-alarm radius (2.83)."""
    return OracleTrust(ALPHA_MIN, LABEL_SIGMAS, equivalent_radius(2.0, 3))


def oracle_single_k1() -> OracleTrust:
    """k = 1 for every channel (3-vector channels: Mahalanobis norm > 1)."""
    return OracleTrust(ALPHA_MIN, 1.0, 1.0)


def oracle_single_k2() -> OracleTrust:
    """k = 2 for every channel."""
    return OracleTrust(ALPHA_MIN, 2.0, 2.0)


def oracle_single_k3() -> OracleTrust:
    """k = 3 for every channel."""
    return OracleTrust(ALPHA_MIN, 3.0, 3.0)


#: table → [(column title, method: a registered name or an entry point of this module)]
TABLES: dict[str, list[tuple[str, str]]] = {
    "scalar k (ranges), 3-vector radius as shipped": [
        ("k = 1", f"{_HERE}:oracle_k1"), (f"k = {LABEL_SIGMAS:g} (shipped)", "oracle"),
        ("k = 2", f"{_HERE}:oracle_k2"), ("k = 3", f"{_HERE}:oracle_k3")],
    f"3-vector radius, k = {LABEL_SIGMAS:g}": [
        ("1σ: r = 1.88", f"{_HERE}:oracle_vector_1sigma"), ("2σ: r = 2.83", f"{_HERE}:oracle_vector_2sigma"),
        (f"{VECTOR_LABEL_SIGMAS:g}σ: r = {equivalent_radius(VECTOR_LABEL_SIGMAS, 3):.2f} (shipped)", "oracle")],
    "one k for every channel": [
        ("k = 1", f"{_HERE}:oracle_single_k1"), ("k = 2", f"{_HERE}:oracle_single_k2"),
        ("k = 3", f"{_HERE}:oracle_single_k3")],
}
#: the tables shown only on tasks with 3-vector channels (elsewhere they equal the first table)
VECTOR_TABLES = ("3-vector radius", "one k for every channel")
#: on a task without 3-vector channels a variant of those tables labels exactly as this one
SAME_ON_RANGE_TASKS = {f"{_HERE}:oracle_vector_1sigma": "oracle", f"{_HERE}:oracle_vector_2sigma": "oracle",
                       f"{_HERE}:oracle_single_k1": f"{_HERE}:oracle_k1",
                       f"{_HERE}:oracle_single_k2": f"{_HERE}:oracle_k2",
                       f"{_HERE}:oracle_single_k3": f"{_HERE}:oracle_k3"}


def has_vector_channels(task: str) -> bool:
    """The task has a GPS or relative-position channel (what the 3-vector radius acts on)."""
    kind = build_layout(get_spec(task)).kind
    return bool(((kind == GPS) | (kind == PEER_REL)).any())


# ---------------------------------------------------------------------------- the numbers


def shipped_per_seed(results_dir: Path, tasks: Sequence[str], seeds: dict[str, list[int]]) -> dict[str, Any]:
    """Per-seed ``rmse`` and ``healthy_rmse`` of the shipped non-privileged Track A methods.

    Returns:
        method → task → {"rmse": [...], "healthy_rmse": [...]} in ``seeds[task]`` order
        (methods missing an episode are left out of that task).
    """
    out: dict[str, Any] = {}
    for path in sorted(Path(results_dir).glob("*.json")):
        data = json.loads(path.read_text())
        method = data["method"]
        if method["privileged"] or method["track"] != "A":
            continue
        by = {(e["task"], e["seed"]): e["metrics"] for e in data["episodes"]}
        for task in tasks:
            rows = [by.get((task, s)) for s in seeds[task]]
            if all(r is not None and r["rmse"] is not None for r in rows):
                out.setdefault(method["name"], {})[task] = {
                    key: [r[key] for r in rows] for key in ("rmse", "healthy_rmse")}
    return out


def _compare(oracle: np.ndarray, other: np.ndarray) -> dict[str, Any]:
    """Paired oracle − other: mean, CI and the verdict ``better`` / ``tie`` / ``worse``."""
    row = paired(oracle, other, "oracle < other")
    row["verdict"] = "better" if row["significant"] else ("worse" if row["contradicted"] else "tie")
    return row


def task_summary(episodes: list[dict], task: str, seeds: list[int], shipped: dict[str, Any]) -> dict[str, Any]:
    """One oracle variant on one task: means, the best shipped method, the bound, the verdicts."""
    by = {e["seed"]: e["metrics"] for e in episodes if e["task"] == task}
    rmse = np.array([by[s]["rmse"] for s in seeds], dtype=float)
    bound = np.array([np.nan if by[s]["bound_rmse"] is None else by[s]["bound_rmse"] for s in seeds])
    uniform = np.array([by[s]["uniform_rmse"] for s in seeds], dtype=float)
    means = {m: float(np.mean(v[task]["rmse"])) for m, v in shipped.items() if task in v}
    best = min(means, key=means.get)
    out: dict[str, Any] = {
        "rmse": float(rmse.mean()), "uniform": float(uniform.mean()), "best": best, "best_rmse": means[best],
        "vs_best": _compare(rmse, np.array(shipped[best][task]["rmse"], dtype=float)),
        "bound": None if np.isnan(bound).any() else float(bound.mean()),
        # oracle − bound, paired (for the record); the verdict reads the task means
        "vs_bound": None if np.isnan(bound).any() else _compare(rmse, bound),
        "below_bound": bool(not np.isnan(bound).any() and rmse.mean() < bound.mean()),
    }
    if task == CASCADED:
        healthy = np.array([by[s]["healthy_rmse"] for s in seeds], dtype=float)
        mappo = np.array(shipped["mappo"][task]["healthy_rmse"], dtype=float)
        out.update(healthy=float(healthy.mean()), mappo_healthy=float(mappo.mean()),
                   healthy_vs_mappo=_compare(healthy, mappo))
    return out


def failures(summary: dict[str, Any]) -> list[str]:
    """What a variant's task summary fails of the calibration's conditions (empty: it passes)."""
    why = []
    if summary["vs_best"]["verdict"] == "worse":
        why.append(f"worse than {summary['best']}")
    if summary["below_bound"]:
        why.append("below the bound")
    if "healthy" in summary and not summary["healthy"] < summary["mappo_healthy"]:
        why.append("healthy RMSE not below mappo's")
    return why


# ---------------------------------------------------------------------------- the report


def _cell(s: dict[str, Any]) -> str:
    mark = {"better": "", "tie": " =", "worse": " ✗"}[s["vs_best"]["verdict"]]
    low = " ↓bound" if s["below_bound"] else ""
    return f"{s['rmse']:.4f} ({s['rmse'] / s['best_rmse']:.3f}{mark}{low})"


def table_lines(title: str, columns: list[tuple[str, str]], tasks: list[str],
                summaries: dict[str, dict[str, Any]]) -> list[str]:
    """One Markdown table: task, bound, uniform, best shipped, the variants' oracle RMSE."""
    header = ["task", "bound", "uniform", "best non-privileged"] + [c for c, _ in columns]
    rows = []
    for task in tasks:
        first = summaries[columns[0][1]][task]
        bound = "—" if first["bound"] is None else f"{first['bound']:.4f}"
        rows.append([task.removeprefix("swarmloc/"), bound, f"{first['uniform']:.4f}",
                     f"{first['best_rmse']:.4f} {first['best']}"] + [_cell(summaries[m][task]) for _, m in columns])
    verdict = ["**passes**", "", "", ""] + [
        "yes" if not any(failures(summaries[m][t]) for t in tasks) else "no" for _, m in columns]
    return [f"### {title}", ""] + markdown_table(header, rows + [verdict], "lrrl" + "r" * len(columns)) + [""]


def reproduce_labels(out: Path, workers: int = 2, seeds: int = 32, results_dir: Path | None = None,
                     progress: bool = True) -> Path:
    """Run the calibration and write the Markdown report (+ ``.json``); returns its path.

    Args:
        out: Markdown file or folder (``<out>/labels.md``).
        workers: worker processes of the runner.
        seeds: test seeds per task (the first ``seeds`` of standard-v0's 32), at least 2.
        results_dir: the shipped results (default: ``bench/results``).
        progress: show the runner's progress bars.
    """
    from swarmloc.bench.evaluation.runner import evaluate_methods
    from swarmloc.bench.evaluation.suites import Suite, get_suite
    from swarmloc.bench.evaluation.shipped import RESULTS_DIRS

    if not 2 <= seeds <= 32:
        raise ValueError(f"seeds must be in [2, 32] (standard-v0's test seeds), got {seeds}")
    standard = get_suite("standard-v0")
    tasks = standard.tasks
    by_task = {t: standard.seeds(t)[:seeds] for t in tasks}
    vector_tasks = [t for t in tasks if has_vector_channels(t)]
    episodes = lambda ts: tuple((t, s) for t in ts for s in by_task[t])  # noqa: E731
    shipped = shipped_per_seed(results_dir or RESULTS_DIRS["standard-v0"], tasks, by_task)

    everywhere = sorted({m for _, m in TABLES["scalar k (ranges), 3-vector radius as shipped"]})
    vector_only = sorted({m for title, cols in TABLES.items() if title.startswith(VECTOR_TABLES)
                          for _, m in cols} - set(everywhere))
    runs: dict[str, list[dict]] = {}
    for methods, ts in ((everywhere, tasks), (vector_only, vector_tasks)):
        suite = Suite("labels-calibration", "1", episodes(ts), "standard-v0 tasks × test seeds")
        for m, run in evaluate_methods(methods, suite, workers=workers, trace=False, progress=progress).items():
            if run.failed:
                raise RuntimeError(f"{m} failed on {sorted(run.failed)}: {next(iter(run.failed.values()))}")
            runs[m] = run.episodes
    summaries = {m: {t: task_summary(eps, t, by_task[t], shipped) for t in tasks if any(e["task"] == t for e in eps)}
                 for m, eps in runs.items()}
    for m, same in SAME_ON_RANGE_TASKS.items():  # the range-only tasks, for the verdict
        summaries[m] = {t: summaries[m].get(t, summaries[same][t]) for t in tasks}

    lines = _intro(seeds)
    for title, columns in TABLES.items():
        lines += table_lines(title, columns, vector_tasks if title.startswith(VECTOR_TABLES) else tasks,
                             summaries)
    lines += _cascaded(summaries)
    lines += _verdict(summaries, tasks)
    raw = {"seeds": seeds, "tables": TABLES, "summaries": summaries,
           "label_sigmas": LABEL_SIGMAS, "vector_label_sigmas": VECTOR_LABEL_SIGMAS,
           "vector_radius": equivalent_radius(VECTOR_LABEL_SIGMAS, 3)}
    return write_paper_report(out, "labels", "\n".join(lines) + "\n", raw)


def _intro(seeds: int) -> list[str]:
    r = equivalent_radius(VECTOR_LABEL_SIGMAS, 3)
    return [
        "# Error labels: calibrating k",
        "",
        "A channel-step is labelled when its systematic error as the filter uses it (injected bias, GPS",
        "drift, heavy-tail excess; for a peer link the neighbour's broadcast-estimate error) exceeds a",
        "threshold in units of σ_eff (`swarmloc.envs.world.labels`): k for a scalar range, a Mahalanobis radius",
        f"for a 3-vector channel (GPS, relative position). Shipped: **k = {LABEL_SIGMAS:g}** and the radius",
        f"of a {VECTOR_LABEL_SIGMAS:g}σ false alarm, **r = {r:.2f}**. The `oracle` gives α_min to every labelled",
        "channel. Cells: the oracle's task-mean RMSE [m] over "
        f"{seeds} test seeds and its ratio to the best shipped",
        "non-privileged Track A method (`bench/results`); `=` not resolved from it (paired 95 %",
        "bootstrap CI of the difference contains 0), `✗` significantly worse, `↓bound` task mean below",
        "the information bound's (`bound_rmse`). A trust policy on the CEKF has no more information than",
        "the bound (the unlabelled measurements and the IMU); an oracle below it chooses links by the truth",
        "of the neighbours' errors, i.e. it keeps favourable noise rather than cutting faults. A variant",
        "**passes** when no cell has `✗` or `↓bound` and, on CascadedFault-v0, its healthy-node RMSE is",
        "below mappo's.",
        "",
    ]


def _cascaded(summaries: dict[str, dict[str, Any]]) -> list[str]:
    rows = []
    for title, columns in TABLES.items():
        if title.startswith(VECTOR_TABLES):
            continue
        for name, m in columns:
            s = summaries[m][CASCADED]
            rows.append([name, f"{s['healthy']:.3f}", f"{s['mappo_healthy']:.3f}",
                         "below" if s["healthy"] < s["mappo_healthy"] else "not below",
                         s["healthy_vs_mappo"]["verdict"]])
    return (["### CascadedFault-v0: healthy-node RMSE (UAVs 0 and 3 over the fault window 20–35 s)", ""]
            + markdown_table(["oracle", "healthy RMSE", "mappo", "mean", "paired CI"], rows, "lrrll") + [""])


def _verdict(summaries: dict[str, dict[str, Any]], tasks: list[str]) -> list[str]:
    lines = ["### Verdict (every task; a 3-vector variant labels as its first-table twin on the others)", ""]
    for title, columns in TABLES.items():
        for name, m in columns:
            why = [f"{t.removeprefix('swarmloc/')}: {', '.join(f)}" for t in tasks if t in summaries[m]
                   for f in [failures(summaries[m][t])] if f]
            lines.append(f"- {title}, {name}: " + ("passes" if not why else "fails — " + "; ".join(why)))
    return lines + ["", f"Shipped: k = {LABEL_SIGMAS:g} for ranges, the {VECTOR_LABEL_SIGMAS:g}σ false-alarm radius for 3-vector "
                    "channels (`envs/world/labels.py`).", ""]
