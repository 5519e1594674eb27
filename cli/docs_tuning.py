"""``swarmloc docs tuning``: docs/tuning.md's tables, rendered from the shipped tuning records.

The page shows, between two markers, the values each tunable method searched and chose and its
dev-v2 scores, read from ``agents/weights/tuned/<method>.json``. ``make docs`` runs this command;
``--check`` (and a test) fail when the page no longer matches the records.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


@dataclass
class Options:
    """Rewrite docs/tuning.md's tables from the shipped tuning records."""

    page: Path = Path("docs/tuning.md")
    """The page whose text between `<!-- tuning:start -->` and `<!-- tuning:end -->` is replaced."""
    check: bool = False
    """Write nothing; exit 1 when the page's tables differ from the records."""


def run(opts: Options) -> int:
    """Write (or, with ``--check``, compare) the tables; 1 when stale, 2 when the page lacks the markers."""
    from swarmloc.agents.trust.tuned import RECORDS_DIR, TUNABLE
    from swarmloc.bench.common.files import write_text_atomic
    from swarmloc.bench.tuning.table import read_records, replace_block, tuning_tables

    text = opts.page.read_text(encoding="utf-8")
    try:
        new = replace_block(text, tuning_tables(read_records(RECORDS_DIR, list(TUNABLE))))
    except ValueError as err:
        print(f"error: {opts.page}: {err}")
        return 2
    if opts.check:
        if new != text:
            print(f"{opts.page} is stale: run swarmloc docs tuning")
            return 1
        return 0
    write_text_atomic(opts.page, new)
    print(f"wrote {opts.page}")
    return 0
