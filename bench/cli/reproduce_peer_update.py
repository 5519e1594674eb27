"""``swarmloc reproduce peer-update``: the registered CEKF's peer update against covariance intersection."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from swarmloc.bench.cli import print_report


@dataclass
class Options:
    """The CEKF's peer update as registered (a known point, madrl §2.3) against covariance intersection, on
    the standard-v1 tasks with peer channels: oracle ceiling, fault size and gate lock-outs under each."""

    out: Path = Path("peer-update.md")
    """Markdown file to write (a folder: <out>/peer-update.md); raw numbers go beside it as .json."""
    seeds: int = 32
    """Test seeds per task (1_000_000 …), at least 2."""
    tasks: list[str] = field(default_factory=list)
    """Task IDs (default: every standard-v1 task with peer channels)."""
    variants: bool = True
    """Also measure the spec variants a consistent filter could start from (Scale with anchors ranged
    within 11 m, HybridNoise without peers); not registered tasks."""


def run(opts: Options) -> int:
    """Write the report and print it."""
    from swarmloc.bench.reproduce.peer_update import reproduce_peer_update

    return print_report(lambda: reproduce_peer_update(opts.out, opts.seeds, opts.tasks or None, variants=opts.variants))
