"""``swarmloc bench speed``: side-by-side throughput of the filter, the world step and the estimators."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


@dataclass
class Options:
    """Speed benchmark: FilterPy, the numpy reference, the numba kernel and the world step, in one run."""

    json: Path | None = None
    """Also write the rows as JSON here (`{"rows": [...], "machine": {...}}`)."""
    quick: bool = False
    """Short runs (a smoke test; the numbers are not comparable)."""


def run(opts: Options) -> int:
    """Measure, print the table, write the JSON."""
    from swarmloc.bench.speed.kernels import run as run_speed

    if opts.json is not None and not opts.json.parent.exists():
        print(f"error: output folder {opts.json.parent} does not exist")
        return 2
    run_speed(opts.json, opts.quick)
    return 0
