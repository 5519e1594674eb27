"""``swarmloc methods``: the method registry as a table."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class Options:
    """List the registered methods."""


def run(opts: Options) -> int:
    """Print a table of the method registry."""
    from rich.console import Console
    from rich.table import Table

    from swarmloc.agents.registry import REGISTRY

    table = Table(title="swarmloc methods (any Track A name also works as '<name>+smooth')")
    for name in ("name", "track", "privileged", "deterministic", "summary"):
        table.add_column(name)
    for e in REGISTRY.values():
        table.add_row(e.name, e.track, "yes" if e.privileged else "", "yes" if e.deterministic else "no", e.summary)
    Console().print(table)
    return 0
