"""The search space of a tunable link-trust policy: one :class:`Param` per constructor argument tuned.

A tunable policy class declares ``SEARCH_SPACE``, a tuple of :class:`Param`, beside its
constructor (``HuberTrust.SEARCH_SPACE`` …); ``swarmloc tune`` searches it and the tuned
record repeats it (docs/tuning.md). The declaration is library-neutral: the tuner maps each
``Param`` onto its sampler (``search_name``, ``search_bounds``, ``from_search``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

Scale = Literal["linear", "log", "log-tail"]
SCALES: tuple[str, ...] = ("linear", "log", "log-tail")


@dataclass(frozen=True)
class Param:
    """One tuned constructor argument and the closed range it is searched over.

    Attributes:
        name: the constructor's keyword (``k``, ``confidence`` …).
        low, high: the range, both ends included, low < high.
        scale: how the range is sampled: ``linear`` (uniform), ``log`` (log-uniform; low > 0), or
            ``log-tail`` (1 − value log-uniform; high < 1): for a probability near 1 such as a gate's
            confidence, where 0.99 → 0.9999 moves the χ² threshold as far as 0.8 → 0.99.
    """

    name: str
    low: float
    high: float
    scale: Scale = "linear"

    def __post_init__(self) -> None:
        if self.scale not in SCALES:
            raise ValueError(f"{self.name}: scale must be one of {list(SCALES)}, got {self.scale!r}")
        if not (math.isfinite(self.low) and math.isfinite(self.high) and self.low < self.high):
            raise ValueError(f"{self.name}: need finite low < high, got [{self.low!r}, {self.high!r}]")
        if self.scale == "log" and self.low <= 0.0:
            raise ValueError(f"{self.name}: a log scale needs low > 0, got {self.low!r}")
        if self.scale == "log-tail" and self.high >= 1.0:
            raise ValueError(f"{self.name}: a log-tail scale needs high < 1, got {self.high!r}")

    @property
    def search_name(self) -> str:
        """The name of the sampled variable: ``name``, or ``1-name`` on the log-tail scale."""
        return f"1-{self.name}" if self.scale == "log-tail" else self.name

    @property
    def search_bounds(self) -> tuple[float, float]:
        """``(low, high)`` of the sampled variable (1 − value on the log-tail scale)."""
        return (1.0 - self.high, 1.0 - self.low) if self.scale == "log-tail" else (self.low, self.high)

    @property
    def log(self) -> bool:
        """Whether the sampled variable is drawn log-uniformly."""
        return self.scale != "linear"

    def from_search(self, x: float) -> float:
        """The constructor's value of a sampled variable ``x``."""
        return 1.0 - x if self.scale == "log-tail" else float(x)

    def to_search(self, value: float) -> float:
        """The sampled variable of a constructor's ``value`` (the inverse of :meth:`from_search`)."""
        return 1.0 - value if self.scale == "log-tail" else float(value)

    def position(self, value: float) -> float:
        """Where ``value`` lies in the range on the sampled scale: 0 at ``low``, 1 at ``high``."""
        lo, hi, x = (math.log(v) if self.log else v for v in (*self.search_bounds, self.to_search(value)))
        where = (x - lo) / (hi - lo)
        return 1.0 - where if self.scale == "log-tail" else where  # 1 − value runs the other way

    def contains(self, value: float) -> bool:
        """Whether ``value`` lies in [low, high]."""
        return self.low <= value <= self.high
