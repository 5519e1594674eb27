"""``swarmloc train mappo-set-gru``: the set + GRU link-trust actor with recurrent MAPPO (torchrl; training seeds only)."""

from __future__ import annotations

from dataclasses import dataclass

from swarmloc.cli.train_mappo import run  # noqa: F401  (``train_mappo`` dispatches on the config's type)
from swarmloc.bench.training.mappo import TrainSetGruArgs


@dataclass
class Options(TrainSetGruArgs):
    """Train the set + GRU link-trust actor (mappo-set-gru) on the v1 randomized families (dev-seed evaluation)."""
