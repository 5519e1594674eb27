"""The ``swarmloc`` command line (tyro): one module per command, one table that names them.

**The convention.** A command is a module with two names:

* ``Options`` — a dataclass, one documented field per option (tyro turns the field
  docstrings into ``--help``); its class docstring is the command's help line;
* ``run(opts: Options) -> int`` — the handler; returns the exit status.

The module imports only what ``Options`` needs (dataclasses, pathlib, tyro and light
parts of the package); everything heavy (numba kernels, torch, the runner) is imported
inside ``run``, so ``swarmloc --help`` and ``swarmloc tasks`` start in well under a second.

``COMMANDS`` below names every command: a leaf maps to its module; a group (``train``,
``reproduce``, ``bench``, ``data``, ``leaderboard``) maps to a table of its members,
registered exactly the same way. Commands from other packages plug in through the
``swarmloc.commands`` entry-point group (``name = "package.module"``, the module following
the same convention)::

    [project.entry-points."swarmloc.commands"]
    my-tool = "my_package.swarmloc_command"
"""

from __future__ import annotations

import importlib
import sys
from importlib import metadata
from pathlib import Path
from types import ModuleType
from typing import Annotated, Any, Callable, Union

import tyro

#: a command: the module path of a leaf, or a group's members
CommandTable = dict[str, "str | CommandTable"]

COMMANDS: CommandTable = {
    "tasks": "swarmloc.bench.cli.tasks",
    "methods": "swarmloc.bench.cli.methods",
    "evaluate": "swarmloc.bench.cli.evaluate",
    "plot": "swarmloc.bench.cli.plot",
    "compare": "swarmloc.bench.cli.compare",
    "explain": "swarmloc.bench.cli.explain",
    "demo": "swarmloc.bench.cli.demo",
    "submit": "swarmloc.bench.cli.submit",
    "leaderboard": {
        "show": "swarmloc.bench.cli.leaderboard_show",
        "html": "swarmloc.bench.cli.leaderboard_html",
        "export": "swarmloc.bench.cli.leaderboard_export",
    },
    "train": {
        "mappo": "swarmloc.bench.cli.train_mappo",
        "mappo-set-gru": "swarmloc.bench.cli.train_set_gru",
        "pfnn": "swarmloc.bench.cli.train_pfnn",
    },
    "reproduce": {
        "madrl": "swarmloc.bench.cli.reproduce_madrl",
        "pfnn": "swarmloc.bench.cli.reproduce_pfnn",
        "immarkf": "swarmloc.bench.cli.reproduce_immarkf",
        "federated": "swarmloc.bench.cli.reproduce_federated",
        "dtvirm": "swarmloc.bench.cli.reproduce_dtvirm",
        "real": "swarmloc.bench.cli.reproduce_real",
        "labels": "swarmloc.bench.cli.reproduce_labels",
        "calibration": "swarmloc.bench.cli.reproduce_calibration",
        "peer-update": "swarmloc.bench.cli.reproduce_peer_update",
    },
    "bench": {
        "speed": "swarmloc.bench.cli.bench_speed",
    },
    "data": {
        "import-util": "swarmloc.bench.cli.data_import_util",
        "import-util-tdoa": "swarmloc.bench.cli.data_import_util_tdoa",
    },
}

#: one line of help per group
GROUP_HELP = {
    "leaderboard": "Show, render or export the leaderboard.",
    "train": "Train a method (training seeds only).",
    "reproduce": "Reproduce a paper's tables with our implementations.",
    "bench": "Performance benchmarks.",
    "data": "Import external data sets (e.g. the UTIL flight logs).",
}

ENTRY_POINT_GROUP = "swarmloc.commands"


def print_report(write: Callable[[], Path]) -> int:
    """Run a ``reproduce`` command: write its report, then print it.

    Args:
        write: writes the report and returns its path.

    Returns:
        0, or 2 after printing ``error: …`` when an option names something that does not
        exist or is not allowed (``ValueError``, ``KeyError``, ``FileNotFoundError``).
    """
    try:
        path = write()
    except (ValueError, KeyError, FileNotFoundError) as err:
        print(f"error: {err.args[0] if isinstance(err, KeyError) and err.args else err}")
        return 2
    print(path.read_text(encoding="utf-8"))
    return 0


def load_command(module_path: str) -> ModuleType:
    """Import a command module and check that it follows the convention.

    Raises:
        TypeError: the module lacks a dataclass ``Options`` or a callable ``run``.
    """
    module = importlib.import_module(module_path)
    options, run = getattr(module, "Options", None), getattr(module, "run", None)
    if not (isinstance(options, type) and hasattr(options, "__dataclass_fields__")) or not callable(run):
        raise TypeError(f"command module {module_path} must define a dataclass `Options` and a function "
                        f"`run(opts) -> int`")
    return module


def command_table() -> CommandTable:
    """``COMMANDS`` plus the commands registered under the ``swarmloc.commands`` entry points."""
    table = dict(COMMANDS)
    for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
        if ep.name in table:
            raise ValueError(f"plugin command {ep.name!r} ({ep.value}) clashes with a built-in command")
        table[ep.name] = ep.value
    return table


def _help_line(module: ModuleType) -> str:
    doc = (module.Options.__doc__ or "").strip()
    return " ".join(doc.split("\n\n")[0].split())


def _parser_type(table: CommandTable, handlers: dict[type, Callable[[Any], int | None]], group: bool) -> Any:
    """The tyro union of a command table; fills ``handlers`` (Options class → run)."""
    options = []
    for name, entry in table.items():
        if isinstance(entry, str):
            module = load_command(entry)
            handlers[module.Options] = module.run
            options.append(Annotated[module.Options, tyro.conf.subcommand(name, description=_help_line(module))])
        else:
            members = _parser_type(entry, handlers, group=True)
            options.append(Annotated[members, tyro.conf.subcommand(name, description=GROUP_HELP.get(name))])
    if group:
        # a suppressed None keeps a one-member group a subcommand level (tyro flattens 1-unions)
        options.append(Annotated[None, tyro.conf.Suppress])
        return Annotated[Union[tuple(options)], tyro.conf.arg(name="")]  # type: ignore[valid-type]
    return Union[tuple(options)]  # type: ignore[valid-type]


def main(argv: list[str] | None = None) -> int:
    """``swarmloc`` entry point.

    Args:
        argv: arguments (default: ``sys.argv[1:]``).

    Returns:
        The exit status.
    """
    handlers: dict[type, Callable[[Any], int | None]] = {}
    parser = _parser_type(command_table(), handlers, group=False)
    parsed = tyro.cli(parser, args=argv, prog="swarmloc",
                      description="swarmloc: benchmark for learned cooperative localization of UAV swarms.")
    run = handlers.get(type(parsed))
    if run is None:
        raise RuntimeError(f"no command handles {type(parsed).__name__}")
    return int(run(parsed) or 0)


if __name__ == "__main__":
    sys.exit(main())
