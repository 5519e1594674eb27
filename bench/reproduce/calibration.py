"""``swarmloc reproduce calibration``: are the v1 tasks a measuring instrument? → docs/calibration.md + .json.

For every task of a suite (default ``standard-v1``) the classical reference methods
(``CLASSICAL``, plus ``imm-kf`` and ``imm-arkf`` on HybridNoise tasks) run through the
runner (``evaluate_methods``: the leaderboard's metrics, ``uniform_rmse`` and the
information bound ``bound_rmse`` per episode), and the report gives per task

* uniform / oracle / bound / best classical (best non-privileged, non-random) / random
  task-mean RMSE with 95 % bootstrap CIs;
* the five criteria of the v1 tasks (``calibration_criteria``; criterion 4, the paper's
  phenomenon, in ``calibration_phenomena``; Scale is judged across its swarm sizes);
* for each randomized family with both splits (``<Family>Random-v1``, in-distribution, and
  ``<Family>RandomShifted-v1``, parameters outside the training ranges) whether the shifted
  split is measurably harder for uniform and the best classical method (the per-seed log
  ratio shifted / in-distribution, paired on the shared test seeds, with its CI above 0);
* the gap closed (``score.py``) of every method evaluated here and of every registered method
  whose shipped results (the suite's folder, ``bench/results/standard-v1``) hold these
  tasks and seeds.

The phenomena that need more than the runner's metrics get it from the runner too:
``uniform`` re-run per seed with its trace (``rollout``; an episode's metrics do not depend
on its batch) for the healthy-node peak error (CascadedFault) and the labelled-link counts
(NLOS), and the bound over the fault window (GradualFault) from ``envs.bound``'s per-step
posterior Cramér–Rao bound on the scored UAVs.
"""

from __future__ import annotations

import json
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from swarmloc.agents.registry import REGISTRY
from swarmloc.bench.common.files import write_text_atomic
from swarmloc.bench.common.provenance import collect_provenance
from swarmloc.bench.scoring import metrics as M
from swarmloc.bench.scoring.families import FAMILY_OF_BASE, group_by_family, task_base, task_label, task_split
from swarmloc.bench.evaluation.outcomes import TaskOutcome
from swarmloc.bench.scoring.score import suite_score
from swarmloc.bench.evaluation.suites import Suite
from swarmloc.bench.evaluation.traces import Trace
from swarmloc.bench.reproduce import calibration_criteria as C
from swarmloc.bench.reproduce.calibration_phenomena import PHENOMENA, RANDOMIZED_TOO, Evidence, scale_phenomenon
from swarmloc.envs.tasks.specs import Faults, TaskSpec
from swarmloc.envs.tasks.catalogue import get_spec

#: the classical reference methods, run on every task
CLASSICAL = ("uniform", "oracle", "chi2-gate", "chi2-soft", "huber", "fixed", "federated-coef", "cusum", "raim",
             C.KIND_RULE, "random")
#: run on the HybridNoise tasks as well (Track B estimators on GPS fixes)
IMM = ("imm-kf", "imm-arkf")
#: bases whose phenomenon reads uniform's per-seed traces
TRACED = ("NLOS", "CascadedFault")
SPLITS = ("fixed", "random", "shifted")


def task_variant(task: str) -> tuple[str, str]:
    """``(base, split)`` of a task ID: ``CascadedFaultRandomShifted-v1`` → ``("CascadedFault", "shifted")``
    (``families.task_base`` and ``families.task_split``)."""
    return task_base(task), task_split(task)


def is_fault_task(spec: TaskSpec) -> bool:
    """The task injects faults (``spec.faults`` is not the empty ``Faults()``)."""
    return spec.faults != Faults()


def methods_for(task: str) -> tuple[str, ...]:
    """The methods the calibration runs on a task."""
    return CLASSICAL + (IMM if task_variant(task)[0] == "HybridNoise" else ())


# --------------------------------------------------------------------------- running


