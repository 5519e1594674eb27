"""``swarmloc docs readme``: the README's leaderboard, rendered from the shipped results.

The README shows the board of the shipped ``standard-v1`` results between two markers. The
text between them is what ``swarmloc leaderboard show --suite standard-v1`` prints after
``swarmloc demo`` has stored those results: the same store, ranking and terminal tables
(``swarmloc.leaderboard.site.views``), printed into a fixed-width text block instead of a
terminal, as wide as its widest table (so that no method name folds). ``make docs`` runs this
command; ``--check`` (and a test) fail when the README's copy no longer matches the shipped
files.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

#: the README's leaderboard sits between these two lines
START = "<!-- leaderboard:start -->"
END = "<!-- leaderboard:end -->"


@dataclass
class Options:
    """Rewrite the README's leaderboard from the shipped standard-v1 results."""

    readme: Path = Path("README.md")
    """The file whose text between `<!-- leaderboard:start -->` and `<!-- leaderboard:end -->` is replaced."""
    check: bool = False
    """Write nothing; exit 1 when the README's leaderboard differs from the shipped results."""


#: methods per track in the README's board (the README is a front door; the whole board: leaderboard show)
README_TOP = 6


def leaderboard_block() -> str:
    """The shipped default board's first ``README_TOP`` methods per track as a fenced text block, as ``swarmloc
    leaderboard show`` prints them.

    Returns:
        The block, fences included, ending in a newline.

    Raises:
        RuntimeError: a shipped results file does not load into the store (the reason is named).
    """
    import io

    from rich.console import Console
    from rich.table import Table

    from swarmloc.bench.evaluation.shipped import DEFAULT_SUITE, RESULTS_DIRS
    from swarmloc.leaderboard.store.shipped import load_shipped
    from swarmloc.leaderboard.store.database import LeaderboardStore
    from swarmloc.leaderboard.site.views import TERMINAL_WIDTH, leaderboard_tables, print_leaderboard

    out = io.StringIO()
    with LeaderboardStore("sqlite://") as store:
        loaded = load_shipped(store, RESULTS_DIRS[DEFAULT_SUITE])
        if loaded.refused:
            raise RuntimeError("shipped results not loaded: " + "; ".join(f"{n}: {why}" for n, why in loaded.refused))
        # as wide as the widest table lays itself out (at least the terminal's width): squeezed into
        # fewer columns, rich would fold a long method name onto a second line
        unbounded = Console(width=10_000)
        tables = [part for part in leaderboard_tables(store, DEFAULT_SUITE, top=README_TOP) if isinstance(part, Table)]
        width = max([TERMINAL_WIDTH] + [unbounded.measure(table).maximum for table in tables])
        console = Console(file=out, width=width, color_system=None, highlight=False)
        print_leaderboard(store, DEFAULT_SUITE, console, top=README_TOP)
    lines = [line.rstrip() for line in out.getvalue().strip("\n").splitlines()]
    return "```text\n" + "\n".join(lines) + "\n```\n"


def with_leaderboard(text: str, block: str) -> str:
    """``text`` with everything between ``START`` and ``END`` replaced by ``block``.

    Args:
        text: the README's text.
        block: the new leaderboard (see :func:`leaderboard_block`).

    Raises:
        ValueError: the markers are missing, repeated or out of order.
    """
    if text.count(START) != 1 or text.count(END) != 1 or text.index(START) > text.index(END):
        raise ValueError(f"the README must hold one {START!r} line and, after it, one {END!r} line")
    head, rest = text.split(START, 1)
    _, tail = rest.split(END, 1)
    return f"{head}{START}\n{block}{END}{tail}"


def run(opts: Options) -> int:
    """Rewrite (or, with ``--check``, compare) the README's leaderboard; 1 when stale, 2 on a bad README."""
    try:
        text = opts.readme.read_text(encoding="utf-8")
        updated = with_leaderboard(text, leaderboard_block())
    except (OSError, ValueError) as err:
        print(f"error: {err}")
        return 2
    if updated == text:
        print(f"{opts.readme}: the leaderboard is current")
        return 0
    if opts.check:
        print(f"{opts.readme}: the leaderboard differs from the shipped results; run `swarmloc docs readme`")
        return 1
    from swarmloc.bench.common.files import write_text_atomic

    write_text_atomic(opts.readme, updated)
    from swarmloc.bench.evaluation.shipped import DEFAULT_SUITE

    print(f"{opts.readme}: leaderboard rewritten from the shipped {DEFAULT_SUITE} results")
    return 0
