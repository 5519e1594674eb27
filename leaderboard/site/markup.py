"""HTML building blocks of the leaderboard site: escaping, the page frame, a number cell, a method's marks.

Every submitted string goes through :func:`escape`; the page frame carries a Content-Security-Policy
that allows the site's own files only.
"""

from __future__ import annotations

import html

from swarmloc.leaderboard.site.ranking import (
    PRIVILEGED_TRAINING_MARK,
    PRIVILEGED_TRAINING_NOTE,
    Standing,
    fmt_times,
    privileged_training,
)

CSP = (
    "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self'; "
    "base-uri 'none'; form-action 'none'"
)


def escape(value: object) -> str:
    """HTML-escape any value (quotes included, so it is safe in attributes)."""
    return html.escape(str(value), quote=True)


def page(title: str, body: str, root: str) -> str:
    """A whole page: ``body`` in the site's frame (CSP, stylesheet, table sorter), links relative to ``root``."""
    return (
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
        f"<meta http-equiv=\"Content-Security-Policy\" content=\"{CSP}\">\n"
        "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n"
        "<meta name=\"referrer\" content=\"no-referrer\">\n"
        f"<title>{escape(title)}</title>\n"
        f"<link rel=\"stylesheet\" href=\"{root}static/leaderboard.css\">\n"
        f"<script src=\"{root}static/leaderboard.js\" defer></script>\n"
        f"</head>\n<body>\n{body}\n</body>\n</html>\n"
    )


def num_cell(value: float | None, text: str, title: str | None = None) -> str:
    """A number's table cell: ``text`` shown, ``value`` sorted by (empty when None), ``title`` on hover."""
    data = "" if value is None else repr(float(value))
    tip = "" if title is None else f" title=\"{escape(title)}\""
    return f"<td class=\"num\" data-value=\"{data}\"{tip}>{escape(text)}</td>"


def made_marks(standing: Standing) -> str:
    """After a method's name: ‡ when fitted to privileged labels while training, and its runs when several."""
    marks = ""
    if privileged_training(standing):
        marks += f" <span class=\"mark\" title=\"{escape(PRIVILEGED_TRAINING_NOTE)}\">{PRIVILEGED_TRAINING_MARK}</span>"
    if standing.over_runs is not None:
        each = ", ".join(f"run {e.run}: 2^S {fmt_times(2.0 ** s)}"
                         for e, s in zip(standing.entries, standing.over_runs.runs))
        tip = f"interquartile mean over {standing.n_runs} training runs ({each})"
        marks += f" <span class=\"runs\" title=\"{escape(tip)}\">({standing.n_runs} runs)</span>"
    return marks


__all__ = ["CSP", "escape", "made_marks", "num_cell", "page"]
