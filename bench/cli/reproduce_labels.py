"""``swarmloc reproduce labels``: the calibration of fault labels v1 (k) on standard-v0."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from swarmloc.bench.cli import print_report


@dataclass
class Options:
    """Calibrate fault labels v1: the oracle at k = 1 … 3 on every standard-v0 task, beside the best shipped
    method and the information bound."""

    out: Path = Path("docs/reproduce/labels.md")
    """Markdown file to write (a folder: <out>/labels.md); raw numbers go beside it as .json."""
    workers: int = 2
    """Worker processes of the runner (1 … 64)."""
    seeds: int = 32
    """Test seeds per task, the first of standard-v0's 32 (2 … 32; the shipped results are compared per seed)."""
    progress: bool = True
    """Show the runner's progress bars."""


def run(opts: Options) -> int:
    """Write the report and print it."""
    from swarmloc.bench.reproduce.labels import reproduce_labels

    return print_report(lambda: reproduce_labels(opts.out, workers=opts.workers, seeds=opts.seeds,
                                                 progress=opts.progress))
