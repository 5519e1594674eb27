"""``swarmloc tune <method>``: search a classical method's parameters on dev-v2 with Optuna, and record the search.

**The budget is the same for every tunable method**: ``trials`` Optuna trials (default
``BUDGET_TRIALS``), drawn by the TPE sampler seeded with ``seed`` (default ``BUDGET_SEED``),
trials one after another, so that a rerun draws the same values. The first trial is the
registered, untuned method's values (enqueued), so the record also holds the default's score on
the same episodes; the other trials are the sampler's (its first ten at random, then TPE).

**The objective is the method's dev-v2 score**: score v2's S (the family-weighted mean of the
per-episode log2 gains over ``uniform``, docs/scoring.md) on each track of the suite, and their
mean with the tracks weighted equally: on dev-v2 ½ S(cooperative) + ½ S(robust-ranging). Each
trial evaluates the policy through the bench runner (``evaluate_methods``: ``<method>-tuned``
handed the trial's parameters as its ``weights`` file) and scores it with ``track_scores``, the
path ``swarmloc evaluate`` takes. The chosen values are the trial with the highest objective
(ties: the earlier trial, so the default keeps a tie).

**The record** (``agents/weights/tuned/<method>.json``, shipped with the package) holds the
method, the chosen ``params``, the search space, the budget, every trial's values and scores,
the chosen and the default trial's scores per track with their 95 % CIs, the command, the
Optuna version, the code's commit and the wall time.
"""

from __future__ import annotations

import json
import tempfile
import time
from collections.abc import Callable, Mapping
from dataclasses import asdict
from pathlib import Path
from typing import Any

from swarmloc.bench import tuning
from swarmloc.bench.common.files import write_text_atomic
from swarmloc.bench.common.provenance import collect_provenance, dist_version, source_commit

#: how the objective combines the tracks (stated in every record)
OBJECTIVE = ("mean over the suite's tracks of score v2's S (log2 gain over uniform, family-weighted); "
             "dev-v2: cooperative and robust-ranging weighted equally")
#: the code a tuning run's numbers depend on (its commit is marked -dirty when any of it is modified)
SOURCE_PATHS = ("envs", "agents/trust", "agents/registry.py", "bench/evaluation", "bench/scoring", "bench/tuning")


def tune_command(method: str, trials: int, seed: int, workers: int) -> str:
    """The ``swarmloc tune`` command line that reproduces a record (``--workers`` does not change the numbers)."""
    return f"swarmloc tune {method} --trials {trials} --seed {seed} --workers {workers}"


