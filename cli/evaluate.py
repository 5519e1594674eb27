"""``swarmloc evaluate``: one method on a suite → a results file (and traces beside it)."""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Literal


@dataclass
class Options:
    """Evaluate a method on a suite and write a results file."""

    method: str
    """Registered name (see `swarmloc methods`), `name+smooth`, `package.module:factory` or `path/to/file.py:factory`."""
    out: Path
    """Results file to write (JSON); per-step traces of the first seeds go to `<stem>.traces.npz` beside it."""
    suite: str = "quick-v2"
    """Suite: `quick-v2`, `standard-v2`, `dev-v2` (benchmark v2, one board per track); `quick-v1`, `standard-v1`,
    `dev-v1` (benchmark v1, deprecated; the shipped board); `quick`, `standard-v0`, `dev` (the frozen v0 tasks);
    `real-v0` or `real-v1` (real flights; need the imported data)."""
    tasks: str | None = None
    """Only these tasks of the suite, comma-separated IDs (the `swarmloc/` prefix may be omitted)."""
    workers: int = 1
    """Worker processes (jobs run in parallel), or the CPUs of a local Ray cluster."""
    backend: Literal["serial", "process", "ray"] | None = None
    """Where the (method, task, seed-chunk) jobs run: `serial` (here), `process` (worker processes on this
    machine) or `ray` (a Ray cluster; `pip install "swarmloc[ray]"`). Default: serial with `--workers 1`, else
    process. Every backend gives the same numbers."""
    address: str | None = None
    """With `--backend ray`: the cluster to join, `auto` (the one `ray start` runs on this node) or `HOST:PORT`.
    Default: $RAY_ADDRESS, else a local cluster of `--workers` CPUs."""
    seeds_per_job: int | None = None
    """Split each task's seeds into jobs of this many (more jobs than tasks for a big cluster). Default: one job
    per task. Methods whose numbers depend on the batch size (mappo, by ~1e-9) reproduce only at equal splits."""
    weights: Path | None = None
    """Weights file handed to the method's factory as `weights=`."""
    progress: bool = True
    """Show a progress bar."""


def run(opts: Options) -> int:
    """Run the evaluation and print a one-line summary per task."""
    from rich.console import Console
    from rich.markup import escape

    from swarmloc.bench.evaluation.backends import check_backend
    from swarmloc.bench.evaluation.runner import EvaluationFailed, evaluate
    from swarmloc.bench.evaluation.suites import get_suite, require_data, restrict_tasks
    from swarmloc.bench.scoring.score import suite_score
    from swarmloc.bench.scoring.tracks import tasks_by_track
    from swarmloc.cli.extras import missing_extra

    console = Console(stderr=True)
    if ":" in opts.method and os.getcwd() not in sys.path:
        sys.path.insert(0, os.getcwd())  # like `python -m`: modules in the working directory import
    try:
        suite = get_suite(opts.suite)
        if opts.tasks:
            suite = restrict_tasks(suite, opts.tasks)
        require_data(suite)
        backend = check_backend(opts.backend, opts.workers, opts.address)
    except (KeyError, ValueError, FileNotFoundError) as err:
        console.print(f"[red]error:[/red] {err.args[0] if err.args else err}")
        return 2
    if not opts.out.parent.exists():
        console.print(f"[red]error:[/red] output folder {opts.out.parent} does not exist")
        return 2
    started = time.perf_counter()
    try:
        results = evaluate(opts.method, suite, opts.out, workers=opts.workers, backend=backend, address=opts.address,
                           seeds_per_job=opts.seeds_per_job, weights=str(opts.weights) if opts.weights else None,
                           progress=opts.progress)
    except EvaluationFailed as err:
        console.print(f"[red]error:[/red] {escape(str(err))}")
        return 1
    except ImportError as err:
        if missing_extra(err) is not None:
            raise  # torch for a learned method, Ray for --backend ray: the command line names the extra
        console.print(f"[red]error:[/red] {err}")
        return 2
    except KeyboardInterrupt:
        console.print(f"[yellow]interrupted[/yellow]: outstanding jobs cancelled, {opts.out} not written")
        return 130
    score = suite_score([e.model_dump() for e in results.episodes], list(results.aggregates),
                        suite=results.suite.name)
    for task, per_metric in results.aggregates.items():
        rmse, bound = per_metric["rmse"], per_metric["bound_rmse"]
        if rmse is None or score is None or task not in score.tasks:
            console.print(f"  {task:34s} [yellow]not run[/yellow]: the method cannot run this task")
            continue
        t = score.tasks[task]
        closed = "" if t.gap_closed is None else f"   gap closed {100 * t.gap_closed:4.0f}%"
        console.print(f"  {task:34s} RMSE {rmse.mean:8.3f} m   {2.0 ** t.mean:6.2f}× uniform"
                      f"   bound {'—' if bound is None else f'{bound.mean:.3f} m'}{closed}")
    # one score per benchmark v2 track (scores never mix tracks); a v0/v1 suite has one
    by_track = tasks_by_track(results.aggregates)
    for track, tasks in by_track.items():
        part = score if track is None else suite_score(
            [e.model_dump() for e in results.episodes if e.task in tasks], tasks, suite=results.suite.name)
        if part is None:
            continue
        low, high = part.times_ci
        k, n = part.coverage
        closed = "—" if part.gap_closed is None else f"{100 * part.gap_closed:.0f}%"
        label = "score" if track is None else f"score, {track} track"
        console.print(f"{label}: {part.times:.2f}× lower error than the standard CEKF (95% CI [{low:.2f}, "
                      f"{high:.2f}]), gap closed {closed}, IQM g {part.iqm:.2f}, tasks {k}/{n}")
    console.print(f"wrote {opts.out} ({len(results.episodes)} episodes, {time.perf_counter() - started:.1f} s)")
    return 0
