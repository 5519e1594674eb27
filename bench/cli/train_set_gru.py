"""``swarmloc train mappo-set-gru``: the set + GRU link-trust actor with recurrent MAPPO (torchrl; training seeds only)."""

from __future__ import annotations

from dataclasses import dataclass

from swarmloc.bench.training.mappo import TrainSetGruArgs


@dataclass
class Options(TrainSetGruArgs):
    """Train the set + GRU link-trust actor (mappo-set-gru) on the v1 randomized families (dev-seed evaluation)."""


def run(opts: Options) -> int:
    """Train, write the weights and their provenance record."""
    from swarmloc.bench.training.mappo import train_mappo

    try:
        train_mappo(opts)
    except (ValueError, KeyError) as err:
        print(f"error: {err}")
        return 2
    return 0
