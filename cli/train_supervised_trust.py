"""``swarmloc train supervised-trust``: the per-channel error-label classifier used as trust (no RL; training seeds only)."""

from __future__ import annotations

from dataclasses import dataclass

from swarmloc.bench.training.supervised_trust import TrainSupervisedTrustArgs


@dataclass
class Options(TrainSupervisedTrustArgs):
    """Fit the supervised-trust classifier on the v2 randomized families (training seeds; no RL)."""


def run(opts: Options) -> int:
    """Fit and write the weights (+ record)."""
    from swarmloc.bench.training.supervised_trust import train_supervised_trust

    try:
        train_supervised_trust(opts)
    except ValueError as err:
        print(f"error: {err}")
        return 2
    return 0
