"""``swarmloc train pfnn``: fit the PF-NN weight-correction network offline on training seeds."""

from __future__ import annotations

from dataclasses import dataclass

from swarmloc.bench.training.pfnn import TrainPfnnArgs


@dataclass
class Options(TrainPfnnArgs):
    """Fit the PF-NN weight-correction network offline on training seeds (frozen at evaluation)."""


def run(opts: Options) -> int:
    """Fit and write the weights (+ provenance)."""
    from swarmloc.bench.training.pfnn import train_pfnn

    try:
        train_pfnn(opts)
    except ValueError as err:
        print(f"error: {err}")
        return 2
    return 0
