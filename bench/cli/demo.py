"""``swarmloc demo``: the main job — the shipped methods on the quick suite, then the leaderboard."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

#: the demo's default comparison: every classical link-trust baseline, the oracle, the
#: learned MAPPO trust and one estimator per family that runs on every task, so that the
#: main job stays within five minutes on a 2-core machine. The task-specific estimators
#: (IMM, federated, CI-EKF, the other PFs) are on the leaderboard and one flag away.
DEMO_METHODS = ("uniform", "fixed", "huber", "chi2-gate", "chi2-soft", "federated-coef", "random",
                "mappo", "dead-reckoning", "pf", "oracle")


@dataclass
class Options:
    """Every shipped method on the quick suite: comparison table and plots, then the leaderboard."""

    out: Path = Path("swarmloc-demo")
    """Output folder (results/, plots/, summary.md; the real flight's in real-v0/; the leaderboard site in leaderboard/)."""
    suite: str = "quick"
    """Suite to run."""
    workers: int = 2
    """Worker processes (or the CPUs of a local Ray cluster)."""
    backend: Literal["serial", "process", "ray"] | None = None
    """Where the evaluation jobs run: `serial`, `process` (worker processes here) or `ray` (a Ray cluster).
    Default: serial with `--workers 1`, else process."""
    address: str | None = None
    """With `--backend ray`: the cluster to join, `auto` or `HOST:PORT` (default: $RAY_ADDRESS, else a local
    cluster of `--workers` CPUs)."""
    methods: tuple[str, ...] = ()
    """Methods to compare (default: DEMO_METHODS; `--methods all` for every registered method)."""
    plots: bool = True
    """Write the plots."""
    leaderboard: bool = True
    """Then load the shipped standard-v0 results into the store and show the leaderboard."""
    db: str | None = None
    """Leaderboard store URL (default: $SWARMLOC_DB or a SQLite file in the user data folder)."""


def run(opts: Options) -> int:
    """Run the demo."""
    from swarmloc.agents.registry import method_names
    from swarmloc.bench.evaluation.backends import check_backend
    from swarmloc.bench.evaluation.demo import run_demo
    from swarmloc.bench.evaluation.suites import get_suite

    methods = list(opts.methods) or list(DEMO_METHODS)
    if methods == ["all"]:
        methods = method_names()
    try:
        backend = check_backend(opts.backend, opts.workers, opts.address)
    except ValueError as err:
        print(f"error: {err}")
        return 2
    where = {"backend": backend, "address": opts.address}
    run_demo(methods, get_suite(opts.suite), opts.out, workers=opts.workers, plots=opts.plots, **where)
    if opts.suite == "quick":  # the real flight joins the demo wherever its data is imported
        run_real_flight_demo(methods, opts.out / "real-v0", workers=opts.workers, plots=opts.plots, **where)
    if opts.leaderboard:
        # the CLI is every room's front door: only its handlers reach the leaderboard
        from swarmloc.leaderboard.shipped import show_leaderboard

        show_leaderboard(opts.out, opts.db)
    return 0


def run_real_flight_demo(methods: list[str], out: Path, workers: int, plots: bool, backend: str | None = None,
                         address: str | None = None) -> bool:
    """The demo on suite ``real-v0`` if its data is here; otherwise print why it is skipped.

    Returns:
        Whether it ran.
    """
    from rich.console import Console

    from swarmloc.bench.evaluation.demo import run_demo
    from swarmloc.bench.evaluation.suites import get_suite, missing_data

    suite = get_suite("real-v0")
    missing = missing_data(suite)
    if missing:
        why = next(iter(missing.values())).splitlines()[0]
        Console().print(f"[yellow]skipping suite real-v0 (real UTIL flight):[/yellow] {why} "
                        "Import it with `swarmloc data import-util` (see `swarmloc evaluate --suite real-v0`).")
        return False
    run_demo(methods, suite, out, workers=workers, plots=plots, backend=backend, address=address)
    return True
