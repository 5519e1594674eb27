"""The ``swarmloc`` command line (tyro), with a registry of subcommands.

Built-in: ``tasks``, ``methods``, ``evaluate``, ``plot``, ``demo``; the leaderboard's
``submit`` and ``leaderboard`` are wired in from ``swarmloc.leaderboard.cli_commands``.

**Adding a subcommand** (``train``, ``reproduce``, ``data``, ``bench speed`` …): in your
own module write a dataclass (one documented field per option) and a handler, and
register them::

    # e.g. agents/cli_commands.py
    from dataclasses import dataclass
    from swarmloc.bench.cli import command

    @dataclass
    class Train:
        \"\"\"Train MAPPO link trust.\"\"\"
        steps: int = 1_000_000
        \"\"\"Environment steps.\"\"\"

    @command("train")
    def run_train(cfg: Train) -> int:
        ...
        return 0

``main()`` imports, before parsing, every module named ``swarmloc.<room>.cli_commands``
(rooms ``agents``, ``bench``, ``leaderboard``) and every module listed under the
``swarmloc.commands`` entry-point group, so registering happens by convention — no edit
of this file. A nested command (``bench speed``) is a registered config type that is
itself a union of subcommand dataclasses (see the ``leaderboard`` command below). A
handler returns the exit status (``None`` = 0).
"""

from __future__ import annotations

import importlib
import os
import sys
import time
import typing
from collections.abc import Callable
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Annotated, Any, Union

import tyro

# --------------------------------------------------------------------------- registry


@dataclass(frozen=True)
class Command:
    """A registered subcommand.

    Attributes:
        name: the subcommand (``swarmloc <name>``).
        config: its tyro-parsable type (a dataclass, or a union of them for nested commands).
        handler: called with the parsed config; returns the exit status (None = 0).
        help: one line for ``swarmloc --help`` (default: the config's docstring).
    """

    name: str
    config: Any
    handler: Callable[[Any], int | None]
    help: str = ""


COMMANDS: dict[str, Command] = {}
#: modules imported by ``main`` so that their commands register themselves
PLUGIN_MODULES = ("swarmloc.agents.cli_commands", "swarmloc.bench.cli_commands", "swarmloc.leaderboard.cli_commands")
ENTRY_POINT_GROUP = "swarmloc.commands"


def register_command(name: str, config: Any, handler: Callable[[Any], int | None], help: str = "") -> None:
    """Register ``swarmloc <name>``.

    Args:
        name: subcommand name (lower case, digits and '-').
        config: a dataclass type (or a union of dataclasses for nested subcommands).
        handler: called with the parsed config.
        help: one line of help.

    Raises:
        ValueError: a bad or already registered name.
    """
    if not name or not all(c.islower() or c.isdigit() or c == "-" for c in name):
        raise ValueError(f"command name {name!r} must be non-empty lower-case letters, digits and '-'")
    if name in COMMANDS and COMMANDS[name].handler is not handler:
        raise ValueError(f"command {name!r} is already registered by {COMMANDS[name].handler.__module__}")
    COMMANDS[name] = Command(name, config, handler, help)


def command(name: str, help: str = "") -> Callable[[Callable[[Any], int | None]], Callable[[Any], int | None]]:
    """Decorator form of :func:`register_command`: the config type is the handler's first parameter's annotation."""

    def wrap(handler: Callable[[Any], int | None]) -> Callable[[Any], int | None]:
        hints = typing.get_type_hints(handler, include_extras=True)
        params = [p for p in hints if p != "return"]
        if not params:
            raise TypeError(f"handler {handler.__name__} of command {name!r} needs an annotated config parameter")
        register_command(name, hints[params[0]], handler, help)
        return handler

    return wrap


