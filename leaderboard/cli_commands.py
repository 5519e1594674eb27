"""Typed commands behind ``swarmloc submit`` and ``swarmloc leaderboard``.

Each command is a dataclass (fields documented for ``tyro``) and a ``run_*`` function
returning a process exit status (0 success, 1 refused or failed). ``swarmloc.bench.cli``
wires them in; :func:`main` also runs them stand-alone::

    python -m swarmloc.leaderboard.cli_commands submit --results r.json --entry-point pkg.mod:make --name X --track A
    python -m swarmloc.leaderboard.cli_commands leaderboard show
    python -m swarmloc.leaderboard.cli_commands leaderboard html --out site/
    python -m swarmloc.leaderboard.cli_commands leaderboard export --format csv
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

from rich.console import Console
from rich.text import Text

from swarmloc.leaderboard.errors import StoreError, SubmissionError
from swarmloc.leaderboard.store import LeaderboardStore
from swarmloc.leaderboard.submit import submit
from swarmloc.leaderboard.verify import VerifyLimits
from swarmloc.leaderboard.views import export, print_leaderboard, render_html


@dataclass
class SubmitCommand:
    """Validate a results file, re-run a sample of its episodes, and store it."""

    results: Path
    """Results file written by `swarmloc evaluate`."""
    entry_point: str
    """The method: `package.module:factory`, `path/to/file.py:factory` or a registered name."""
    name: str
    """Name shown on the leaderboard (at most 64 characters)."""
    track: Literal["A", "B"]
    """A: link trust inside the env's CEKF; B: full estimator."""
    authors: str = ""
    """Authors (at most 256 characters)."""
    url: str | None = None
    """Paper or code link (http:// or https://)."""
    description: str = ""
    """Short description (at most 2000 characters)."""
    privileged: bool = False
    """The method reads ground truth or fault labels (listed apart, not ranked)."""
    weights: Path | None = None
    """Weights file the method loads; its SHA-256 must match the results file."""
    search_path: tuple[Path, ...] = ()
    """Directories the method's modules are imported from."""
    db_url: str | None = None
    """Store URL (default: $SWARMLOC_DB, else a SQLite file in the user data directory)."""
    trust: bool = False
    """Skip verification; allowed only for the shipped reference methods."""
    sample_frac: float = 0.1
    """Fraction of episodes re-run for verification (at least `min_episodes`)."""
    min_episodes: int = 3
    """Minimum number of episodes re-run."""
    seed: int | None = None
    """Seed of the episode sampler (random when omitted; recorded in the store)."""
    time_limit_s: float = 900.0
    """Wall-time limit of the verification re-run, in seconds."""
    memory_limit_mb: int = 8192
    """Address-space limit of the verification worker, in MiB."""


@dataclass
class LeaderboardShow:
    """Print the leaderboard in the terminal."""

    db_url: str | None = None
    """Store URL (default: $SWARMLOC_DB, else a SQLite file in the user data directory)."""
    suite: str | None = None
    """Only this suite (all suites when omitted)."""


@dataclass
class LeaderboardHtml:
    """Write the static HTML leaderboard site."""

    out: Path
    """Output directory (created if missing)."""
    db_url: str | None = None
    """Store URL (default: $SWARMLOC_DB, else a SQLite file in the user data directory)."""
    suite: str | None = None
    """Only this suite (all suites when omitted)."""


@dataclass
class LeaderboardExport:
    """Export the leaderboard as CSV or JSON."""

    format: Literal["csv", "json"] = "csv"
    """Output format."""
    out: Path | None = None
    """Output file (standard output when omitted)."""
    db_url: str | None = None
    """Store URL (default: $SWARMLOC_DB, else a SQLite file in the user data directory)."""
    suite: str | None = None
    """Only this suite (all suites when omitted)."""


LeaderboardCommand = LeaderboardShow | LeaderboardHtml | LeaderboardExport


def _refused(console: Console, what: str, err: Exception) -> int:
    console.print(Text(f"{what}: {err}", style="bold red"))
    return 1


def run_submit(cmd: SubmitCommand, console: Console | None = None) -> int:
    """Run ``swarmloc submit``; print the receipt or the reason for refusal.

    Returns:
        0 when stored, 1 when refused (nothing stored).
    """
    out = console or Console()
    try:
        receipt = submit(
            cmd.results,
            cmd.entry_point,
            {
                "name": cmd.name, "authors": cmd.authors, "url": cmd.url,
                "description": cmd.description, "track": cmd.track, "privileged": cmd.privileged,
            },
            weights=cmd.weights,
            db_url=cmd.db_url,
            trust=cmd.trust,
            sample_frac=cmd.sample_frac,
            min_episodes=cmd.min_episodes,
            sample_seed=cmd.seed,
            limits=VerifyLimits(wall_time_s=cmd.time_limit_s,
                                memory_bytes=cmd.memory_limit_mb * 1024**2),
            search_path=cmd.search_path,
        )
    except (SubmissionError, StoreError, ValueError) as err:
        return _refused(out, "submission refused", err)
    out.print(Text(receipt.describe()))
    return 0


def run_leaderboard(cmd: LeaderboardCommand, console: Console | None = None) -> int:
    """Run ``swarmloc leaderboard [show | html | export]``.

    Returns:
        0 on success, 1 when the store cannot be opened.
    """
    out = console or Console()
    try:
        store = LeaderboardStore(cmd.db_url)
    except StoreError as err:
        return _refused(out, "cannot open the leaderboard", err)
    with store:
        if isinstance(cmd, LeaderboardShow):
            print_leaderboard(store, cmd.suite, console)
        elif isinstance(cmd, LeaderboardHtml):
            index = render_html(store, cmd.out, cmd.suite)
            out.print(Text(f"wrote {index}"))
        else:
            text = export(store, cmd.format, cmd.suite)
            if cmd.out is None:
                sys.stdout.write(text)
            else:
                cmd.out.write_text(text, encoding="utf-8")
                out.print(Text(f"wrote {cmd.out}"))
    return 0


def main(argv: list[str] | None = None) -> int:
    """Stand-alone CLI (``submit`` and ``leaderboard show|html|export``) built with tyro."""
    import tyro

    Leaderboard = Annotated[
        Annotated[LeaderboardShow, tyro.conf.subcommand("show")]
        | Annotated[LeaderboardHtml, tyro.conf.subcommand("html")]
        | Annotated[LeaderboardExport, tyro.conf.subcommand("export")],
        tyro.conf.arg(name=""),
    ]
    command = tyro.cli(
        Annotated[SubmitCommand, tyro.conf.subcommand("submit")]
        | Annotated[
            Leaderboard,  # type: ignore[valid-type]
            tyro.conf.subcommand("leaderboard", description="Show, render or export the leaderboard."),
        ],
        args=argv,
    )
    if isinstance(command, SubmitCommand):
        return run_submit(command)
    return run_leaderboard(command)


if __name__ == "__main__":
    sys.exit(main())
