"""``swarmloc reproduce madrl``: madrl Experiments 1 and 3–7 on our tasks, beside the paper's tables."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from swarmloc.bench.cli import print_report


@dataclass
class Options:
    """madrl Experiments 1, 3–7 on our tasks (test seeds), beside the paper's tables."""

    out: Path = Path("madrl.md")
    """Markdown file to write (a folder: <out>/madrl.md); raw numbers go beside it as .json."""
    seeds: int = 32
    """test seeds per task (1_000_000 …; 32 = the standard-v0 / standard-v1 episodes)."""
    traces: int = 8
    """seeds per task whose per-step traces give per-channel weights, pre-fault and peak errors."""
    weights: Path | None = None
    """MAPPO weights (default: the shipped agents/weights/mappo.pt)."""
    accuracy_only_weights: Path | None = None
    """Weights of the reward ablation (default: the shipped mappo_accuracy_only.pt, if present)."""
    version: int = 1
    """Benchmark version of the tasks: 1 (`*-v1`, with the learned reference beside mappo) or 0 (the frozen v0)."""


def run(opts: Options) -> int:
    """Write the report and print it."""
    from swarmloc.bench.reproduce.madrl import reproduce_madrl

    return print_report(lambda: reproduce_madrl(opts.out, opts.seeds, opts.traces, opts.weights,
                                                opts.accuracy_only_weights, version=opts.version))