def _classes(tp: Any) -> list[type]:
    """Every class inside a (possibly Annotated / union) type."""
    origin = typing.get_origin(tp)
    if origin is Annotated:
        return _classes(typing.get_args(tp)[0])
    if origin is Union or (origin is not None and str(origin) == "<class 'types.UnionType'>"):
        return [c for arg in typing.get_args(tp) for c in _classes(arg)]
    import types

    if isinstance(tp, types.UnionType):
        return [c for arg in tp.__args__ for c in _classes(arg)]
    return [tp] if isinstance(tp, type) else []


def _load_plugins() -> None:
    """Import the convention modules and the entry-point plugins (they register commands)."""
    for module in PLUGIN_MODULES:
        try:
            importlib.import_module(module)
        except ModuleNotFoundError as err:
            if err.name != module:  # the module exists but something it imports is missing
                raise
    for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
        importlib.import_module(ep.value.split(":")[0])
    _wire_leaderboard()


def _wire_leaderboard() -> None:
    """``submit`` and ``leaderboard`` from ``swarmloc.leaderboard.cli_commands`` (which does not register itself)."""
    if "submit" in COMMANDS and "leaderboard" in COMMANDS:
        return
    try:
        lb = importlib.import_module("swarmloc.leaderboard.cli_commands")
    except ModuleNotFoundError as err:
        if err.name and err.name.startswith("swarmloc.leaderboard"):
            return
        raise
    if "submit" not in COMMANDS and hasattr(lb, "SubmitCommand"):
        register_command("submit", lb.SubmitCommand, lb.run_submit,
                         "Validate a results file, re-run a sample of its episodes, and store it.")
    if "leaderboard" not in COMMANDS and hasattr(lb, "LeaderboardShow"):
        nested = Annotated[
            Union[
                Annotated[lb.LeaderboardShow, tyro.conf.subcommand("show")],
                Annotated[lb.LeaderboardHtml, tyro.conf.subcommand("html")],
                Annotated[lb.LeaderboardExport, tyro.conf.subcommand("export")],
            ],
            tyro.conf.arg(name=""),
        ]
        register_command("leaderboard", nested, lb.run_leaderboard, "Show, render or export the leaderboard.")


# --------------------------------------------------------------------------- built-in commands


@dataclass
class TasksCommand:
    """List the registered tasks."""


@command("tasks", help="List the registered tasks.")
def run_tasks(cfg: TasksCommand) -> int:
    """Print a table of the task catalogue."""
    from rich.console import Console
    from rich.table import Table

    from swarmloc.envs.tasks import CATALOGUE, get_spec

    table = Table(title="swarmloc tasks")
    table.add_column("ID", no_wrap=True)
    for name in ("UAVs", "channels/UAV", "duration [s]", "dt [s]", "faults", "scored"):
        table.add_column(name)
    for task_id in CATALOGUE:
        s = get_spec(task_id)
        faults = [k for k, v in s.faults.model_dump().items() if v not in (None, (), [], 0.0)]
        table.add_row(task_id, str(s.n_uav), str(s.n_channels), f"{s.duration:g}", f"{s.dt:g}",
                      ", ".join(faults) or "—", "all" if not s.scoring.nodes else str(list(s.scoring.nodes)))
    Console().print(table)
    return 0


@dataclass
class MethodsCommand:
    """List the registered methods."""


@command("methods", help="List the registered methods.")
def run_methods(cfg: MethodsCommand) -> int:
    """Print a table of the method registry."""
    from rich.console import Console
    from rich.table import Table

    from swarmloc.agents.registry import REGISTRY

    table = Table(title="swarmloc methods (any Track A name also works as '<name>+smooth')")
    for name in ("name", "track", "privileged", "deterministic", "summary"):
        table.add_column(name)
    for e in REGISTRY.values():
        table.add_row(e.name, e.track, "yes" if e.privileged else "", "yes" if e.deterministic else "no", e.summary)
    Console().print(table)
    return 0


