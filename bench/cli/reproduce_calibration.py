"""``swarmloc reproduce calibration``: the calibration report of a suite's tasks → docs/calibration.md + .json."""

from __future__ import annotations

import shlex
from dataclasses import dataclass, fields
from pathlib import Path

from swarmloc.bench.cli import print_report


@dataclass
class Options:
    """Calibrate the v1 tasks: per task the five criteria (ceiling valid, the fault matters, headroom, the paper's
    phenomenon, nothing degenerate) from the classical methods, the split comparison and the gap closed."""

    suite: str = "standard-v1"
    """Suite whose tasks are calibrated (see docs/suites.md)."""
    tasks: str | None = None
    """Only these tasks of the suite, comma-separated IDs (the `swarmloc/` prefix may be omitted)."""
    seeds: int | None = None
    """The first this many seeds of each task, at least 2 (default: all of the suite's)."""
    out_md: Path = Path("docs/calibration.md")
    """Markdown report to write."""
    out_json: Path = Path("docs/calibration.json")
    """The report's numbers, machine-readable."""
    workers: int = 1
    """Worker processes of the runner (1 … 64)."""
    progress: bool = True
    """Show the runner's progress bar."""


def command_line(opts: Options) -> str:
    """The command that reproduces a report: ``swarmloc reproduce calibration`` and its non-default options."""
    words = ["swarmloc", "reproduce", "calibration"]
    for f in fields(Options):
        value = getattr(opts, f.name)
        if f.name not in ("workers", "progress") and value != f.default:
            words += [f"--{f.name.replace('_', '-')}", str(value)]
    return shlex.join(words)


def run(opts: Options) -> int:
    """Write the report and its JSON; print the report."""
    from swarmloc.bench.reproduce.calibration import reproduce_calibration

    def write() -> Path:
        reproduce_calibration(opts.suite, opts.tasks, opts.seeds, opts.out_md, opts.out_json, workers=opts.workers,
                              progress=opts.progress, command=command_line(opts))
        return opts.out_md

    return print_report(write)
