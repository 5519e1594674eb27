"""``swarmloc docs tasks``: the task pages, one Markdown page per registered task and an index.

Each page is its task class's docstring (``swarmloc.envs.tasks.docgen.task_pages``, over the
Gymnasium registry), so the pages say exactly what ``help(NLOSEnv)`` says. ``make docs`` runs
this command; ``--check`` (and a test) fail when the committed pages no longer match the
classes.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


@dataclass
class Options:
    """Write the task pages (docs/tasks/) from the task classes' docstrings."""

    out: Path = Path("docs/tasks")
    """Folder of the pages (created if missing)."""
    check: bool = False
    """Write nothing; exit 1 when a page is missing or differs from its task class, or no task has it."""


def stale_pages(out: Path, pages: dict[str, str]) -> list[str]:
    """The file names of ``pages`` (name → text) that ``out`` lacks or holds with another text."""
    return [name for name, text in pages.items()
            if not (out / name).is_file() or (out / name).read_text(encoding="utf-8") != text]


def run(opts: Options) -> int:
    """Write (or, with ``--check``, compare) the task pages; 1 when a page is stale or has no task."""
    from swarmloc.bench.common.files import write_text_atomic
    from swarmloc.envs.tasks.docgen import task_pages

    pages = task_pages()
    stale = stale_pages(opts.out, pages)
    # a page that no registered task generates any more (a renamed or removed task)
    orphans = sorted(p.name for p in opts.out.glob("*.md") if p.name not in pages) if opts.out.is_dir() else []
    for name in orphans:
        print(f"{opts.out / name}: no registered task has this page; delete it")
    if opts.check:
        if stale:
            print(f"{opts.out}: {len(stale)} of {len(pages)} pages differ from the task classes "
                  f"({', '.join(stale[:5])}{', …' if len(stale) > 5 else ''}); run `swarmloc docs tasks`")
        if stale or orphans:
            return 1
        print(f"{opts.out}: the {len(pages)} task pages are current")
        return 0
    opts.out.mkdir(parents=True, exist_ok=True)
    for name in stale:
        write_text_atomic(opts.out / name, pages[name])
    print(f"{opts.out}: {len(stale)} of {len(pages)} task pages rewritten")
    return 0