def check_budget(trials: int, seed: int) -> None:
    """Refuse a budget Optuna cannot run.

    Raises:
        ValueError: ``trials`` < 1 or ``seed`` < 0 (the message names the value and the allowed range).
    """
    if isinstance(trials, bool) or not isinstance(trials, int) or trials < 1:
        raise ValueError(f"trials must be an integer >= 1, got {trials!r}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"seed must be an integer >= 0, got {seed!r}")


def _track_summary(score: Any) -> dict[str, float]:
    """S, 2^S and the 95 % CI of 2^S of one track's ``SuiteScore``."""
    low, high = score.times_ci
    return {"S": score.S, "times": score.times, "times_ci": [low, high]}


def tune(method: str, trials: int = tuning.BUDGET_TRIALS, seed: int = tuning.BUDGET_SEED, *, workers: int = 1,
         suite: Any = None, overrides: Mapping[str, Any] | None = None,
         on_trial: Callable[[dict[str, Any]], None] | None = None) -> dict[str, Any]:
    """Search ``method``'s space on ``suite`` with Optuna's TPE sampler and return the record (module docstring).

    Args:
        method: a tunable method (``swarmloc.agents.trust.tuned.TUNABLE``).
        trials: Optuna trials, >= 1, the registered default's included.
        seed: seed of the TPE sampler, >= 0.
        workers: worker processes of each trial's evaluation (the numbers do not depend on it).
        suite: the ``Suite`` of the objective (default: dev-v2). Tests pass a small one.
        overrides: task-spec overrides for every task (shortened episodes in tests; recorded).
        on_trial: called with each trial's entry of the record as it finishes (progress).

    Returns:
        The record (a JSON-ready dict); :func:`write_record` writes it.

    Raises:
        ValueError: an untunable method or a bad budget. RuntimeError: an evaluation failed, or a
        track has no score.
    """
    import optuna

    from swarmloc.agents.trust.tuned import TUNED_SUFFIX, check_tunable, default_params, search_space
    from swarmloc.bench.evaluation.runner import evaluate_methods
    from swarmloc.bench.evaluation.suites import get_suite
    from swarmloc.bench.scoring.tracks import track_scores

    check_tunable(method)
    check_budget(trials, seed)
    suite = get_suite(tuning.TUNING_SUITE) if suite is None else suite
    space = search_space(method)
    default = default_params(method)
    commit = source_commit(SOURCE_PATHS)  # at the start: HEAD may move during a long run
    name = f"{method}{TUNED_SUFFIX}"
    entries: list[dict[str, Any]] = []
    track_results: dict[int, dict[str, Any]] = {}

    def objective(trial: optuna.Trial, params_file: Path) -> float:
        started = time.perf_counter()
        params = {p.name: p.from_search(trial.suggest_float(p.search_name, *p.search_bounds, log=p.log))
                  for p in space}
        params_file.write_text(json.dumps({"method": method, "params": params}), encoding="utf-8")
        run = evaluate_methods([name], suite, workers=workers, weights={name: str(params_file)}, trace=False,
                               progress=False, overrides=overrides)[name]
        if run.failed:
            raise RuntimeError(f"{name} {params} failed: " + "; ".join(f"{t}: {e}" for t, e in run.failed.items()))
        scores = track_scores(run.episodes, suite.tasks, suite=suite.name)
        missing = [str(track) for track, score in scores.items() if score is None]
        if missing:
            raise RuntimeError(f"{name} {params} has no score on the track(s) {missing}")
        track_results[trial.number] = scores
        per_track = {str(track): score.S for track, score in scores.items()}
        value = sum(per_track.values()) / len(per_track)
        entry = {"number": trial.number, "params": params, "S": per_track, "objective": value,
                 "seconds": round(time.perf_counter() - started, 2)}
        entries.append(entry)
        if on_trial is not None:
            on_trial(entry)
        return value

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    sampler = optuna.samplers.TPESampler(seed=seed)
    study = optuna.create_study(direction="maximize", sampler=sampler)
    study.enqueue_trial({p.search_name: p.to_search(default[p.name]) for p in space})
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="swarmloc-tune-") as scratch:
        params_file = Path(scratch) / "trial.json"
        study.optimize(lambda trial: objective(trial, params_file), n_trials=trials)
    wall = time.perf_counter() - started

    best = max(entries, key=lambda e: (e["objective"], -e["number"]))  # ties: the earlier trial

    def summary(entry: dict[str, Any]) -> dict[str, Any]:
        scores = track_results[entry["number"]]
        return {"trial": entry["number"], "params": entry["params"], "objective": entry["objective"],
                "tracks": {str(track): _track_summary(score) for track, score in scores.items()}}

    return {
        "method": method,
        "params": best["params"],
        "objective": OBJECTIVE,
        "suite": {"name": suite.name, "sha256": suite.sha256, "tasks": list(suite.tasks),
                  "episodes": len(suite.episodes)},
        "overrides": dict(overrides) if overrides else None,
        "space": [asdict(p) for p in space],
        "budget": {"trials": trials, "sampler": "optuna.samplers.TPESampler", "seed": seed,
                   "first_trial": "the registered default (enqueued)"},
        "chosen": summary(best),
        "default": summary(entries[0]),
        "trials": entries,
        "command": tune_command(method, trials, seed, workers),
        "optuna_version": dist_version("optuna"),
        "source_commit": commit,
        "provenance": collect_provenance().model_dump(mode="json"),
        "wall_seconds": round(wall, 1),
    }


def write_record(record: Mapping[str, Any], out: str | Path) -> Path:
    """Write a tuning record as indented JSON, atomically.

    Args:
        record: what :func:`tune` returned.
        out: the file (its folder is created).

    Returns:
        The path written.
    """
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(out, json.dumps(record, indent=2) + "\n")
    return out
