"""``swarmloc reproduce dtvirm``: dtvirm Tables 1, 5, 6 (MDS-MAP, CI-EKF on AnchorFree-v0)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from swarmloc.bench.cli import print_report


@dataclass
class Options:
    """dtvirm Tables 1, 5, 6: MDS-MAP initialization and the CI-EKF on AnchorFree-v0."""

    out: Path = Path("dtvirm.md")
    """Markdown file to write (a folder: <out>/dtvirm.md); raw numbers go beside it as .json."""
    seeds: int = 16
    """AnchorFree-v0 test seeds (1_000_000 …), at least 2."""
    trials: int = 200
    """Monte Carlo trials of the Table 1 initializer comparison (the paper: 500)."""


def run(opts: Options) -> int:
    """Write the report and print it."""
    from swarmloc.bench.reproduce.dtvirm import reproduce_dtvirm

    return print_report(lambda: reproduce_dtvirm(opts.out, opts.seeds, opts.trials))