def evaluate(tasks: Sequence[str], seeds: Mapping[str, Sequence[int]], *, workers: int = 1,
             overrides: Mapping[str, Any] | None = None, progress: bool = False) -> dict[str, TaskOutcome]:
    """Every task's methods (``methods_for``) on its seeds, through ``evaluate_methods``.

    Args:
        tasks: task IDs; seeds: task → its seeds.
        workers: worker processes (1: in this process).
        overrides: task-spec overrides for every task (shortened episodes in tests).
        progress: show the runner's progress bar.

    Returns:
        task → its outcome (every method's per-seed metrics; ``unsupported`` where one cannot run).

    Raises:
        RuntimeError: a job failed (the message names the method, the task and the error).
    """
    outcomes: dict[str, TaskOutcome] = {}
    hybrid = [t for t in tasks if IMM[0] in methods_for(t)]
    for methods, chosen in ((CLASSICAL, list(tasks)), (IMM, hybrid)):
        run_methods(methods, tuple((t, s) for t in chosen for s in seeds[t]), outcomes, overrides=overrides,
                    workers=workers, progress=progress)
    return outcomes


def run_methods(methods: Sequence[str], episodes: Sequence[tuple[str, int]], outcomes: dict[str, TaskOutcome], *,
                overrides: Mapping[str, Any] | None = None, workers: int = 1, progress: bool = False) -> None:
    """``methods`` on the (task, seed) ``episodes`` through the runner, merged by task into ``outcomes``.

    Raises:
        RuntimeError: a job failed (the message names the method, the task and the error).
    """
    from swarmloc.bench.evaluation.runner import evaluate_methods

    if not episodes:
        return

    def keep(part: TaskOutcome) -> None:
        have = outcomes.setdefault(part.task, TaskOutcome(task=part.task, seeds=part.seeds))
        have.episodes.update(part.episodes)
        have.unsupported.update(part.unsupported)

    suite = Suite("calibration", "1", tuple(episodes), "calibration runs")
    runs = evaluate_methods(list(methods), suite, workers=workers, trace=False, progress=progress, on_task=keep,
                            overrides=overrides)
    failed = [f"{m} on {t}: {e}" for m, r in runs.items() for t, e in r.failed.items()]
    if failed:
        raise RuntimeError("calibration runs failed:\n" + "\n".join(failed))


def uniform_traces(spec: TaskSpec, seeds: Sequence[int]) -> tuple[list[Trace], list[np.ndarray]]:
    """``uniform`` on each seed alone, with its trace, and each episode's healthy UAVs.

    Healthy: ``scoring.healthy_nodes`` where the task names them, else the UAVs the episode's
    fault schedule leaves without an IMU fault (every UAV on a task without IMU faults).
    """
    from swarmloc.agents.registry import load_method
    from swarmloc.bench.evaluation.runner import rollout
    from swarmloc.envs.world.worlds import make_world

    traces, healthy = [], []
    for seed in seeds:
        _, trace = rollout(load_method("uniform"), spec, [int(seed)], trace=True)
        assert trace is not None
        traces.append(trace)
        if spec.scoring.healthy_nodes:
            nodes = np.zeros(spec.n_uav, dtype=bool)
            nodes[list(spec.scoring.healthy_nodes)] = True
        else:
            world = make_world(spec, 1)
            world.reset([int(seed)])
            schedule = getattr(world, "schedule", None)
            nodes = ~schedule.faulty_nodes[0] if schedule is not None else np.ones(spec.n_uav, dtype=bool)
        healthy.append(nodes)
    return traces, healthy


def window_bounds(spec: TaskSpec, seeds: Sequence[int]) -> np.ndarray | None:
    """``(n,)`` the information bound over ``scoring.fault_window`` on the scored UAVs [m], per seed.

    None where the task has no fault window, the bound is undefined, or its recursion fails.
    """
    from swarmloc.envs.filter.bound import bound_rmse, pcrlb, record_inputs, unsupported_reason

    if spec.scoring.fault_window is None or unsupported_reason(spec) is not None:
        return None
    inputs, _ = record_inputs(spec, [int(s) for s in seeds])
    out = pcrlb(inputs)
    if (out.failed_at >= 0).any():
        return None
    times = spec.dt * np.arange(1, spec.n_steps + 1)
    steps = M.window_steps(times, spec.scoring.fault_window) & (times >= spec.scoring.start - 1e-9)
    nodes = np.zeros(spec.n_uav, dtype=bool)
    nodes[list(spec.scored_nodes)] = True
    values = np.array([bound_rmse(out.pos_var[:, b], steps, nodes) for b in range(len(seeds))])
    return values if np.isfinite(values).all() else None


