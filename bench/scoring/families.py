"""Task families: which tasks the leaderboard and the reports group into one column.

A task's family comes from its ID: drop the ``swarmloc/`` namespace and the ``-v<N>``
version, then a trailing ``Random`` (the randomized variant) and trailing digits (a
swarm size or a contamination percentage), which leaves the task's *base* name::

    swarmloc/Scale32-v0 → Scale32 → Scale            swarmloc/HybridNoise10-v0 → HybridNoise
    swarmloc/CascadedFaultRandom-v0 → CascadedFault  swarmloc/NLOSStep-v0 → NLOSStep

``FAMILY_OF_BASE`` then names the family of each base (NLOS and NLOSStep are one family,
VisionLoss and Indoor are the pf-nn scenarios, UTILFlight and the UTIL TDOA flights are the real
flight data, TDOA the simulated TDOA room, AnchorNLOS benchmark v2's one-UAV anchor NLOS). A base
missing from the table is a family of its own, so a new task never disappears from a view.
This module is the one place that defines families; everything that groups tasks imports it.
"""

from __future__ import annotations

import re
from collections.abc import Iterable

NAMESPACE = "swarmloc/"

#: base name → family (see the module docstring for how a base is derived from a task ID)
FAMILY_OF_BASE: dict[str, str] = {
    "Ideal": "Ideal",
    "NLOS": "NLOS",
    "NLOSStep": "NLOS",
    "Scale": "Scale",
    "CascadedFault": "Cascaded",
    "VisionLoss": "Vision",
    "Indoor": "Vision",
    "HybridNoise": "Hybrid",
    "GradualFault": "Gradual",
    "AnchorFree": "AnchorFree",
    "UTILFlight": "Real",
    "TDOA": "TDOA",
    "AnchorNLOS": "AnchorNLOS",
    # the real UTIL TDOA flights (``tasks.UTIL_TDOA_FLIGHTS``)
    **{base: "Real" for base in (
        "UTILC0425Tdoa2Los", "UTILC0425Tdoa3Los", "UTILC0426Tdoa2NoLabel", "UTILC0426Tdoa2Wood",
        "UTILC0426Tdoa2WoodCardPlasticMetal", "UTILC0426Tdoa3NoObs", "UTILC0426Tdoa3WoodCardPlasticMetal",
        "UTILC0607Tdoa2WoodPlasticMetal")},
}

#: display order of the families (one not listed here comes after these, in order of appearance)
FAMILY_ORDER: tuple[str, ...] = (
    "Ideal", "NLOS", "Scale", "Cascaded", "Vision", "Hybrid", "Gradual", "AnchorFree", "AnchorNLOS", "TDOA", "Real",
)

_VERSION = re.compile(r"-v\d+$")
_VARIANT = re.compile(r"(?:Random(?:Shifted)?)?\d*(?:Random(?:Shifted)?)?$")


def short_task(task: str) -> str:
    """``swarmloc/Scale32-v0`` → ``Scale32-v0`` (the ID without its namespace)."""
    return task.removeprefix(NAMESPACE)


def task_label(task: str) -> str:
    """``swarmloc/Scale32-v0`` → ``Scale32`` (no namespace, no version): a column header."""
    return _VERSION.sub("", short_task(task))


def task_base(task: str) -> str:
    """The task's base name: its label without a ``Random`` / ``RandomShifted`` variant suffix and trailing digits.

    >>> task_base("swarmloc/CascadedFaultRandom-v0"), task_base("HybridNoise30-v1"), task_base("NLOSRandomShifted-v1")
    ('CascadedFault', 'HybridNoise', 'NLOS')
    """
    label = task_label(task)
    return _VARIANT.sub("", label) or label


def task_split(task: str) -> str:
    """The scenario split of a task: ``"fixed"``, ``"random"`` (``…Random``: scenario parameters
    drawn per episode, the in-distribution split learned methods train on) or ``"shifted"``
    (``…RandomShifted``: drawn outside the training ranges, the out-of-distribution split).

    >>> task_split("swarmloc/NLOS-v1"), task_split("NLOSRandom-v1"), task_split("ScaleRandomShifted-v1")
    ('fixed', 'random', 'shifted')
    """
    label = task_label(task)
    if label.endswith("RandomShifted"):
        return "shifted"
    return "random" if "Random" in label[len(task_base(task)):] else "fixed"


def task_family(task: str) -> str:
    """The family of a task ID (``FAMILY_OF_BASE`` of its base; the base itself if unlisted).

    >>> task_family("swarmloc/Scale16-v0"), task_family("swarmloc/Indoor-v0")
    ('Scale', 'Vision')
    """
    base = task_base(task)
    return FAMILY_OF_BASE.get(base, base)


def group_by_family(tasks: Iterable[str]) -> dict[str, list[str]]:
    """Tasks grouped by family, families in ``FAMILY_ORDER`` (others after, as they appear).

    Args:
        tasks: task IDs; their order is kept within each family.

    Returns:
        family → its tasks.
    """
    groups: dict[str, list[str]] = {}
    for task in tasks:
        groups.setdefault(task_family(task), []).append(task)
    rank = {family: i for i, family in enumerate(FAMILY_ORDER)}
    order = sorted(groups, key=lambda f: (rank.get(f, len(rank)), list(groups).index(f)))
    return {family: groups[family] for family in order}


__all__ = ["FAMILY_OF_BASE", "FAMILY_ORDER", "group_by_family", "short_task", "task_base", "task_family", "task_label", "task_split"]
