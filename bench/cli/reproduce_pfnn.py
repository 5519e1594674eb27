"""``swarmloc reproduce pfnn``: pf-nn Tables 4 (accuracy) and 5 (time per step) on Indoor-v0."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from swarmloc.bench.cli import print_report


@dataclass
class Options:
    """pf-nn Tables 4 (accuracy) and 5 (time per step) on Indoor, beside the paper's numbers."""

    out: Path = Path("pfnn.md")
    """Markdown file to write (a folder: <out>/pfnn.md); raw numbers go beside it as .json."""
    seeds: int = 32
    """Indoor test seeds (1_000_000 …)."""
    duration: float | None = None
    """Episode length [s] (default: the task's 100 s)."""
    timing_steps: int = 300
    """Steps of the Table 5 timing episode."""
    oracle: bool = True
    """Also run the privileged online-trained PF-NN (shown apart)."""
    version: int = 1
    """Benchmark version of the task: 1 (Indoor-v1, pf-nn's v1 fit) or 0 (the frozen Indoor-v0)."""


def run(opts: Options) -> int:
    """Write the report and print it."""
    from swarmloc.bench.reproduce.pfnn import reproduce_pfnn

    return print_report(lambda: reproduce_pfnn(opts.out, opts.seeds, opts.duration, opts.timing_steps, opts.oracle,
                                               version=opts.version))