def gather_evidence(outcome: TaskOutcome, spec: TaskSpec) -> Evidence:
    """A task's evidence: the methods that ran on every seed, plus what its phenomenon needs."""
    episodes = {m: rows for m, rows in outcome.episodes.items() if all(r.get("rmse") is not None for r in rows)}
    base = task_variant(outcome.task)[0]
    traces, healthy = uniform_traces(spec, outcome.seeds) if base in TRACED else ([], [])
    return Evidence(task=outcome.task, spec=spec, seeds=tuple(outcome.seeds), episodes=episodes,
                    privileged=frozenset(m for m in episodes if m in REGISTRY and REGISTRY[m].privileged),
                    uniform_traces=traces, healthy_nodes=healthy,
                    window_bound=window_bounds(spec, outcome.seeds) if base == "GradualFault" else None)


# --------------------------------------------------------------------------- per task, per family


def _passes(criteria: Mapping[str, Any]) -> bool:
    """Criteria 1, 2, 4 and 5 hold where judged (3 is judged over the suite)."""
    return all(v["pass"] is not False for k, v in criteria.items() if k != "headroom" and v is not None)


def task_result(ev: Evidence) -> dict[str, Any]:
    """One task's numbers and criteria (the Scale phenomenon is filled in by ``family_results``)."""
    base, split = task_variant(ev.task)
    fault = is_fault_task(ev.spec)
    rmse, bound = ev.rmse, ev.bound
    best_classical = C.best_of(rmse, exclude=ev.privileged | {C.RANDOM})
    phen = None
    target, fn = PHENOMENA.get(base, (None, None))
    if target is not None and (split == "fixed" or base in RANDOMIZED_TOO):
        phen = {"target": target, **(fn(ev) if fn is not None else {"measured": "across Scale tasks", "pass": None})}
    criteria = {
        "ceiling": C.ceiling_valid(rmse, bound, ev.privileged),
        "fault_matters": C.fault_matters(rmse["uniform"], bound, fault),
        "headroom": C.headroom(ev.task, ev.episodes, fault),
        "phenomenon": phen,
        "not_degenerate": C.not_degenerate(rmse),
    }
    return {
        "task": ev.task, "family": FAMILY_OF_BASE.get(base, base), "base": base, "split": split,
        "fault_task": fault, "n_seeds": len(ev.seeds), "seeds": list(ev.seeds),
        "rmse": {m: C.mean_ci(v) for m, v in rmse.items()},
        "bound": None if bound is None else C.mean_ci(bound),
        "best_classical": best_classical, "criteria": criteria, "passes": _passes(criteria),
        "kind_rule": C.kind_rule(rmse),
        "gap_closed": {m: C.gap_closed(ev.task, rows) for m, rows in ev.episodes.items()},
    }


def family_results(results: list[dict[str, Any]], evidence: Mapping[str, Evidence]) -> dict[str, Any]:
    """Judge the phenomena that span a family's tasks (Scale) and write them into its tasks' results.

    Returns:
        family name → its verdict (``{"Scale": {...}}`` when a fixed Scale task ran).
    """
    scale = [r for r in results if r["base"] == "Scale" and r["split"] == "fixed"]
    if not scale:
        return {}
    ns = {r["task"]: evidence[r["task"]].spec.n_uav for r in scale}
    verdict = scale_phenomenon({ns[r["task"]]: evidence[r["task"]].rmse["uniform"] for r in scale},
                               {ns[r["task"]]: evidence[r["task"]].rmse["oracle"] for r in scale
                                if "oracle" in evidence[r["task"]].rmse})
    verdict = {"target": PHENOMENA["Scale"][0], **verdict}
    for r in scale:
        r["criteria"]["phenomenon"] = verdict
        r["passes"] = _passes(r["criteria"])
    return {"Scale": verdict}


