"""``swarmloc tasks``: the task catalogue as a table."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class Options:
    """List the registered tasks."""


def run(opts: Options) -> int:
    """Print a table of the task catalogue."""
    from rich.console import Console
    from rich.table import Table

    from swarmloc.envs.tasks.catalogue import CATALOGUE, get_spec

    table = Table(title="swarmloc tasks")
    table.add_column("ID", no_wrap=True)
    for name in ("UAVs", "channels/UAV", "duration [s]", "dt [s]", "faults", "scored"):
        table.add_column(name)
    for task_id in CATALOGUE:
        s = get_spec(task_id)
        faults = [k for k, v in s.faults.model_dump().items() if v not in (None, (), [], 0.0)]
        table.add_row(task_id, str(s.n_uav), str(s.n_channels), f"{s.duration:g}", f"{s.dt:g}",
                      ", ".join(faults) or "—", "all" if not s.scoring.nodes else str(list(s.scoring.nodes)))
    Console().print(table)
    return 0
