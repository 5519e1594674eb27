"""``swarmloc plot``: the figures of results files (error vs time, error CDF, trust, trajectories)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import tyro


@dataclass
class Options:
    """Plot results files (error vs time, error CDF, trust, trajectories; methods compared per task)."""

    results: tyro.conf.Positional[tuple[Path, ...]]
    """Results files written by `swarmloc evaluate`."""
    out: Path = Path("swarmloc-plots")
    """Output folder for the PNGs."""


def run(opts: Options) -> int:
    """Write the PNGs."""
    from rich.console import Console

    from swarmloc.bench.reports.plots import plot_results

    if not opts.results:
        Console(stderr=True).print("[red]error:[/red] give at least one results file")
        return 2
    written = plot_results(list(opts.results), opts.out)
    Console().print(f"wrote {len(written)} plots to {opts.out}")
    return 0