def split_comparison(results: Sequence[Mapping[str, Any]],
                     per_seed: Mapping[str, Mapping[str, np.ndarray]]) -> list[dict[str, Any]]:
    """Each shifted task beside its in-distribution twin: uniform and best classical, means, CIs, paired ratios.

    The two tasks of a family run the same test seeds, and a seed keys every draw of the
    world (counter-based streams), so the seed pairs them: per seed
    ``d = log2(RMSE_shifted / RMSE_in-distribution)`` of the method (the best classical method
    of each split on its split), whose mean and bootstrap CI say how much harder the shifted
    split is. Pairing is valid whatever the correlation (the seeds are independent draws) and
    removes the between-seed spread the two task means share.

    Args:
        results: the tasks' results (``task_result``).
        per_seed: task → method → per-seed RMSE, in the order of that task's ``seeds``.

    Returns:
        One row per family with both splits; ``harder`` for a method: the CI of its mean ``d``
        lies above 0; the row's ``harder``: for uniform and for the best classical method.
    """
    by_label = {task_label(r["task"]): r for r in results}
    rows = []
    for shifted in results:
        if shifted["split"] != "shifted":
            continue
        inside = by_label.get(task_label(shifted["task"]).removesuffix("Shifted"))
        if inside is None:
            continue
        common = sorted(set(inside["seeds"]) & set(shifted["seeds"]))
        row: dict[str, Any] = {"family": shifted["family"], "in_distribution": inside["task"],
                               "shifted": shifted["task"], "paired_seeds": len(common)}
        for role in ("uniform", "best_classical"):
            a_m = "uniform" if role == "uniform" else inside["best_classical"]
            b_m = "uniform" if role == "uniform" else shifted["best_classical"]
            a, b = inside["rmse"][a_m], shifted["rmse"][b_m]
            a_seed = dict(zip(inside["seeds"], per_seed[inside["task"]][a_m]))
            b_seed = dict(zip(shifted["seeds"], per_seed[shifted["task"]][b_m]))
            d = C.mean_ci(np.log2([b_seed[s] / a_seed[s] for s in common])) if len(common) >= 2 else None
            row[role] = {"in_distribution": {"method": a_m, **a}, "shifted": {"method": b_m, **b},
                         "ratio": b["mean"] / a["mean"], "paired_log2": d,
                         "harder": d is not None and d["ci"][0] > 0.0}
        row["harder"] = row["uniform"]["harder"] and row["best_classical"]["harder"]
        rows.append(row)
    return rows


# --------------------------------------------------------------------------- gap closed


def shipped_episodes(results_dir: Path, tasks: Sequence[str], seeds: Mapping[str, Sequence[int]],
                     reference: Mapping[tuple[str, int], Mapping[str, Any]], skip: Sequence[str] = ()) -> dict:
    """The shipped episodes of registered methods on these tasks and seeds.

    A task counts for a method when its file holds every seed with an RMSE. Each episode is
    scored against this run's ``uniform_rmse`` and ``bound_rmse`` of the same task and seed
    (``reference``), so every method in the gap-closed table shares one A_t per task (and a
    schema-1 file, which has neither, is scored too).

    Args:
        results_dir: the shipped results; tasks, seeds: what ran here.
        reference: (task, seed) → this run's uniform metrics.
        skip: methods evaluated here (their fresh episodes are used instead).

    Returns:
        method → ``{"privileged", "episodes": [{"task", "seed", "metrics"}]}``.
    """
    out: dict[str, Any] = {}
    for path in sorted(Path(results_dir).glob("*.json")):
        data = json.loads(path.read_text(encoding="utf-8"))
        name = data["method"]["name"]
        if name not in REGISTRY or name in skip:
            continue
        by = {(e["task"], e["seed"]): e["metrics"] for e in data["episodes"]}
        episodes = []
        for task in tasks:
            rows = [by.get((task, int(s))) for s in seeds[task]]
            if all(r is not None and r.get("rmse") is not None for r in rows):
                for s, r in zip(seeds[task], rows):
                    ref = reference[(task, int(s))]
                    m = {**r, "uniform_rmse": ref["uniform_rmse"], "bound_rmse": ref["bound_rmse"]}
                    episodes.append({"task": task, "seed": int(s), "metrics": m})
        if episodes:
            out[name] = {"privileged": bool(data["method"]["privileged"]), "episodes": episodes}
    return out


