"""``swarmloc reproduce real``: every registered method on the real flights (suite real-v1) → docs/reproduce/real.md."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from swarmloc.bench.cli import print_report


@dataclass
class Options:
    """The sim-to-real report: every method on real-v1 (UTIL TWR + 8 TDOA flights) and on TDOA-v1."""

    out: Path = Path("real.md")
    """Markdown file to write (a folder: <out>/real.md); raw numbers beside it as .json, the plot as .png."""
    workers: int = 2
    """Worker processes."""
    seeds: int = 4
    """Test seeds per task, 1 … 4 (the suite's 4)."""
    methods: tuple[str, ...] = ()
    """Methods (default: every registered one)."""


def run(opts: Options) -> int:
    """Write the report and print it; without the data, say where it comes from (exit status 2)."""
    from swarmloc.bench.reproduce.real import reproduce_real

    return print_report(lambda: reproduce_real(opts.out, list(opts.methods) or None, workers=opts.workers,
                                               seeds=opts.seeds))
