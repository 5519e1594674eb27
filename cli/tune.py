"""``swarmloc tune <method>``: a classical method's parameters searched on dev-v2, one budget for all (docs/tuning.md)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import tyro

from swarmloc.bench.tuning import BUDGET_SEED, BUDGET_TRIALS


@dataclass
class Options:
    """Tune a classical Track A method on dev-v2 (Optuna TPE; objective: the mean of the two tracks' score-v2 S)."""

    method: Annotated[str, tyro.conf.Positional, tyro.conf.arg(metavar="METHOD")]
    """A tunable method: huber, chi2-gate, chi2-soft, cusum, raim, cusum-chi2."""
    trials: int = BUDGET_TRIALS
    """Optuna trials, the registered default's included (the shipped records all use the default)."""
    seed: int = BUDGET_SEED
    """Seed of the TPE sampler (the same seed draws the same values)."""
    workers: int = 1
    """Worker processes of each trial's evaluation (the numbers do not depend on it)."""
    out: Path | None = None
    """Where to write the record (default: the shipped one, agents/weights/tuned/<method>.json)."""


def run(opts: Options) -> int:
    """Run the search, print a line per trial, and write the record."""
    from rich.console import Console

    from swarmloc.agents.trust.tuned import check_tunable, record_path
    from swarmloc.bench.tuning.search import check_budget, tune, write_record

    console = Console(stderr=True, soft_wrap=True)  # a trial per line, also in a log file
    try:
        check_tunable(opts.method)
        check_budget(opts.trials, opts.seed)
        if opts.workers < 1:
            raise ValueError(f"workers must be >= 1, got {opts.workers}")
    except ValueError as err:
        console.print(f"[red]error:[/red] {err}")
        return 2

    def show(trial: dict) -> None:
        values = ", ".join(f"{k} {v:.4g}" for k, v in trial["params"].items())
        tracks = "  ".join(f"{t} {s:+.3f}" for t, s in trial["S"].items())
        console.print(f"  trial {trial['number']:3d}  {values:48s}  S: {tracks}  mean {trial['objective']:+.4f}"
                      f"  ({trial['seconds']:.1f} s)")

    console.print(f"tuning {opts.method}: {opts.trials} trials, TPE seed {opts.seed}, on dev-v2")
    record = tune(opts.method, opts.trials, opts.seed, workers=opts.workers, on_trial=show)
    out = write_record(record, opts.out if opts.out is not None else record_path(opts.method))
    chosen, default = record["chosen"], record["default"]
    console.print(f"chosen: trial {chosen['trial']}, {chosen['params']}: mean S {chosen['objective']:+.4f} "
                  f"(the default's {default['objective']:+.4f}); {record['wall_seconds']:.0f} s; wrote {out}")
    return 0
