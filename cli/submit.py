"""``swarmloc submit``: validate a results file, re-run a sample of its episodes in the sandbox, store it."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Literal

import tyro

if TYPE_CHECKING:
    from rich.console import Console


_FROM_RESULTS = "(default: the results file's)"


@dataclass
class Options:
    """Validate a results file, re-run a sample of its episodes in a sandbox, and store it."""

    results: Annotated[Path, tyro.conf.Positional, tyro.conf.arg(metavar="RESULTS")]
    """Results file written by `swarmloc evaluate` (it names the method, its track and privileged flag)."""
    entry_point: Annotated[str | None, tyro.conf.arg(metavar="ENTRY_POINT", help_behavior_hint=_FROM_RESULTS)] = None
    """The method: `package.module:factory`, `path/to/file.py:factory` or a registered name."""
    name: Annotated[str | None, tyro.conf.arg(metavar="STR", help_behavior_hint="(default: the results file's method "
                                                                            "name)")] = None
    """Name shown on the leaderboard, at most 64 characters."""
    track: Annotated[Literal["A", "B"] | None, tyro.conf.arg(metavar="{A,B}", help_behavior_hint=_FROM_RESULTS)] = None
    """A: link trust inside the env's CEKF; B: full estimator."""
    authors: str = ""
    """Authors (at most 256 characters)."""
    url: str | None = None
    """Paper or code link (http:// or https://)."""
    description: str = ""
    """Short description (at most 2000 characters)."""
    privileged: Annotated[bool | None, tyro.conf.arg(metavar="{True,False}", help_behavior_hint=_FROM_RESULTS)] = None
    """The method reads ground truth or fault labels (listed apart, not ranked)."""
    weights: Path | None = None
    """Weights file given to `swarmloc evaluate --weights`; its SHA-256 must match the results file."""
    search_path: tuple[Path, ...] = ()
    """Directories the method's modules are imported from, shown read-only to the method's sandbox (default for a
    `module:factory` method not installed as a package: the working directory, as `swarmloc evaluate` imports
    it)."""
    db_url: str | None = None
    """Store URL, e.g. `sqlite:///lb.db` or `postgresql+psycopg://user@host/db` (default: $SWARMLOC_DB, else a
    SQLite file in the user data directory)."""
    trust: bool = False
    """Skip verification; allowed only for the shipped reference methods."""
    sandbox: bool = True
    """Re-run inside bubblewrap (`bwrap`). `--no-sandbox` is for your own method on your own store where bwrap is
    unavailable: it keeps only the time, memory, process and file-size limits."""
    sample_frac: float = 0.1
    """Fraction of episodes re-run for verification (at least `min_episodes`)."""
    min_episodes: int = 3
    """Minimum number of episodes re-run."""
    seed: int | None = None
    """Seed of the episode sampler (random when omitted; recorded in the store)."""
    time_limit_s: float = 900.0
    """Wall-time limit of the verification re-run, in seconds."""
    memory_limit_mb: int = 8192
    """Address-space limit of the verification worker and of the method's process, each, in MiB."""
    max_processes: int = 1024
    """Processes and threads each verification sandbox may hold."""
    max_file_mb: int = 64
    """Largest file (captured output included) a verification process may write, in MiB."""
    backend: Literal["serial", "process", "ray"] | None = None
    """Where the sandboxed re-runs run: on this machine (default; `serial` and `process` are the same here: one
    re-run), or `ray`: as Ray tasks, one sandboxed re-run per chunk of tasks, the same sandbox rules and limits
    for each (nodes see the method's files at the same paths)."""
    address: str | None = None
    """With `--backend ray`: the cluster to join, `auto` or `HOST:PORT` (default: $RAY_ADDRESS, else a local
    cluster of every CPU here)."""


def _module_search_path(entry_point: str) -> tuple[Path, ...]:
    """The working directory for a `module:factory` method found nowhere else (as `swarmloc evaluate` imports it)."""
    from swarmloc.leaderboard.submit.entry_points import locate_source, parse_entry_point

    entry = parse_entry_point(entry_point)
    if entry.kind != "module" or locate_source(entry) is not None:
        return ()
    return (Path.cwd(),)


def run(opts: Options, console: Console | None = None) -> int:
    """Submit; print the receipt or the reason for refusal.

    Returns:
        0 when stored, 1 when refused (nothing stored).
    """
    from rich.console import Console
    from rich.text import Text

    from swarmloc.cli.extras import missing_extra
    from swarmloc.leaderboard.errors import StoreError, SubmissionError
    from swarmloc.leaderboard.store.schema import read_submitted_results
    from swarmloc.leaderboard.submit.pipeline import submit
    from swarmloc.leaderboard.verify.verification import VerifyLimits, run_in_worker

    out = console or Console()
    if opts.address is not None and opts.backend != "ray":
        out.print(Text(f"submission refused: --address {opts.address} names a Ray cluster; it needs --backend ray",
                       style="bold red"))
        return 1
    rerun = run_in_worker
    if opts.backend == "ray":
        from swarmloc.leaderboard.verify.ray_rerun import ray_rerun

        rerun = ray_rerun(opts.address)
    try:
        results = read_submitted_results(opts.results)  # the one read: every step of the submission uses it
        entry_point = opts.entry_point or results.results.method.entry_point
        receipt = submit(
            results,
            entry_point,
            {
                "name": opts.name, "authors": opts.authors, "url": opts.url,
                "description": opts.description, "track": opts.track, "privileged": opts.privileged,
            },
            weights=opts.weights,
            db_url=opts.db_url,
            trust=opts.trust,
            sample_frac=opts.sample_frac,
            min_episodes=opts.min_episodes,
            sample_seed=opts.seed,
            limits=VerifyLimits(wall_time_s=opts.time_limit_s, memory_bytes=opts.memory_limit_mb * 1024**2,
                                max_processes=opts.max_processes, max_file_bytes=opts.max_file_mb * 1024**2),
            search_path=opts.search_path or _module_search_path(entry_point),
            sandbox=opts.sandbox,
            rerun=rerun,
        )
    except (SubmissionError, StoreError, ValueError, ImportError) as err:
        if missing_extra(err) is not None:
            raise  # not the submission's fault: the command line names the extra to install
        out.print(Text(f"submission refused: {err}", style="bold red"))
        return 1
    out.print(Text(receipt.describe()))
    return 0
