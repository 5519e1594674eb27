"""Markdown reports (paper reproductions, calibration): tables, file placement, atomic writing."""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from swarmloc.bench.common.files import write_text_atomic


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]], align: str = "") -> list[str]:
    """A Markdown table as lines.

    Args:
        header: column titles.
        rows: cells, already formatted.
        align: one character per column, ``l`` or ``r`` (default: every column left).
    """
    rule = [("---:" if a == "r" else "---") for a in (align or "l" * len(header))]
    return ["| " + " | ".join(header) + " |", "|" + "|".join(rule) + "|"] + ["| " + " | ".join(r) + " |"
                                                                          for r in rows]


def report_path(out: str | os.PathLike[str], name: str) -> Path:
    """Where a report goes: ``out`` itself, or ``<out>/<name>.md`` when ``out`` is a folder (or has no suffix)."""
    out = Path(out)
    return out / f"{name}.md" if out.is_dir() or not out.suffix else out


def write_report(path: str | os.PathLike[str], text: str, raw: dict[str, Any], indent: int = 1) -> Path:
    """Write the Markdown ``text`` and its raw numbers (``<path>.json``), each atomically.

    Args:
        path: the Markdown file; its folder is created if missing.
        text: the report.
        raw: the numbers behind it (floats of numpy types are converted).
        indent: JSON indentation.

    Returns:
        The Markdown path.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(path, text)
    write_text_atomic(path.with_suffix(".json"), json.dumps(raw, indent=indent, default=float) + "\n")
    return path
