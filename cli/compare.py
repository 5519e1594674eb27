"""``swarmloc compare``: two results files of one suite, paired episode by episode."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import tyro

from swarmloc.bench.scoring.bootstrap import DEFAULT_RESAMPLES

if TYPE_CHECKING:
    from rich.console import Console

    from swarmloc.bench.evaluation.results import Results
    from swarmloc.bench.scoring.compare import Comparison, TrackComparisons


@dataclass
class Options:
    """Compare two results files of one suite episode by episode (B against A, paired CIs)."""

    a: tyro.conf.Positional[str]
    """Results file of the reference (baseline), from `swarmloc evaluate`; or `shipped:<method>`, the
    shipped results of a reference method on the other file's suite (e.g. `shipped:cusum`)."""
    b: tyro.conf.Positional[str]
    """Results file compared with it (same suite); or `shipped:<method>`."""
    resamples: int = DEFAULT_RESAMPLES
    """Bootstrap resamples of the paired CIs (the leaderboard's default)."""
    json: Path | None = None
    """Also write the comparison as JSON to this file."""


#: columns of piped output: the widest task ID and the four number columns
PIPED_WIDTH = 100


def _signed(x: float) -> str:
    return f"{x:+.3f}"


def print_comparison(c: Comparison, console: Console) -> None:
    """The per-task table and the suite line (of one track of a v2 suite: its tasks, its verdict)."""
    from rich.markup import escape
    from rich.table import Table

    on = c.suite if c.track is None else f"{c.suite}, {c.track} track"
    table = Table(title=escape(f"B against A on {on}; B − A: gain over uniform in log2"), title_justify="left")
    table.add_column("task", no_wrap=True)
    for col in ("RMSE A [m]", "RMSE B [m]", "B − A [95 % CI]", "B ahead"):
        table.add_column(escape(col), justify="right", no_wrap=True)
    for t in c.tasks:
        d = t.difference
        style = "green" if d.ci_low > 0 else "red" if d.ci_high < 0 else None
        table.add_row(t.task.removeprefix("swarmloc/"), f"{t.rmse_a:.3f}", f"{t.rmse_b:.3f}",
                      f"{_signed(d.mean)} [{_signed(d.ci_low)}, {_signed(d.ci_high)}]", f"{d.ahead}/{d.count}",
                      style=style)
    console.print(table)
    d, (la, ha), (lb, hb) = c.difference, c.score_a.times_ci, c.score_b.times_ci
    console.print(f"2^S  A {c.score_a.times:.3f} [{la:.3f}, {ha:.3f}]   B {c.score_b.times:.3f} [{lb:.3f}, {hb:.3f}]")
    console.print(f"S_B − S_A = {_signed(d.mean)} log2 [{_signed(d.ci_low)}, {_signed(d.ci_high)}] (paired 95 % CI); "
                  f"B ahead on {d.ahead}/{d.count} tasks; P(B > A) = {c.p_improvement:.2f}")
    verdict = ("B is ahead beyond doubt" if d.ci_low > 0 else "A is ahead beyond doubt" if d.ci_high < 0
               else "level: the seeds cannot tell them apart")
    console.print(f"verdict{'' if c.track is None else f' ({c.track} track)'}: {verdict}")
    for task, why in c.left_out:
        console.print(f"left out: {task} ({why})")


def print_track_comparisons(c: TrackComparisons, console: Console) -> None:
    """Each board's comparison (one per track of a v2 suite, headline first), then what no track compared."""
    from rich.text import Text

    for comparison in c.comparisons.values():
        print_comparison(comparison, console)
    for what, why in c.not_compared:
        console.print(Text(f"not compared: {what} ({why})"))


SHIPPED = "shipped:"


def _load_pair(a: str, b: str) -> tuple[Results, Results]:
    """Read both results, each once; a ``shipped:<method>`` side is the shipped file of that method on
    the other side's suite (``standard-v1`` when both are shipped).

    Raises:
        KeyError: the suite has no shipped results, or the method none on it (the allowed ones named).
    """
    from swarmloc.bench.evaluation.results import load_results
    from swarmloc.bench.evaluation.shipped import DEFAULT_SUITE, RESULTS_DIRS, shipped_results

    def shipped(text: str, suite: str) -> Path:
        method = text.removeprefix(SHIPPED)
        if suite not in RESULTS_DIRS:
            raise KeyError(f"{text!r}: suite {suite!r} has no shipped results; those of {', '.join(RESULTS_DIRS)} do")
        known = [p.stem for p in shipped_results(RESULTS_DIRS[suite])]
        if method not in known:
            raise KeyError(f"{text!r}: no shipped results of {method!r} on {suite}; shipped: {', '.join(known)}")
        return RESULTS_DIRS[suite] / f"{method}.json"

    a, b = str(a), str(b)
    if a.startswith(SHIPPED) and b.startswith(SHIPPED):
        return load_results(shipped(a, DEFAULT_SUITE)), load_results(shipped(b, DEFAULT_SUITE))
    if a.startswith(SHIPPED):
        rb = load_results(Path(b))
        return load_results(shipped(a, rb.suite.name)), rb
    ra = load_results(Path(a))
    return ra, load_results(shipped(b, ra.suite.name)) if b.startswith(SHIPPED) else load_results(Path(b))


def run(opts: Options, console: Console | None = None) -> int:
    """Print the comparison; 2 when a file is invalid or the two cannot be paired."""
    import json
    import sys

    from rich.console import Console
    from rich.text import Text

    from swarmloc.bench.common.files import write_text_atomic
    from swarmloc.bench.scoring.compare import compare_tracks, track_comparisons_dict

    # piped output has no terminal width to fit: lay the table out for the width it needs
    console = console or (Console() if sys.stdout.isatty() else Console(width=PIPED_WIDTH))
    if opts.resamples < 1:
        console.print(Text(f"error: --resamples must be >= 1, got {opts.resamples}", style="bold red"))
        return 2
    try:
        a, b = _load_pair(opts.a, opts.b)
        # a v2 suite: one verdict per track, as the boards rank (scores never mix tracks)
        comparisons = compare_tracks(a, b, n_resamples=opts.resamples)
    except (ValueError, KeyError) as err:  # ResultsFileError is a ValueError
        console.print(Text(f"error: {err.args[0] if isinstance(err, KeyError) else err}", style="bold red"))
        return 2
    first = next(iter(comparisons.comparisons.values()))
    for label, path, name in (("A", opts.a, first.name_a), ("B", opts.b, first.name_b)):
        console.print(Text(f"{label}: {name} ({path})"))
    print_track_comparisons(comparisons, console)
    if opts.json is not None:
        write_text_atomic(opts.json, json.dumps(track_comparisons_dict(comparisons), indent=1) + "\n")
        console.print(f"wrote {opts.json}")
    return 0
