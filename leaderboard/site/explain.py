"""The leaderboard site's explanations: each shipped Track A method's trust decisions on the step-NLOS task.

For a method page whose entry is a shipped, non-privileged Track A method (a registered
name, see ``SHIPPED_REFERENCE_METHODS``), the site runs ``swarmloc explain`` on
``EXPLAIN_TASK`` (NLOSStep-v1 once it exists, else v0; the first test seed) and keeps
``explain/<id>/`` — the Figure 6 chain (``figure.png``) and the Table 5 summary
(``summary.md``, ``summary.json``) — and the page shows the figure, the summary's main
numbers and links to both. User submissions are not re-run here: the site only runs the
code it ships.
"""

from __future__ import annotations

import html
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from swarmloc.leaderboard.store.database import SHIPPED_REFERENCE_METHODS

#: the first test seed (``swarmloc.envs.tasks.seeds.TEST_SEED_START``)
EXPLAIN_SEED = 1_000_000
#: episode length override [s] (None: the task's 50 s; tests shorten it)
EXPLAIN_DURATION: float | None = None


def explain_task() -> str:
    """``swarmloc/NLOSStep-v1`` when registered, else ``swarmloc/NLOSStep-v0``."""
    from swarmloc.envs.tasks.catalogue import CATALOGUE

    return "swarmloc/NLOSStep-v1" if "swarmloc/NLOSStep-v1" in CATALOGUE else "swarmloc/NLOSStep-v0"


def explainable(entry: Any) -> bool:
    """Whether the site explains this entry: a shipped, non-privileged Track A method."""
    return entry.track == "A" and not entry.privileged and entry.entry_point in SHIPPED_REFERENCE_METHODS


@dataclass(frozen=True)
class SiteExplanation:
    """What a method page shows: the folder's files (relative to the site root) and the summary."""

    figure: str
    markdown: str
    json: str
    summary: dict[str, Any]


def write_explanation(entry: Any, out: Path) -> SiteExplanation:
    """Explain ``entry``'s method into ``out / "explain" / <id>`` (overwritten)."""
    from swarmloc.bench.explain import explain
    from swarmloc.bench.explain.figure import plot_chain
    from swarmloc.bench.explain.report import summarize, write_summary

    folder = out / "explain" / str(entry.id)
    folder.mkdir(parents=True, exist_ok=True)
    overrides = {} if EXPLAIN_DURATION is None else {"duration": EXPLAIN_DURATION}
    ex = explain(entry.entry_point, explain_task(), [EXPLAIN_SEED], **overrides)
    figure = plot_chain(ex, folder / "figure.png")
    summary = summarize(ex)
    report = write_summary(summary, folder, figure.name)
    rel = f"explain/{entry.id}"
    return SiteExplanation(figure=f"{rel}/{figure.name}", markdown=f"{rel}/{report.name}",
                           json=f"{rel}/{report.with_suffix('.json').name}", summary=summary)


def _num(value: float | None, digits: int = 3) -> str:
    return "—" if value is None else f"{value:.{digits}f}"


def explanation_section(ex: SiteExplanation | None, error: str | None, root: str = "../") -> str:
    """The method page's "Explanation" section (empty when there is neither an explanation nor an error)."""
    e = lambda v: html.escape(str(v), quote=True)
    if ex is None:
        return "" if error is None else (f"<section id=\"explanation\"><h2>Explanation</h2><p class=\"meta\">"
                                         f"Explanation unavailable: {e(error)}</p></section>")
    s = ex.summary
    top = s["top_features"]["attacked_inside"][:3]
    drivers = ", ".join(f"{e(t['feature'])} ({t['mean']:+.3f})" for t in top) or "—"
    window = s["fault_window_s"]
    span = "" if window is None else f" inside {window[0]:g}–{window[1]:g} s"
    return "\n".join([
        "<section id=\"explanation\"><h2>Explanation on " + e(s["task"]) + "</h2>",
        (f"<p class=\"meta\">Why the method trusted each channel as it did (madrl Experiment 4), seed "
         f"{e(s['seeds'][0])}: {e(s['explainer'])} attributions of α to the observation features, baseline "
         f"{e(s['baseline'])}.</p>"),
        "<table class=\"facts\">",
        f"<tr><th scope=\"row\">Mean α, attacked channel{e(span)}</th><td>{_num(s['alpha_attacked'])}</td></tr>",
        f"<tr><th scope=\"row\">Mean α, normal channels{e(span)}</th><td>{_num(s['alpha_normal'])}</td></tr>",
        (f"<tr><th scope=\"row\">Fault-window RMSE [m]</th><td>{_num(s['fault_rmse'])} "
         f"(uniform {_num(s['reference_fault_rmse'])})</td></tr>"),
        f"<tr><th scope=\"row\">What drives the attacked channel's α</th><td>{drivers}</td></tr>",
        "</table>",
        (f"<figure><img src=\"{root}{e(ex.figure)}\" alt=\"innovation, trust, error and attributions over "
         f"time\" loading=\"lazy\"></figure>"),
        (f"<p><a href=\"{root}{e(ex.markdown)}\">Table 5 summary (Markdown)</a> · "
         f"<a href=\"{root}{e(ex.json)}\" download>summary JSON</a></p></section>"),
    ])
