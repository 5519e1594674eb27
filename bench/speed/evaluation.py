"""Evaluation throughput by execution backend: episodes/s of ``process`` and ``ray`` at 1 and 2 workers.

Rows (``impl``): ``evaluate-process`` and ``evaluate-ray`` at ``B`` = workers, each one
whole evaluation of :data:`METHOD` on the ``quick`` suite (every simulated task × 4 test
seeds, one job per task) in a fresh process pool or a fresh local Ray cluster, start-up
included — what a user waits for (the numba kernels compiled and cached beforehand, by
one serial episode). Besides ``episodes_per_s``, ``env_steps_per_s`` and
``wall_s``, a ``ray`` row has ``slowdown_vs_process`` (its wall time over the
``process`` row's at the same workers, minus 1) and ``overhead_s_per_task`` (the
difference per job). Not measured in quick mode: starting pools and clusters would be
the whole smoke test.

Measured by ``swarmloc bench speed`` (these rows among the others).
"""

from __future__ import annotations

import time
from collections.abc import Sequence

from swarmloc.bench.evaluation.suites import Suite, get_suite
from swarmloc.envs.tasks.catalogue import get_spec

METHOD = "pf"
"""The particle filter: a few seconds per task, so that start-up and scheduling are not the whole measurement."""


def measure_evaluation(suite: Suite, method: str = METHOD, backends: Sequence[str] = ("process", "ray"),
                       workers: Sequence[int] = (1, 2)) -> list[dict]:
    """Time one evaluation of ``method`` on ``suite`` per (backend, workers).

    Args:
        suite: the suite.
        method: the method evaluated.
        backends: among ``serial``, ``process``, ``ray``.
        workers: worker counts (a Ray cluster this process is already connected to is
            used as it is, whatever its size).

    Returns:
        Rows ``{"impl", "B", "episodes_per_s", "env_steps_per_s", "uav_steps_per_s", "wall_s", "jobs", ...}``.
    """
    from swarmloc.bench.evaluation.runner import evaluate_methods

    # warm-up: compile (and cache on disk) the numba kernels here, so that no row pays for it
    evaluate_methods([method], Suite("warm-up", "0", suite.episodes[:1]), trace=False, progress=False)
    specs = {t: get_spec(t) for t in suite.tasks}
    steps = sum(specs[t].n_steps for t, _ in suite.episodes)
    uav_steps = sum(specs[t].n_steps * specs[t].n_uav for t, _ in suite.episodes)
    rows, walls = [], {}
    for backend in backends:
        for n in workers:
            started = time.perf_counter()
            evaluate_methods([method], suite, workers=n, backend=backend, trace=False, progress=False)
            wall = walls[(backend, n)] = time.perf_counter() - started
            rows.append({"impl": f"evaluate-{backend}", "B": n, "method": method, "suite": suite.name,
                         "episodes": len(suite.episodes), "jobs": len(suite.tasks), "wall_s": wall,
                         "episodes_per_s": len(suite.episodes) / wall, "env_steps_per_s": steps / wall,
                         "uav_steps_per_s": uav_steps / wall})
    for row in rows:
        base = walls.get(("process", row["B"]))
        if row["impl"] == "evaluate-ray" and base is not None:
            row["slowdown_vs_process"] = row["wall_s"] / base - 1.0
            row["overhead_s_per_task"] = (row["wall_s"] - base) / row["jobs"]
    return rows


def measure_rows(quick: bool = False) -> list[dict]:
    """The evaluation-throughput rows of ``swarmloc bench speed`` (none in quick mode)."""
    if quick:
        return []
    try:
        import ray  # noqa: F401  (only to know whether the ray rows can be measured)
    except ImportError:
        return measure_evaluation(get_suite("quick"), backends=("process",))
    return measure_evaluation(get_suite("quick"))


def print_rows(rows: list[dict]) -> None:
    """The rows as a table: episodes/s, wall time and Ray's overhead."""
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"evaluation throughput ({rows[0]['method']} on {rows[0]['suite']})" if rows else "")
    for col in ("backend", "workers", "episodes/s", "wall [s]", "vs process", "overhead/task [s]"):
        table.add_column(col, justify="right")
    for r in rows:
        slower = r.get("slowdown_vs_process")
        overhead = r.get("overhead_s_per_task")
        table.add_row(r["impl"].removeprefix("evaluate-"), str(r["B"]), f"{r['episodes_per_s']:.2f}",
                      f"{r['wall_s']:.1f}", "—" if slower is None else f"{100 * slower:+.0f} %",
                      "—" if overhead is None else f"{overhead:+.2f}")
    Console().print(table)
