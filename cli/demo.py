"""``swarmloc demo``: the main job — the shipped methods on the quick suite (``quick-v2``), then the leaderboard."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

#: the demo's default comparison: the classical link-trust baselines (one-step gates,
#: sequential detection, integrity monitoring), the oracle, the paper's learned MAPPO trust
#: and one estimator per family that runs on every task (``mappo-set-gru``, about 2× mappo's
#: cost, and the ``non-cooperative`` probe are on the leaderboard and one flag away),
#: so that the main job stays short on a 2-core machine (the target is five minutes; measured
#: 4 min 30 s by `make demo` with a populated leaderboard store, warm numba cache: quick-v1 99 s
#: + 41 s of plots, real-v1 95 s + 20 s, the leaderboard ≈ 15 s; with ``non-cooperative`` too,
#: 4 min 58 s; `pf` is a third of quick-v1's CPU time; quick-v2, benchmark v2's 9 headline tasks: 23 s
#: of evaluation and 34 s in all with the plots). The task-specific estimators (IMM,
#: federated, CI-EKF, the other PFs) are on the leaderboard and one flag away.
DEMO_METHODS = ("uniform", "fixed", "huber", "chi2-gate", "chi2-soft", "federated-coef", "cusum", "raim", "random",
                "mappo", "dead-reckoning", "pf", "oracle")


@dataclass
class Options:
    """Every shipped method on the quick suite: comparison table and plots, then the leaderboard."""

    out: Path = Path("swarmloc-demo")
    """Output folder (results/, plots/, summary.md; the real flights' in real-v1/; the leaderboard site in leaderboard/)."""
    suite: str = "quick-v2"
    """Suite to run: `quick-v2` (benchmark v2's headline tasks, one board per track), `quick-v1` (benchmark v1,
    deprecated), `quick` (the frozen v0 tasks)."""
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
    """Then load the shipped results (standard-v1, then the frozen standard-v0) into the store and show the leaderboard."""
    db: str | None = None
    """Leaderboard store URL (default: $SWARMLOC_DB or a SQLite file in the user data folder)."""


def run(opts: Options) -> int:
    """Run the demo."""
    from swarmloc.agents.registry import method_names
    from swarmloc.bench.evaluation.backends import check_backend
    from swarmloc.bench.evaluation.suites import get_suite
    from swarmloc.bench.reports.demo import run_demo

    if opts.leaderboard:
        # the CLI is every room's front door: only its handlers reach the leaderboard. Imported
        # first: without the store's extra the demo stops here, not after minutes of episodes
        from swarmloc.leaderboard.store.shipped import show_leaderboard

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
    if opts.suite in ("quick", "quick-v1", "quick-v2"):  # the real flights join wherever their data is imported
        run_real_flight_demo(methods, opts.out / REAL_SUITE, workers=opts.workers, plots=opts.plots, **where)
    if opts.leaderboard:
        show_leaderboard(opts.out, opts.db)
    return 0


#: the real-flight suite the demo adds to the quick suite where its data is imported
REAL_SUITE = "real-v1"


def run_real_flight_demo(methods: list[str], out: Path, workers: int, plots: bool, backend: str | None = None,
                         address: str | None = None, suite_name: str = REAL_SUITE) -> bool:
    """The demo on the real-flight suite (``real-v1``) if its data is here; otherwise say why and where it comes from.

    Returns:
        Whether it ran.
    """
    from rich.console import Console
    from rich.markup import escape

    from swarmloc.bench.evaluation.suites import Suite, get_suite, missing_data
    from swarmloc.bench.reports.demo import run_demo

    suite = get_suite(suite_name)
    missing = missing_data(suite)
    if missing:
        lines = next(iter(missing.values())).splitlines()
        why, source = lines[0], next((ln for ln in lines if ln.startswith("The data comes from")), "")
        Console().print(f"[yellow]skipping suite {suite_name} (real UTIL flights, {len(missing)} of "
                        f"{len(suite.tasks)} tasks without data):[/yellow] {escape(why)} {escape(source)} Import "
                        "them with `swarmloc data import-util` and `swarmloc data import-util-tdoa` (see "
                        "docs/real-flights.md).")
        return False
    # every seed of a recorded flight replays the same recording (the seed moves only the initial
    # prior), so the demo runs one seed per flight; `swarmloc evaluate --suite real-v1` runs all four
    first = tuple((task, suite.seeds(task)[0]) for task in suite.tasks)
    one_seed = Suite(f"{suite.name}-first-seed", suite.version, first, f"{suite.name}, the first seed of each flight")
    run_demo(methods, one_seed, out, workers=workers, plots=plots, backend=backend, address=address)
    return True