def gap_closed_table(methods: Mapping[str, Mapping[str, Any]], tasks: Sequence[str]) -> dict[str, Any]:
    """The score's gap closed (Σ G_t / Σ A_t over tasks with a gap) of each method: over the suite, per family.

    Args:
        methods: method → ``{"source", "privileged", "episodes"}``.
        tasks: the tasks, in suite order.
    """
    families = group_by_family(tasks)
    table = {}
    for name, entry in methods.items():
        eps = entry["episodes"]
        whole = suite_score(eps, list(tasks))
        per_family = {}
        for family, members in families.items():
            s = suite_score([e for e in eps if e["task"] in members], members)
            per_family[family] = None if s is None else s.gap_closed
        table[name] = {"source": entry["source"], "privileged": entry["privileged"],
                       "suite": None if whole is None else whole.gap_closed,
                       "covered": 0 if whole is None else len(whole.tasks),
                       "with_gap": 0 if whole is None else sum(t.gap_closed is not None for t in whole.tasks.values()),
                       "families": per_family}
    return table


# --------------------------------------------------------------------------- the report


def calibrate(tasks: Sequence[str], seeds: Mapping[str, Sequence[int]], *, workers: int = 1,
              overrides: Mapping[str, Any] | None = None, results_dir: Path | None = None,
              progress: bool = False) -> dict[str, Any]:
    """Run the calibration and return its numbers (what docs/calibration.json holds, less provenance).

    Args:
        tasks: task IDs, in report order; seeds: task → its seeds (at least 2 each).
        workers: worker processes of the runner.
        overrides: task-spec overrides (shortened episodes in tests: not the suite's numbers, and the
            shipped results are then not compared).
        results_dir: the shipped results (default: the standard-v1 ones, ``bench/results/standard-v1``).
        progress: show the runner's progress bar.
    """
    from swarmloc.bench.evaluation.shipped import RESULTS_DIRS

    short = [t for t in tasks if len(seeds[t]) < 2]
    if short:
        raise ValueError(f"need at least 2 seeds per task for confidence intervals; {short} have fewer")
    started = time.perf_counter()
    outcomes = evaluate(tasks, seeds, workers=workers, overrides=overrides, progress=progress)
    specs = {t: get_spec(t, **(overrides or {})) for t in tasks}
    evidence = {t: gather_evidence(outcomes[t], specs[t]) for t in tasks}
    wall = time.perf_counter() - started
    results = [task_result(evidence[t]) for t in tasks]
    families = family_results(results, evidence)
    fault = [r["criteria"]["headroom"] for r in results if r["fault_task"]]

    methods = {m: {"source": "this run", "privileged": m in ev.privileged, "episodes": []}
               for ev in evidence.values() for m in ev.episodes}
    for t, ev in evidence.items():
        for m, rows in ev.episodes.items():
            methods[m]["episodes"] += [{"task": t, "seed": s, "metrics": r} for s, r in zip(ev.seeds, rows)]
    shipped: dict[str, Any] = {}
    folder = Path(results_dir) if results_dir is not None else RESULTS_DIRS["standard-v1"]
    if not overrides:
        reference = {(t, s): r for t, ev in evidence.items() for s, r in zip(ev.seeds, ev.episodes["uniform"])}
        shipped = shipped_episodes(folder, tasks, seeds, reference, skip=list(methods))
        methods.update({m: {"source": "shipped", **v} for m, v in shipped.items()})
    n_episodes = sum(len(seeds[t]) for t in tasks)
    splits = split_comparison(results, {t: ev.rmse for t, ev in evidence.items()})
    return {
        "tasks": results, "families": families, "splits": splits,
        "headroom": C.headroom_overall(fault), "gap_closed": gap_closed_table(methods, tasks),
        "shipped_methods": sorted(shipped), "shipped_dir": _shown_path(folder), "overrides": dict(overrides or {}),
        "unsupported": {t: dict(o.unsupported) for t, o in outcomes.items() if o.unsupported},
        "timing": {"wall_s": wall, "episodes": n_episodes, "per_task_s": wall / len(tasks),
                   "per_task_seed_s": wall / n_episodes},
    }


