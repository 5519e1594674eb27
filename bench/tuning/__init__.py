"""Tuning the classical Track A methods on dev-v2: one budget for every method (``swarmloc tune``, docs/tuning.md).

This package's top level stays light (the command line reads the budget at ``--help``);
``search`` imports Optuna and the runner when it runs.
"""

#: Optuna trials per method, the registered default's included (the same for every tunable method)
BUDGET_TRIALS = 80
#: seed of the TPE sampler
BUDGET_SEED = 0
#: the suite the objective is measured on (dev seeds only; never a test seed)
TUNING_SUITE = "dev-v2"
