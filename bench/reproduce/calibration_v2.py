"""``swarmloc reproduce calibration --version 2``: which v2 tasks are admitted to the headline → docs/calibration-v2.*.

Benchmark v2 admits a task to its track's headline only where it measures what the track is
about (docs/benchmark-v2.md). The criteria are computed on **dev seeds only**
(``DEV_SEED_START`` …), before any test-seed evaluation, and the suites freeze what they say
(``suites.STANDARD_V2_TASKS`` and the hash of the rows, ``suites.CALIBRATION_V2_SHA256``; a test
holds both equal to ``docs/calibration-v2.json``). Per task, on the same dev seeds:

a. *cooperation carries information* (cooperative track): the bound with every peer channel
   removed ≥ ``PEER_INFORMATION_RATIO`` × the bound (task means of ``bound_rmse``);
b. *the fault matters*: uniform ≥ ``FAULT_RATIO`` × uniform on the same episodes with the
   faults removed (``spec.faults`` emptied: same truth, same noise draws);
c. *the bound is attainable*: ``centralized-oracle`` within ``ATTAINABLE_RATIO`` × the bound on
   the fault-free counterpart;
d. *headroom that is not a lock-out*, judged over each track: the single-step gates
   (``chi2-soft``, ``chi2-gate``) close between 0 and ``GAP_CLOSED_MAX`` of the achievable gap
   (score v1's gap closed against the bound) on at least half of the track's fault tasks that pass
   the other criteria (the headline the track would have); a task's row carries its own value and
   the track's verdict;
e. *a kind rule is not enough* (cooperative track): ``non-cooperative`` ≥ ``KIND_RULE_RATIO`` ×
   the oracle's RMSE;
f. *ceiling valid*: no non-privileged method below the bound, the oracle no worse than any of them
   (paired 95 % bootstrap CIs, ``calibration_criteria.ceiling_valid``);
g. *nothing degenerate*: ``random`` ≥ 10 % worse than the best method
   (``calibration_criteria.not_degenerate``).

A task passes when every criterion that applies to it passes; it is then ``in_headline``. A row's
``criteria`` hold the criteria that apply (name → ``value``, ``pass``, ``measured``), its ``not_applicable``
the others with the reason (a and e on the robust-ranging track, b and d on a task without faults). Beside the
criteria each row gives the task means the report's tables read (uniform, oracle,
non-cooperative, centralized-oracle, the bounds), so the per-family uniform/bound and oracle/bound
ratios come from the same runs.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from swarmloc.bench.common.files import write_text_atomic
from swarmloc.bench.common.provenance import collect_provenance
from swarmloc.bench.evaluation.outcomes import TaskOutcome
from swarmloc.bench.evaluation.suites import DEV_SEED_START
from swarmloc.bench.reproduce import calibration_criteria as C
from swarmloc.bench.reproduce.calibration import run_methods
from swarmloc.bench.scoring.families import group_by_family, task_family, task_label, task_split
from swarmloc.envs.tasks.catalogue import canonical_task_id, get_spec
from swarmloc.envs.tasks.specs import Faults, TaskSpec
from swarmloc.envs.tasks.v2 import CATALOGUE_V2

#: a: the bound with the peers removed, at least this many times the bound
PEER_INFORMATION_RATIO = 1.5
#: b: uniform at least this many times uniform with the faults removed
FAULT_RATIO = 1.5
#: c: centralized-oracle within this many times the bound, faults removed
ATTAINABLE_RATIO = 1.3
#: d: the gates close at most this share of the achievable gap (and no less than 0) …
GAP_CLOSED_MAX = C.GAP_CLOSED_MAX
#: … on at least this share of the track's fault tasks
HEADROOM_TASK_FRACTION = C.HEADROOM_TASK_FRACTION
#: e: non-cooperative at least this many times the oracle's RMSE
KIND_RULE_RATIO = 1.25
#: dev seeds per task (2_000_000 …)
DEFAULT_SEEDS = 8
CENTRAL = "centralized-oracle"
PRIVILEGED = ("oracle", CENTRAL)
#: the methods run with the faults on (``non-cooperative`` on the cooperative track only)
METHODS = ("uniform", "oracle", CENTRAL, "chi2-gate", "chi2-soft", "huber", "fixed", "cusum", "raim", "random")
CRITERIA = ("peer_information", "fault_matters", "attainable", "headroom", "kind_rule", "ceiling", "not_degenerate")
TRACKS = ("cooperative", "robust-ranging")


def dev_seeds(n: int = DEFAULT_SEEDS) -> list[int]:
    """The first ``n`` dev seeds (2_000_000 …); the v2 calibration never reads a test seed."""
    if n < 2:
        raise ValueError(f"seeds={n}: need at least 2 dev seeds for confidence intervals")
    return list(range(DEV_SEED_START, DEV_SEED_START + n))


def candidate_tasks() -> list[str]:
    """The simulated v2 tasks, in catalogue order (every one is a candidate for its track's headline)."""
    return list(CATALOGUE_V2)


# --------------------------------------------------------------------------- running


def fault_free(spec: TaskSpec) -> dict[str, Any]:
    """The overrides of ``spec``'s fault-free counterpart: every fault removed (same truth, same noise draws).

    A task scored on each episode's healthy UAVs (``nodes_from_schedule="healthy"``) scores every UAV of
    ``scoring.nodes`` once no UAV is faulty."""
    over: dict[str, Any] = {"faults": Faults().model_dump()}
    if spec.scoring.nodes_from_schedule == "healthy":
        over["scoring"] = {"nodes_from_schedule": "all"}
    return over


def _run(methods: Sequence[str], tasks: Sequence[str], seeds: Sequence[int], overrides: Mapping[str, Any] | None,
         workers: int, progress: bool) -> dict[str, TaskOutcome]:
    """``methods`` on ``tasks`` × ``seeds`` through the runner, with ``overrides`` on every task."""
    outcomes: dict[str, TaskOutcome] = {}
    run_methods(methods, tuple((t, s) for t in tasks for s in seeds), outcomes, overrides=overrides, workers=workers,
                progress=progress)
    return outcomes


def measure(tasks: Sequence[str], seeds: Sequence[int], *, workers: int = 1, progress: bool = False,
            overrides: Mapping[str, Any] | None = None) -> dict[str, dict[str, dict[str, np.ndarray]]]:
    """Every per-seed number the criteria read, for each task.

    Returns:
        task → ``{"on": method → (n,) RMSE, "bound": {"on", "off", "no_peers"} → (n,) bound_rmse,
        "off": method → (n,) RMSE with the faults removed, "episodes": method → metric dicts}``.
    """
    base = dict(overrides or {})
    coop = [t for t in tasks if get_spec(t, **base).track == "cooperative"]
    on = _run(METHODS + ("non-cooperative",), coop, seeds, base, workers, progress)
    on.update(_run(METHODS, [t for t in tasks if t not in coop], seeds, base, workers, progress))
    off = {}
    for t in tasks:  # one run per task: the fault-free counterpart's overrides depend on the task
        off.update(_run(("uniform", CENTRAL), [t], seeds, {**base, **fault_free(get_spec(t, **base))}, workers,
                        progress))
    peerless = _run(("uniform",), coop, seeds, {**base, "sensors": {"peers": {"kind": "none"}}}, workers, progress)
    out = {}
    for t in tasks:
        per = lambda o, m, key="rmse": np.array([np.nan if e[key] is None else e[key]
                                                 for e in o.episodes[m]], dtype=float)
        rmse_on = {m: per(on[t], m) for m in on[t].episodes if m not in on[t].unsupported}
        bound = {"on": per(on[t], "uniform", "bound_rmse"), "off": per(off[t], "uniform", "bound_rmse")}
        if t in peerless:
            bound["no_peers"] = per(peerless[t], "uniform", "bound_rmse")
        out[t] = {"on": rmse_on, "bound": bound, "off": {m: per(off[t], m) for m in off[t].episodes},
                  "episodes": {m: on[t].episodes[m] for m in rmse_on}}
    return out


# --------------------------------------------------------------------------- criteria


def _ratio(num: np.ndarray, den: np.ndarray) -> float:
    return float(np.mean(num) / np.mean(den))


def criterion(value: float | None, passed: bool | None, measured: str) -> dict[str, Any]:
    """One criterion's row: ``value``, ``pass`` (None: does not apply) and what was measured."""
    return {"value": None if value is None or not math.isfinite(value) else round(float(value), 4),
            "pass": passed, "measured": measured}


def task_criteria(task: str, track: str, m: Mapping[str, Any], fault_task: bool) -> dict[str, dict[str, Any]]:
    """Criteria a–g of one task except d's track verdict (``headroom`` holds the task's own value here)."""
    on, bound, off = m["on"], m["bound"], m["off"]
    coop = track == "cooperative"
    out: dict[str, dict[str, Any]] = {}
    if coop:
        r = _ratio(bound["no_peers"], bound["on"])
        out["peer_information"] = criterion(r, r >= PEER_INFORMATION_RATIO, f"bound without peers / bound {r:.2f}")
    else:
        out["peer_information"] = criterion(None, None, "robust-ranging track (one UAV)")
    if fault_task:
        r = _ratio(on["uniform"], off["uniform"])
        out["fault_matters"] = criterion(r, r >= FAULT_RATIO, f"uniform / uniform without faults {r:.2f}")
    else:
        out["fault_matters"] = criterion(None, None, "no fault")
    r = _ratio(off[CENTRAL], bound["off"])
    out["attainable"] = criterion(r, r <= ATTAINABLE_RATIO, f"centralized-oracle / bound without faults {r:.2f}")
    gaps = {g: C.gap_closed(task, m["episodes"][g])["gap_closed"] for g in C.GATING if g in m["episodes"]}
    closed = [v for v in gaps.values() if v is not None]
    value = max(closed) if closed and len(closed) == len(gaps) else None
    own = None if not fault_task else (value is not None and 0.0 <= value <= GAP_CLOSED_MAX)
    text = ", ".join(f"{g} {'—' if v is None else f'{v:.2f}'}" for g, v in gaps.items())
    out["headroom"] = {**criterion(value, own, f"gap closed: {text}" if fault_task else "no fault"),
                       "task_pass": own}
    if coop:
        r = _ratio(on["non-cooperative"], on["oracle"])
        out["kind_rule"] = criterion(r, r >= KIND_RULE_RATIO, f"non-cooperative / oracle {r:.2f}")
    else:
        out["kind_rule"] = criterion(None, None, "robust-ranging track (no peers)")
    # below the bound: the non-privileged methods (the bound is a floor for every estimator only in expectation;
    # the privileged ones are held to it by tests/test_bound_property.py); the oracle against every public method
    public = {m: v for m, v in on.items() if m not in PRIVILEGED}
    floor = C.ceiling_valid(public, bound["on"], ())
    top = C.ceiling_valid({**public, "oracle": on["oracle"]}, None, PRIVILEGED)
    out["ceiling"] = criterion(floor["min_ratio"], floor["pass"] and top["pass"],
                               "; ".join([floor["measured"]] + (top["measured"].split("; ")[1:])))
    degenerate = C.not_degenerate(on)
    out["not_degenerate"] = criterion(degenerate["ratio"], degenerate["pass"], degenerate["measured"])
    return out


def _passes_the_others(row: Mapping[str, Any]) -> bool:
    return all(c["pass"] is not False for name, c in row["criteria"].items() if name != "headroom")


def track_headroom(rows: Sequence[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Criterion d over each track: the gates' own-task verdicts held on ≥ ``HEADROOM_TASK_FRACTION`` of its fault
    tasks that pass every other criterion (the headline it would make: a task out of it for another reason does not
    decide the track's headroom); every row of the track gets the track's ``pass``."""
    verdicts = {}
    for track in TRACKS:
        judged = [r["criteria"]["headroom"]["task_pass"] for r in rows
                  if r["track"] == track and r["criteria"]["headroom"]["task_pass"] is not None
                  and _passes_the_others(r)]
        held = sum(bool(v) for v in judged)
        ok = held >= HEADROOM_TASK_FRACTION * len(judged) if judged else None
        verdicts[track] = {"pass": ok, "held": held, "judged": len(judged)}
        for r in rows:
            if r["track"] == track:
                h = r["criteria"]["headroom"]
                h["pass"] = ok if h["task_pass"] is not None else None
                h["measured"] += (f" (track: {held}/{len(judged)} of the fault tasks that pass the other criteria within "
                                  f"0–{GAP_CLOSED_MAX:g})")
    return verdicts


def admitted(criteria: Mapping[str, Mapping[str, Any]]) -> bool:
    """Every criterion that applies passes."""
    return all(c["pass"] is not False for c in criteria.values())


def build_rows(numbers: Mapping[str, Mapping[str, Any]], seeds: Sequence[int],
               overrides: Mapping[str, Any] | None = None) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """The report's rows (one per task, ``docs/calibration-v2.json``) and the tracks' headroom verdicts."""
    rows = []
    for task, m in numbers.items():
        spec = get_spec(task, **(overrides or {}))
        fault_task = spec.faults != Faults()
        means = {k: round(float(np.mean(v)), 4) for k, v in m["on"].items()}
        rows.append({"task": task, "track": spec.track, "family": task_family(task), "split": task_split(task),
                     "seeds": [int(s) for s in seeds],
                     "criteria": task_criteria(task, spec.track, m, fault_task),
                     "rmse": means, "bound": {k: round(float(np.mean(v)), 4) for k, v in m["bound"].items()},
                     "rmse_faults_off": {k: round(float(np.mean(v)), 4) for k, v in m["off"].items()}})
    verdicts = track_headroom(rows)
    for r in rows:
        # a row holds the criteria that apply to its task; the others, with why, beside them
        r["not_applicable"] = {name: c["measured"] for name, c in r["criteria"].items() if c["pass"] is None}
        r["criteria"] = {name: c for name, c in r["criteria"].items() if c["pass"] is not None}
        r["in_headline"] = admitted(r["criteria"])
        r["failing"] = [name for name, c in r["criteria"].items() if c["pass"] is False]
    return rows, verdicts


def rows_sha256(rows: Sequence[Mapping[str, Any]]) -> str:
    """SHA-256 of the rows' canonical JSON (sorted keys, compact): what the v2 suites' hashes cover."""
    return hashlib.sha256(json.dumps(list(rows), sort_keys=True, separators=(",", ":")).encode()).hexdigest()


# --------------------------------------------------------------------------- report


def _cell(c: Mapping[str, Any]) -> str:
    mark = {True: "✓", False: "✗", None: "·"}[c["pass"]]
    return mark if c["value"] is None else f"{c['value']:.2f} {mark}"


def family_ratios(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Per family (over its tasks' rows): the geometric means of uniform/bound and oracle/bound."""
    by = {r["task"]: r for r in rows}
    out = []
    for family, tasks in group_by_family(by).items():
        u = [math.log2(by[t]["rmse"]["uniform"] / by[t]["bound"]["on"]) for t in tasks]
        o = [math.log2(by[t]["rmse"]["oracle"] / by[t]["bound"]["on"]) for t in tasks]
        out.append({"family": family, "track": by[tasks[0]]["track"], "tasks": len(tasks),
                    "uniform_over_bound": round(2 ** float(np.mean(u)), 3),
                    "oracle_over_bound": round(2 ** float(np.mean(o)), 3)})
    return out


def render(rows: Sequence[Mapping[str, Any]], verdicts: Mapping[str, Any], families: Sequence[Mapping[str, Any]],
           seeds: Sequence[int], command: str) -> str:
    """The Markdown report."""
    lines = ["# Benchmark v2 calibration: which tasks enter the headline", "",
             (f"Generated by `{command}` on dev seeds {seeds[0]} … {seeds[-1]} ({len(seeds)} per task); no test "
              "seed is read. A task enters its track's headline when every criterion that applies passes "
              "(· : does not apply). Criteria and thresholds: `bench/reproduce/calibration_v2.py`."), "",
             ("a: bound without peers / bound ≥ 1.5 (cooperative); b: uniform / uniform without faults ≥ 1.5; "
              "c: centralized-oracle / bound without faults ≤ 1.3; d: the gates' gap closed in [0, 0.7] on at least "
              "half of the track's fault tasks that pass the other criteria (the cell: the task's own value and "
              "whether it is in [0, 0.7]; the track's verdict above each table); e: non-cooperative / oracle ≥ 1.25 "
              "(cooperative); f: the lowest non-privileged RMSE / bound, none below it, the oracle no worse than "
              "any of them; g: random / best method ≥ 1.10."), ""]
    for track in TRACKS:
        mine = [r for r in rows if r["track"] == track]
        if not mine:
            continue
        v = verdicts[track]
        verdict = "passes" if v["pass"] else "fails" if v["pass"] is False else "not judged"
        lines += [f"## Track: {track}", "",
                  (f"Criterion d over the track: {v['held']}/{v['judged']} of the fault tasks that pass the other "
                   f"criteria within 0–0.7 → {verdict}."), "",
                  ("| task | a peers | b fault | c attainable | d gates | e kind rule | f ceiling | g random | "
                   "uniform | non-coop | oracle | central | bound | headline |"),
                  "|---|---|---|---|---|---|---|---|---:|---:|---:|---:|---:|---|"]
        for r in mine:
            c, m = r["criteria"], r["rmse"]
            nc = f"{m['non-cooperative']:.3f}" if "non-cooperative" in m else "—"
            cells = ["·" if k not in c else _cell({**c[k], "pass": c[k]["task_pass"]} if k == "headroom" else c[k])
                     for k in CRITERIA]
            lines.append(f"| {task_label(r['task'])} | " + " | ".join(cells)
                         + f" | {m['uniform']:.3f} | {nc} | {m['oracle']:.3f} | {m[CENTRAL]:.3f} | "
                         f"{r['bound']['on']:.3f} | {'**yes**' if r['in_headline'] else 'no: ' + ', '.join(r['failing'])} |")
        lines.append("")
    lines += ["## Per family: uniform and the oracle against the bound (geometric means over the family's tasks)", "",
              "| family | track | tasks | uniform / bound | oracle / bound |", "|---|---|---:|---:|---:|"]
    lines += [f"| {f['family']} | {f['track']} | {f['tasks']} | {f['uniform_over_bound']:.2f} | "
              f"{f['oracle_over_bound']:.2f} |" for f in families]
    head = [task_label(r["task"]) for r in rows if r["in_headline"]]
    lines += ["", f"Headline ({len(head)} of {len(rows)}): {', '.join(head) or 'none'}.", ""]
    return "\n".join(lines)


def reproduce_calibration_v2(out_md: Path, out_json: Path, *, tasks: Sequence[str] | None = None,
                             seeds: int = DEFAULT_SEEDS, workers: int = 1, progress: bool = False,
                             command: str = "swarmloc reproduce calibration --version 2",
                             overrides: Mapping[str, Any] | None = None, sim_to_real: bool = True) -> dict[str, Any]:
    """Run the v2 calibration and write the Markdown report and its JSON (``rows``: one per task).

    Args:
        out_md, out_json: where to write.
        tasks: task IDs (default: every simulated v2 task, ``candidate_tasks``).
        seeds: dev seeds per task, at least 2.
        workers, progress: the runner's.
        command: the command line the report names.
        overrides: spec overrides for every run (shortened episodes in tests; the report is then not the
            calibration).
        sim_to_real: add the robust-ranging track's ranking of the classical methods beside their ranking on the
            real flights (``sim_to_real.measure_sim_to_real``, Kendall τ with a bootstrap CI; needs the UTIL data).

    Returns:
        The JSON document.
    """
    chosen = [canonical_task_id(t) for t in tasks] if tasks else candidate_tasks()
    bad = [t for t in chosen if get_spec(t).version != 2]
    if bad:
        raise ValueError(f"tasks {bad} are not v2 tasks; the v2 calibration judges v2 tasks only")
    seed_list = dev_seeds(seeds)
    t0 = time.perf_counter()
    numbers = measure(chosen, seed_list, workers=workers, progress=progress, overrides=overrides)
    rows, verdicts = build_rows(numbers, seed_list, overrides)
    families = family_ratios(rows)
    real = None
    if sim_to_real:
        from swarmloc.bench.reproduce.sim_to_real import measure_sim_to_real

        real = measure_sim_to_real(sim_seeds=seed_list, overrides=overrides, progress=progress)
        real.pop("rmse", None)  # the per-episode tables stay out of the report
    doc = {"command": command, "seeds": seed_list, "rows": rows, "rows_sha256": rows_sha256(rows),
           "tracks": verdicts, "families": families, "sim_to_real": real,
           "thresholds": {"peer_information": PEER_INFORMATION_RATIO, "fault_matters": FAULT_RATIO,
                          "attainable": ATTAINABLE_RATIO, "gap_closed_max": GAP_CLOSED_MAX,
                          "headroom_task_fraction": HEADROOM_TASK_FRACTION, "kind_rule": KIND_RULE_RATIO,
                          "random_min_ratio": C.RANDOM_MIN_RATIO},
           "seconds": round(time.perf_counter() - t0, 1), "provenance": collect_provenance().model_dump(mode="json")}
    write_text_atomic(out_json, json.dumps(doc, indent=1) + "\n")
    text = render(rows, verdicts, families, seed_list, command)
    if real is not None:
        from swarmloc.bench.reproduce.sim_to_real import render_sim_to_real

        text += "\n" + "\n".join(render_sim_to_real(real)) + "\n"
    write_text_atomic(out_md, text)
    return doc
