"""``swarmloc train mappo`` and ``swarmloc reproduce madrl`` (registered into the command groups).

Imported by ``swarmloc.bench.cli_commands``; the heavy modules (torchrl, the runner) are
imported inside the handlers so ``swarmloc --help`` stays fast.
"""

from __future__ import annotations

from swarmloc.bench.cli_commands import register_subcommand
from swarmloc.bench.reproduce_madrl import ReproduceMadrlArgs
from swarmloc.bench.train_cli import TrainMappoArgs


def run_train_mappo(cfg: TrainMappoArgs) -> int:
    """``swarmloc train mappo``: train, write the weights and their provenance record."""
    from swarmloc.bench.train_cli import train_mappo

    try:
        train_mappo(cfg)
    except (ValueError, KeyError) as err:
        print(f"error: {err}")
        return 2
    return 0


def run_reproduce_madrl(cfg: ReproduceMadrlArgs) -> int:
    """``swarmloc reproduce madrl``: write the report and print it."""
    from swarmloc.bench.reproduce_madrl import reproduce_madrl

    try:
        path = reproduce_madrl(cfg.out, cfg.seeds, cfg.traces, cfg.weights, cfg.accuracy_only_weights)
    except (ValueError, FileNotFoundError) as err:
        print(f"error: {err}")
        return 2
    print(path.read_text())
    return 0


register_subcommand("train", "mappo", TrainMappoArgs, run_train_mappo,
                    "Train MAPPO link trust on a task mixture (torchrl; training seeds only).")
register_subcommand("reproduce", "madrl", ReproduceMadrlArgs, run_reproduce_madrl,
                    "madrl Experiments 1, 3-7 on our tasks + the issue-5 targets.")
