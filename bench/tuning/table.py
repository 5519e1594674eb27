"""The tables of docs/tuning.md, rendered from the shipped tuning records (``swarmloc docs tuning``)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from swarmloc.agents.trust.search_space import Param

#: docs/tuning.md's generated tables sit between these two lines
START = "<!-- tuning:start -->"
END = "<!-- tuning:end -->"


def read_records(records_dir: str | Path, methods: list[str]) -> list[dict[str, Any]]:
    """The records of ``methods`` found in ``records_dir`` (``<method>.json``), in the order given."""
    paths = [Path(records_dir) / f"{m}.json" for m in methods]
    return [json.loads(p.read_text(encoding="utf-8")) for p in paths if p.is_file()]


#: a tuned value this close to an end of its range, as a share of the range on its sampled scale, is marked
EDGE = 0.02


def _value(x: float) -> str:
    return f"{x:.5g}"


def _tuned(param: Param, value: float) -> str:
    """The tuned value, marked when it sits at an end of its range (the best may lie outside the space)."""
    where = param.position(value)
    edge = " (low end)" if where < EDGE else " (high end)" if where > 1.0 - EDGE else ""
    return f"{_value(value)}{edge}"


def _times(track: dict[str, Any]) -> str:
    low, high = track["times_ci"]
    return f"{track['times']:.2f}× [{low:.2f}, {high:.2f}]"


def tuning_tables(records: list[dict[str, Any]]) -> str:
    """The two Markdown tables of the records: the values searched and chosen, and the dev-v2 scores.

    Args:
        records: tuning records (``swarmloc.bench.tuning.search.tune``'s), one per method.

    Returns:
        Markdown, ending in a newline; a line saying so when there is no record.
    """
    if not records:
        return "No tuning record is shipped yet.\n"
    lines = ["| method | parameter | searched over | scale | default | tuned |", "|---|---|---|---|---|---|"]
    for r in records:
        default, chosen = r["default"]["params"], r["params"]
        for p in (Param(**fields) for fields in r["space"]):
            lines.append(f"| `{r['method']}` | `{p.name}` | [{_value(p.low)}, {_value(p.high)}] | {p.scale} "
                         f"| {_value(default[p.name])} | {_tuned(p, chosen[p.name])} |")
    tracks = list(records[0]["chosen"]["tracks"])
    head = " | ".join(f"{t}: default | {t}: tuned" for t in tracks)
    lines += ["", f"| method | trials | chosen trial | {head} | mean S: default → tuned | wall time |",
              "|---|---|---|" + "---|---|" * len(tracks) + "---|---|"]
    for r in records:
        default, chosen = r["default"], r["chosen"]
        cells = " | ".join(f"{_times(default['tracks'][t])} | {_times(chosen['tracks'][t])}" for t in tracks)
        lines.append(f"| `{r['method']}` | {r['budget']['trials']} | {chosen['trial']} | {cells} "
                     f"| {default['objective']:+.3f} → {chosen['objective']:+.3f} | {r['wall_seconds'] / 60:.1f} min |")
    return "\n".join(lines) + "\n"


def replace_block(text: str, block: str) -> str:
    """``text`` with the part between :data:`START` and :data:`END` replaced by ``block``.

    Raises:
        ValueError: either marker is missing, or END comes before START.
    """
    start, end = text.find(START), text.find(END)
    if start < 0 or end < start:
        raise ValueError(f"the page needs the lines {START!r} and then {END!r}")
    return text[: start + len(START)] + "\n" + block + text[end:]
