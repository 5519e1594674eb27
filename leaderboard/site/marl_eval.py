"""The leaderboard in marl-eval's raw-data JSON (InstaDeep's marl-eval, [marl-eval]; built on rliable).

marl-eval reads one nested object (its README, "Data Structure for Raw Experiment data")::

    {env_name: {task_name: {algorithm_name: {run_name: {
        "step_<k>": {"step_count": int, metric: [one value per evaluation episode], ...},
        "absolute_metrics": {metric: <the same list>, ...}}}}}}

``data_process_pipeline`` lower-cases every key and adds ``mean_<metric>`` to every step;
``create_matrices_for_rliable`` builds a (runs × tasks) matrix per algorithm from the ``mean_``
metrics of ``absolute_metrics``, indexing every algorithm with the first one's run names, and the
pipeline derives the evaluation interval from the steps' ``step_count``. So here:

* **environment**: ``swarmloc-<suite>`` for a v1 suite; ``swarmloc-<suite>-<track>`` for each track of
  a benchmark v2 suite (scores never mix tracks, and marl-eval aggregates over an environment's tasks);
* **task**: the task ID (``swarmloc/Scale8-v2``; marl-eval lower-cases it);
* **algorithm**: the method name (a comma, which marl-eval refuses, becomes ``;``; a name already taken on
  the environment, ignoring case, gets `` #<entry id>``); ranked and partial-coverage methods, not the
  privileged ones (they read ground truth and are not ranked);
* **run**: ``run_0`` … ``run_<n-1>``, the method's training runs in run-seed order (the seeds are in the
  JSON/CSV export's ``run_seeds``); ``run_0`` alone for a method of one run;
* **steps**: one, ``step_0`` with ``step_count`` 0 (the evaluated policy; no training curve), and
  ``absolute_metrics`` with the same values (the final evaluation, which marl-eval's matrices read);
* **metrics**, one value per episode (the suite's seeds of the task, in seed order): ``gain`` =
  log2(RMSE_uniform / RMSE), the score's per-episode gain (higher is better, 0 is uniform: no
  normalisation needed, so leave it out of ``metrics_to_normalize``), and ``rmse`` [m] (lower is better).

marl-eval's matrices need every algorithm of an environment to have the same runs and tasks: a
partial-coverage method lacks the tasks it cannot run, and a method of one run has ``run_0`` only, so
keep the algorithms of equal runs and full coverage (docs/leaderboard.md shows how) before
``create_matrices_for_rliable``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from swarmloc.bench.scoring.score import SuiteScore
from swarmloc.leaderboard.site.ranking import Standing, SuiteBoard, episodes_of
from swarmloc.leaderboard.store.records import LeaderboardEntry

#: marl-eval's name of the final evaluation
ABSOLUTE_METRICS = "absolute_metrics"
#: the one logged step (the evaluated policy)
STEP = "step_0"


def environment_name(suite: str, track: str | None) -> str:
    """``swarmloc-<suite>``, with ``-<track>`` for a track of a v2 suite."""
    return f"swarmloc-{suite}" + ("" if track is None else f"-{track}")


def _algorithm_name(standing: Standing, taken: set[str]) -> str:
    """The method's name for marl-eval: no comma, unique on its environment whatever the case."""
    name = standing.entry.name.replace(",", ";")
    if name.casefold() in taken:
        name = f"{name} #{standing.entry.id}"
    taken.add(name.casefold())
    return name


def _runs(standing: Standing) -> list[tuple[LeaderboardEntry, SuiteScore | None]]:
    """The standing's runs in run-seed order (``runs`` keeps that order), or its entry alone."""
    return [(r.entry, r.score) for r in standing.runs] or [(standing.entry, standing.score)]


def _run_data(entry: LeaderboardEntry, score: SuiteScore) -> dict[str, dict[str, Any]]:
    """Task → one run's step and absolute metrics on the task (its covered tasks only)."""
    rmse = {(str(ep["task"]), int(ep["seed"])): ep["metrics"].get("rmse") for ep in episodes_of(entry)}
    out = {}
    for task, t in score.tasks.items():
        order = np.argsort(t.seeds, kind="stable")
        metrics = {"gain": [float(g) for g in t.gains[order]],
                   "rmse": [rmse[(task, int(seed))] for seed in t.seeds[order]]}
        out[task] = {STEP: {"step_count": 0, **metrics}, ABSOLUTE_METRICS: metrics}
    return out


def marl_eval_data(boards: Sequence[tuple[SuiteBoard, str | None]]) -> dict[str, dict[str, Any]]:
    """The boards in marl-eval's raw-data layout (see the module docstring).

    Args:
        boards: ``(board, track)`` pairs: a v1 suite's board with track None, or each track's board of a
            v2 suite (:func:`swarmloc.leaderboard.site.export.boards`).

    Returns:
        ``{environment: {task: {algorithm: {"run_<k>": {"step_0": {...}, "absolute_metrics": {...}}}}}}``,
        tasks in the board's order; JSON-ready.
    """
    data: dict[str, dict[str, Any]] = {}
    for board, track in boards:
        env: dict[str, Any] = {task: {} for task in board.tasks}
        taken: set[str] = set()
        for standing in board.ranked + board.partial:
            if standing.score is None:
                continue
            algorithm = _algorithm_name(standing, taken)
            for k, (entry, score) in enumerate(_runs(standing)):
                for task, run in ({} if score is None else _run_data(entry, score)).items():
                    env[task].setdefault(algorithm, {})[f"run_{k}"] = run
        data[environment_name(board.name, track)] = {task: algos for task, algos in env.items() if algos}
    return data


__all__ = ["ABSOLUTE_METRICS", "STEP", "environment_name", "marl_eval_data"]
