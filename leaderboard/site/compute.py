"""The compute view: what each method of a board costs per update, beside the accuracy ranking.

A UAV has a decision budget per filter update: T_max = 50 ms in the standard reward (madrl's delay
budget; ``swarmloc.envs.world.reward``, docs/reward.md), past which the reward's delay penalty
grows exponentially. Per method the view gives

* **delay per update** [ms]: the results' ``delay_ms``, the compute time per UAV-step of the
  filter and the method's FLOPs on the stated processor profile (``swarmloc.envs.world.cost``;
  docs/scoring.md), mean over the board's tasks of each task's mean, and its **worst task** (the task with the
  highest mean, where the budget binds first: the largest swarm). Null where the method reports
  no FLOPs (a Track B estimator that reports none): "not measured";
* **over budget**: the tasks whose mean delay exceeds T_max, of the tasks measured;
* **FLOPs per channel**: what a Track A method declares per present channel and step (results
  schema 6; null where it declares none, or the file predates it).

A standing that stands for several training runs takes the mean over its runs, task by task.
Standings keep the accuracy board's order (ranked, partial coverage, privileged), so the two read
side by side.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from swarmloc.envs.world.reward import STANDARD_WEIGHTS
from swarmloc.leaderboard.site.ranking import Standing, SuiteBoard

#: the decision budget per update [ms]: the standard reward's T_max (madrl)
DELAY_BUDGET_MS: float = STANDARD_WEIGHTS.t_max * 1e3


@dataclass(frozen=True)
class Compute:
    """One standing's cost on a board.

    Attributes:
        delay_ms: mean delay per update over the board's measured tasks [ms] (None: not measured).
        worst_task: the task of the highest mean delay, and that delay [ms] (None: not measured).
        over_budget: tasks whose mean delay exceeds :data:`DELAY_BUDGET_MS`.
        measured: tasks with a delay.
        flops_per_channel: declared FLOPs per channel and step (None: not declared).
    """

    delay_ms: float | None
    worst_task: tuple[str, float] | None
    over_budget: int
    measured: int
    flops_per_channel: float | None

    @property
    def within_budget(self) -> bool | None:
        """True when every measured task's mean delay is within the budget (None: not measured)."""
        return None if self.delay_ms is None else self.over_budget == 0


def task_delays(standing: Standing, tasks: Sequence[str]) -> dict[str, float]:
    """Task → mean delay per update [ms] of the standing (the mean over its runs), for the tasks measured."""
    delays = {}
    for task in tasks:
        values = [agg.mean for e in standing.entries if (agg := e.task_aggregates.get(task, {}).get("delay_ms"))]
        if len(values) == len(standing.entries):  # every run measured it
            delays[task] = sum(values) / len(values)
    return delays


def standing_compute(standing: Standing, tasks: Sequence[str]) -> Compute:
    """The compute view of one standing on a board of these tasks."""
    delays = task_delays(standing, tasks)
    flops = {e.flops_per_channel for e in standing.entries}
    worst = max(delays.items(), key=lambda item: item[1]) if delays else None
    return Compute(
        delay_ms=sum(delays.values()) / len(delays) if delays else None,
        worst_task=worst,
        over_budget=sum(d > DELAY_BUDGET_MS for d in delays.values()),
        measured=len(delays),
        flops_per_channel=flops.pop() if len(flops) == 1 else None,  # runs of one method declare the same
    )


def place(board: SuiteBoard, standing: Standing) -> str:
    """Where the standing sits in the accuracy tables: its # in the ranked table (``3``), its rank in the
    partial-coverage table (``p2``), or ``—`` (privileged: not ranked)."""
    if any(s is standing for s in board.ranked):
        return str(standing.separable_rank)
    return f"p{standing.rank}" if any(s is standing for s in board.partial) else "—"


def compute_rows(board: SuiteBoard) -> list[tuple[Standing, Compute]]:
    """Every standing of the board (ranked, partial, privileged, in board order) with its compute view."""
    return [(s, standing_compute(s, board.tasks)) for s in board.standings]


__all__ = ["DELAY_BUDGET_MS", "Compute", "compute_rows", "place", "standing_compute", "task_delays"]
