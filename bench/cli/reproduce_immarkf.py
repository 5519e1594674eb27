"""``swarmloc reproduce immarkf``: imm-arkf Table 2 on HybridNoise{10,30,50}."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from swarmloc.bench.cli import print_report


@dataclass
class Options:
    """imm-arkf Table 2 on HybridNoise{10,30,50} (IMM-ARKF vs IMM-KF vs IMM-EKF), beside the paper's numbers."""

    out: Path = Path("immarkf.md")
    """Markdown file to write (a folder: <out>/immarkf.md); raw numbers go beside it as .json."""
    seeds: int = 16
    """Test seeds per task (1_000_000 …), at least 2."""
    duration: float | None = None
    """Episode length [s] (default: the tasks' 60 s)."""
    version: int = 1
    """Benchmark version of the tasks: 1 (contamination mixture) or 0 (the frozen v0, eq. 1 as printed)."""


def run(opts: Options) -> int:
    """Write the report and print it."""
    from swarmloc.bench.reproduce.immarkf import reproduce_immarkf

    return print_report(lambda: reproduce_immarkf(opts.out, opts.seeds, opts.duration, opts.version))