@dataclass
class EvaluateCommand:
    """Evaluate a method on a suite and write a results file."""

    method: str
    """Registered name (see `swarmloc methods`), `name+smooth`, `package.module:factory` or `path/to/file.py:factory`."""
    out: Path
    """Results file to write (JSON); per-step traces of the first seeds go to `<stem>.traces.npz` beside it."""
    suite: str = "quick"
    """Suite: `quick`, `standard-v0`, `dev` or `real-v0` (real flights; needs the imported data)."""
    tasks: str | None = None
    """Only these tasks of the suite, comma-separated IDs (the `swarmloc/` prefix may be omitted)."""
    workers: int = 1
    """Worker processes (tasks run in parallel)."""
    weights: Path | None = None
    """Weights file handed to the method's factory as `weights=`."""
    progress: bool = True
    """Show a progress bar."""


@command("evaluate", help="Evaluate a method on a suite and write a results file.")
def run_evaluate(cfg: EvaluateCommand) -> int:
    """Run the evaluation and print a one-line summary per task."""
    from rich.console import Console

    from swarmloc.bench.runner import evaluate
    from swarmloc.bench.stats import aggregate_across_tasks
    from swarmloc.bench.suites import get_suite, require_data, restrict_tasks

    console = Console(stderr=True)
    if ":" in cfg.method and os.getcwd() not in sys.path:
        sys.path.insert(0, os.getcwd())  # like `python -m`: modules in the working directory import
    try:
        suite = get_suite(cfg.suite)
        if cfg.tasks:
            suite = restrict_tasks(suite, cfg.tasks)
        require_data(suite)
    except (KeyError, ValueError, FileNotFoundError) as err:
        console.print(f"[red]error:[/red] {err.args[0] if err.args else err}")
        return 2
    if not cfg.out.parent.exists():
        console.print(f"[red]error:[/red] output folder {cfg.out.parent} does not exist")
        return 2
    started = time.perf_counter()
    results = evaluate(cfg.method, suite, cfg.out, workers=cfg.workers,
                       weights=str(cfg.weights) if cfg.weights else None, progress=cfg.progress)
    for task, per_metric in results.aggregates.items():
        rmse = per_metric["rmse"]
        score = per_metric["normalized_score"]
        if rmse is None:
            console.print(f"  {task:34s} [yellow]not run[/yellow]: the method cannot run this task")
            continue
        console.print(f"  {task:34s} RMSE {rmse.mean:8.3f} m   score {'—' if score is None else f'{score.mean:7.3f}'}")
    overall = aggregate_across_tasks(results.episodes, "normalized_score")
    if overall is not None:
        console.print(f"normalized score {overall.mean:.3f} (IQM {overall.iqm:.3f}, 95% CI "
                      f"[{overall.ci_low:.3f}, {overall.ci_high:.3f}])")
    console.print(f"wrote {cfg.out} ({len(results.episodes)} episodes, {time.perf_counter() - started:.1f} s)")
    return 0


@dataclass
class PlotCommand:
    """Plot results files (one per method; methods are compared per task)."""

    results: tyro.conf.Positional[tuple[Path, ...]]
    """Results files written by `swarmloc evaluate`."""
    out: Path = Path("swarmloc-plots")
    """Output folder for the PNGs."""


@command("plot", help="Plot results files (error vs time, error CDF, trust, trajectories).")
def run_plot(cfg: PlotCommand) -> int:
    """Write the PNGs."""
    from rich.console import Console

    from swarmloc.bench.plots import plot_results

    if not cfg.results:
        Console(stderr=True).print("[red]error:[/red] give at least one results file")
        return 2
    written = plot_results(list(cfg.results), cfg.out)
    Console().print(f"wrote {len(written)} plots to {cfg.out}")
    return 0


#: the demo's default comparison: every classical link-trust baseline, the oracle, the
#: learned MAPPO trust and one estimator per family that runs on every task, so that the
#: main job stays within five minutes on a 2-core machine. The task-specific estimators
#: (IMM, federated, CI-EKF, the other PFs) are on the leaderboard and one flag away.
DEMO_METHODS = ("uniform", "fixed", "huber", "chi2-gate", "chi2-soft", "federated-coef", "random",
                "mappo", "dead-reckoning", "pf", "oracle")


