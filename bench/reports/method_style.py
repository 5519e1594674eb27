"""One look per method in every plot: a colour, a line style and a marker.

Every figure that draws several methods (the leaderboard site's score, heatmap and profile
plots, ``swarmloc plot``'s error and CDF plots) takes its styles from :func:`method_styles`,
so a method looks the same in all of them and two methods in one figure never share a look
(matplotlib's default cycle gave every single-method figure the same blue, and repeats
after ten methods).

The shipped methods have fixed slots (``uniform``, the reference, is black and solid). Any
other name starts from a slot derived from a hash of the name, so it is stable across runs
and sites, and moves to the next free slot only when that look is already taken in the
same figure. Neighbouring slots differ in line style and marker as well as colour, so
lines stay apart in greyscale and for colour-blind readers.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable
from dataclasses import dataclass

#: black, then tab20 (dark and light of each hue adjacent), then three tab20b shades: 24 colours
PALETTE: tuple[str, ...] = (
    "#000000",
    "#1f77b4", "#aec7e8", "#ff7f0e", "#ffbb78", "#2ca02c", "#98df8a", "#d62728", "#ff9896",
    "#9467bd", "#c5b0d5", "#8c564b", "#c49c94", "#e377c2", "#f7b6d2", "#7f7f7f", "#c7c7c7",
    "#bcbd22", "#dbdb8d", "#17becf", "#9edae5",
    "#393b79", "#8c6d31", "#843c39",
)
LINESTYLES: tuple[str, ...] = ("-", "--", "-.", ":")
MARKERS: tuple[str, ...] = ("o", "s", "^", "D", "v", "P", "X", "*")

#: registered methods, in slot order (slot i: colour i, line style i mod 4, marker i mod 8)
KNOWN_METHODS: tuple[str, ...] = (
    "uniform", "oracle", "mappo", "mappo-no-smoothing", "chi2-soft", "chi2-gate", "huber",
    "mappo-accuracy-only", "random", "fixed", "federated-coef", "mappo-no-isolation",
    "dead-reckoning", "pf", "pf-800", "adaptive-pf", "pf-nn", "imm-kf", "imm-ekf", "imm-arkf",
    "federated", "federated-fdi", "ci-ekf", "ci-ekf-no-aa",
)

#: distinct (colour, line style, marker) looks
N_SLOTS = len(PALETTE) * len(LINESTYLES) * len(MARKERS)


@dataclass(frozen=True)
class MethodStyle:
    """How one method is drawn.

    Attributes:
        colour: matplotlib colour (hex).
        linestyle: matplotlib line style.
        marker: matplotlib marker.
    """

    colour: str
    linestyle: str
    marker: str

    def line(self) -> dict[str, str]:
        """Keyword arguments for ``Axes.plot``."""
        return {"color": self.colour, "linestyle": self.linestyle}


def _slot_style(slot: int) -> MethodStyle:
    """Slot k: colour k mod 24, line style k mod 4, marker k mod 8 — then the next combinations."""
    k = slot % N_SLOTS
    layer = k // len(PALETTE)  # past the first 24 slots, shift the style and marker sequences
    return MethodStyle(PALETTE[k % len(PALETTE)], LINESTYLES[(k + layer) % len(LINESTYLES)],
                       MARKERS[(k + layer // len(LINESTYLES)) % len(MARKERS)])


def _home_slot(name: str) -> int:
    base = name.removesuffix("+smooth")
    if base in KNOWN_METHODS:
        # a Track A "+smooth" variant gets the same colour with another line style and marker
        return KNOWN_METHODS.index(base) + (len(PALETTE) if base != name else 0)
    digest = hashlib.sha256(name.encode("utf-8")).digest()
    return len(KNOWN_METHODS) + int.from_bytes(digest[:4], "big") % (N_SLOTS - len(KNOWN_METHODS))


def method_styles(names: Iterable[str]) -> dict[str, MethodStyle]:
    """The style of every method in one figure: stable per name, never two alike.

    A name keeps its home slot unless a method earlier in ``names`` holds that look; then it
    takes the next slot whose colour is still free in the figure (or, with more than 24
    methods, the next free look).

    Args:
        names: method names, in drawing order (repeats are ignored).

    Returns:
        name → ``MethodStyle``.
    """
    unique = list(dict.fromkeys(names))
    styles: dict[str, MethodStyle] = {}
    colours: set[str] = set()
    looks: set[MethodStyle] = set()
    # known names first, so a hashed name never pushes a shipped method off its colour
    for name in sorted(unique, key=lambda n: n.removesuffix("+smooth") not in KNOWN_METHODS):
        slot = _home_slot(name)
        style = _slot_style(slot)
        need_new_colour = len(unique) <= len(PALETTE)
        while style in looks or (need_new_colour and style.colour in colours):
            slot += 1
            style = _slot_style(slot)
        styles[name] = style
        colours.add(style.colour)
        looks.add(style)
    return {name: styles[name] for name in unique}


def method_style(name: str) -> MethodStyle:
    """The style of a method drawn alone (its home slot)."""
    return _slot_style(_home_slot(name))


__all__ = ["KNOWN_METHODS", "LINESTYLES", "MARKERS", "PALETTE", "MethodStyle", "method_style", "method_styles"]
