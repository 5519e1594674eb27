"""``swarmloc reproduce federated``: federated Tables 2–3 on GradualFault."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from swarmloc.bench.cli import print_report


@dataclass
class Options:
    """federated Tables 2–3 on GradualFault (Scheme 1, Scheme 2, the adaptive federated filter)."""

    out: Path = Path("federated.md")
    """Markdown file to write (a folder: <out>/federated.md); raw numbers go beside it as .json."""
    seeds: int = 16
    """Test seeds (1_000_000 …), at least 2."""
    version: int = 1
    """Benchmark version of the task: 1 (GradualFault-v1) or 0 (the frozen GradualFault-v0)."""


def run(opts: Options) -> int:
    """Write the report and print it."""
    from swarmloc.bench.reproduce.federated import reproduce_federated

    return print_report(lambda: reproduce_federated(opts.out, opts.seeds, opts.version))