@dataclass
class DemoCommand:
    """Evaluate every shipped method on the quick suite (plus real-v0 where its data is imported); print the
    comparison; write plots."""

    out: Path = Path("swarmloc-demo")
    """Output folder (results/, plots/, summary.md; the real flight's in real-v0/)."""
    suite: str = "quick"
    """Suite to run."""
    workers: int = 2
    """Worker processes."""
    methods: tuple[str, ...] = ()
    """Methods to compare (default: DEMO_METHODS; `--methods all` for every registered method)."""
    plots: bool = True
    """Write the plots."""
    leaderboard: bool = True
    """Then load the shipped standard-v0 results into the store and show the leaderboard."""
    db: str | None = None
    """Leaderboard store URL (default: $SWARMLOC_DB or a SQLite file in the user data folder)."""


@command("demo", help="Every shipped method on the quick suite: comparison table and plots.")
def run_demo_command(cfg: DemoCommand) -> int:
    """Run the demo."""
    from swarmloc.agents.registry import method_names
    from swarmloc.bench.demo import run_demo
    from swarmloc.bench.suites import get_suite

    methods = list(cfg.methods) or list(DEMO_METHODS)
    if methods == ["all"]:
        methods = method_names()
    run_demo(methods, get_suite(cfg.suite), cfg.out, workers=cfg.workers, plots=cfg.plots)
    if cfg.suite == "quick":  # the real flight joins the demo wherever its data is imported
        run_real_flight_demo(methods, cfg.out / "real-v0", workers=cfg.workers, plots=cfg.plots)
    if cfg.leaderboard:
        # bench does not depend on leaderboard: reach it the way the submit command is wired
        try:
            shipped = importlib.import_module("swarmloc.leaderboard.shipped")
        except ModuleNotFoundError as err:
            from rich.console import Console

            Console().print(f"[yellow]leaderboard not shown:[/yellow] {err}")
        else:
            shipped.show_leaderboard(cfg.out, cfg.db)
    return 0


def run_real_flight_demo(methods: list[str], out: Path, workers: int, plots: bool) -> bool:
    """The demo on suite ``real-v0`` if its data is here; otherwise print why it is skipped.

    Returns:
        Whether it ran.
    """
    from rich.console import Console

    from swarmloc.bench.demo import run_demo
    from swarmloc.bench.suites import get_suite, missing_data

    suite = get_suite("real-v0")
    missing = missing_data(suite)
    if missing:
        why = next(iter(missing.values())).splitlines()[0]
        Console().print(f"[yellow]skipping suite real-v0 (real UTIL flight):[/yellow] {why} "
                        "Import it with `swarmloc data import-util` (see `swarmloc evaluate --suite real-v0`).")
        return False
    run_demo(methods, suite, out, workers=workers, plots=plots)
    return True


# --------------------------------------------------------------------------- entry point


def build_parser_type() -> Any:
    """The tyro type of the whole CLI: a union of every registered command."""
    _load_plugins()
    options = tuple(
        Annotated[cmd.config, tyro.conf.subcommand(cmd.name, description=cmd.help or None)]
        for cmd in COMMANDS.values()
    )
    return Union[options]  # type: ignore[valid-type]


def main(argv: list[str] | None = None) -> int:
    """``swarmloc`` entry point.

    Args:
        argv: arguments (default: ``sys.argv[1:]``).

    Returns:
        The exit status.
    """
    parsed = tyro.cli(build_parser_type(), args=argv, prog="swarmloc",
                      description="swarmloc: benchmark for learned cooperative localization of UAV swarms.")
    for cmd in COMMANDS.values():
        if any(isinstance(parsed, cls) for cls in _classes(cmd.config)):
            status = cmd.handler(parsed)
            return int(status or 0)
    raise RuntimeError(f"no handler for parsed command {type(parsed).__name__}")


if __name__ == "__main__":
    # run through the package module so that plugins register into the same COMMANDS
    from swarmloc.bench.cli import main as _package_main

    sys.exit(_package_main())
