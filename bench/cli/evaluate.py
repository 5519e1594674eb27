"""``swarmloc evaluate``: one method on a suite → a results file (and traces beside it)."""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path


@dataclass
class Options:
    """Evaluate a method on a suite and write a results file."""

    method: str
    """Registered name (see `swarmloc methods`), `name+smooth`, `package.module:factory` or `path/to/file.py:factory`."""
    out: Path
    """Results file to write (JSON); per-step traces of the first seeds go to `<stem>.traces.npz` beside it."""
    suite: str = "quick"
    """Suite: `quick`, `standard-v0`, `dev` or `real-v0` (real flights; needs the imported data)."""
    tasks: str | None = None
    """Only these tasks of the suite, comma-separated IDs (the `swarmloc/` prefix may be omitted)."""
    workers: int = 1
    """Worker processes (tasks run in parallel)."""
    weights: Path | None = None
    """Weights file handed to the method's factory as `weights=`."""
    progress: bool = True
    """Show a progress bar."""


def run(opts: Options) -> int:
    """Run the evaluation and print a one-line summary per task."""
    from rich.console import Console

    from swarmloc.bench.evaluation.runner import evaluate
    from swarmloc.bench.evaluation.stats import aggregate_across_tasks
    from swarmloc.bench.evaluation.suites import get_suite, require_data, restrict_tasks

    console = Console(stderr=True)
    if ":" in opts.method and os.getcwd() not in sys.path:
        sys.path.insert(0, os.getcwd())  # like `python -m`: modules in the working directory import
    try:
        suite = get_suite(opts.suite)
        if opts.tasks:
            suite = restrict_tasks(suite, opts.tasks)
        require_data(suite)
    except (KeyError, ValueError, FileNotFoundError) as err:
        console.print(f"[red]error:[/red] {err.args[0] if err.args else err}")
        return 2
    if not opts.out.parent.exists():
        console.print(f"[red]error:[/red] output folder {opts.out.parent} does not exist")
        return 2
    started = time.perf_counter()
    results = evaluate(opts.method, suite, opts.out, workers=opts.workers,
                       weights=str(opts.weights) if opts.weights else None, progress=opts.progress)
    for task, per_metric in results.aggregates.items():
        rmse = per_metric["rmse"]
        score = per_metric["normalized_score"]
        if rmse is None:
            console.print(f"  {task:34s} [yellow]not run[/yellow]: the method cannot run this task")
            continue
        console.print(f"  {task:34s} RMSE {rmse.mean:8.3f} m   score {'—' if score is None else f'{score.mean:7.3f}'}")
    overall = aggregate_across_tasks(results.episodes, "normalized_score")
    if overall is not None:
        console.print(f"normalized score {overall.mean:.3f} (IQM {overall.iqm:.3f}, 95% CI "
                      f"[{overall.ci_low:.3f}, {overall.ci_high:.3f}])")
    console.print(f"wrote {opts.out} ({len(results.episodes)} episodes, {time.perf_counter() - started:.1f} s)")
    return 0