def _shown_path(folder: Path) -> str:
    """``folder`` relative to the repository root where it lies inside it (as the report shows it)."""
    root = Path(__file__).resolve().parents[2]
    try:
        return Path(folder).resolve().relative_to(root).as_posix()
    except ValueError:
        return str(folder)


def plain(value: Any) -> Any:
    """``value`` with numpy scalars and arrays as Python numbers and lists, non-finite floats as None (JSON)."""
    if isinstance(value, Mapping):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [plain(v) for v in value]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if np.isfinite(value) else None
    return value


def reproduce_calibration(suite: str = "standard-v1", tasks: Sequence[str] | str | None = None,
                          seeds: int | None = None, out_md: Path = Path("docs/calibration.md"),
                          out_json: Path = Path("docs/calibration.json"), *, workers: int = 1,
                          overrides: Mapping[str, Any] | None = None, results_dir: Path | None = None,
                          progress: bool = False, command: str = "swarmloc reproduce calibration") -> dict[str, Any]:
    """Run the calibration of a suite's tasks and write the Markdown report and its JSON, each atomically.

    Args:
        suite: the suite (``swarmloc.bench.evaluation.suites.suite_names``).
        tasks: only these of its tasks (IDs or one comma-separated string; None: all).
        seeds: the first this many seeds of each task (None: all of the suite's).
        out_md, out_json: the files to write (their folders are created).
        workers, overrides, results_dir, progress: as in ``calibrate``.
        command: the command line the report says generated it.

    Returns:
        The JSON's content.

    Raises:
        KeyError: unknown suite. ValueError: a task not in the suite, or a seed count out of range.
    """
    from swarmloc.bench.evaluation.suites import get_suite, restrict_tasks
    from swarmloc.bench.reproduce.calibration_report import render

    chosen = get_suite(suite)
    if tasks:
        chosen = restrict_tasks(chosen, tasks)
    available = min(len(chosen.seeds(t)) for t in chosen.tasks)
    if seeds is not None and not 2 <= seeds <= available:
        raise ValueError(f"seeds must be in [2, {available}] (the suite's seeds per task), got {seeds}")
    by_task = {t: chosen.seeds(t)[:seeds] for t in chosen.tasks}
    from swarmloc.bench.evaluation.shipped import RESULTS_DIRS

    raw = calibrate(chosen.tasks, by_task, workers=workers, overrides=overrides,
                    results_dir=results_dir if results_dir is not None else RESULTS_DIRS.get(suite), progress=progress)
    # one sanitized record behind both files, so that the Markdown and the JSON agree
    raw = plain({"command": command, "suite": {"name": suite, "selection": chosen.name, "sha256": chosen.sha256},
                 "provenance": collect_provenance().model_dump(mode="json"), **raw})
    for path in (Path(out_md), Path(out_json)):
        path.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(out_json, json.dumps(raw, indent=1, allow_nan=False) + "\n")
    write_text_atomic(out_md, render(raw))
    return raw


__all__ = ["CLASSICAL", "IMM", "calibrate", "evaluate", "family_results", "gap_closed_table", "gather_evidence",
           "is_fault_task", "methods_for", "plain", "reproduce_calibration", "shipped_episodes", "split_comparison",
           "task_result", "task_variant", "uniform_traces", "window_bounds"]
