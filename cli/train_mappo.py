"""``swarmloc train mappo``: MAPPO link trust on a task mixture (torchrl; training seeds only)."""

from __future__ import annotations

from dataclasses import dataclass

from swarmloc.bench.training.mappo import TrainMappoArgs, TrainSetGruArgs


@dataclass
class Options(TrainMappoArgs):
    """Train MAPPO link trust on a task mixture (torchrl; training seeds only; dev-seed evaluation)."""


def run(opts: Options | TrainSetGruArgs) -> int:
    """Train, write the weights and their provenance record."""
    from swarmloc.bench.training.mappo import train_mappo

    try:
        train_mappo(opts)
    except (ValueError, KeyError) as err:
        print(f"error: {err}")
        return 2
    return 0
