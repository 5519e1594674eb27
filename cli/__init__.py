"""The ``swarmloc`` command line (tyro): one module per command, one table that names them.

**The convention.** A command is a module with two names:

* ``Options`` — a dataclass, one documented field per option (tyro turns the field
  docstrings into ``--help``); its class docstring is the command's help line;
* ``run(opts: Options) -> int`` — the handler; returns the exit status.

A family of small commands may share one module instead: the table names
``module:Class``, where ``Class`` is the ``Options`` dataclass and its method ``run(self)``
the handler (``reproduce.py`` holds the nine ``reproduce`` commands so).

The module imports only what ``Options`` needs (dataclasses, pathlib, tyro and light
parts of the package); everything heavy (numba kernels, torch, the runner) is imported
inside ``run``, so ``swarmloc --help`` and ``swarmloc tasks`` start in well under a second.

A command whose extra is not installed (``ModuleNotFoundError`` of one of its packages) ends
with one line naming the extra to install (``swarmloc.cli.extras``), not a traceback.

``COMMANDS`` below names every command: a leaf maps to its module; a group (``train``,
``reproduce``, ``bench``, ``data``, ``docs``, ``leaderboard``) maps to a table of its members,
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
from typing import Annotated, Any, Callable, NamedTuple, Union

import tyro

from swarmloc.cli.extras import missing_extra, needs_extra

#: a command: the module path of a leaf, or a group's members
CommandTable = dict[str, "str | CommandTable"]

COMMANDS: CommandTable = {
    "tasks": "swarmloc.cli.tasks",
    "methods": "swarmloc.cli.methods",
    "evaluate": "swarmloc.cli.evaluate",
    "plot": "swarmloc.cli.plot",
    "compare": "swarmloc.cli.compare",
    "explain": "swarmloc.cli.explain",
    "demo": "swarmloc.cli.demo",
    "submit": "swarmloc.cli.submit",
    "tune": "swarmloc.cli.tune",
    "leaderboard": {
        "show": "swarmloc.cli.leaderboard_show",
        "html": "swarmloc.cli.leaderboard_html",
        "export": "swarmloc.cli.leaderboard_export",
    },
    "train": {
        "mappo": "swarmloc.cli.train_mappo",
        "mappo-set-gru": "swarmloc.cli.train_set_gru",
        "pfnn": "swarmloc.cli.train_pfnn",
        "supervised-trust": "swarmloc.cli.train_supervised_trust",
    },
    "reproduce": {
        "madrl": "swarmloc.cli.reproduce:Madrl",
        "pfnn": "swarmloc.cli.reproduce:Pfnn",
        "immarkf": "swarmloc.cli.reproduce:Immarkf",
        "federated": "swarmloc.cli.reproduce:Federated",
        "dtvirm": "swarmloc.cli.reproduce:Dtvirm",
        "real": "swarmloc.cli.reproduce:Real",
        "nlos-fit": "swarmloc.cli.reproduce:NlosFit",
        "labels": "swarmloc.cli.reproduce:Labels",
        "calibration": "swarmloc.cli.reproduce:Calibration",
        "peer-update": "swarmloc.cli.reproduce:PeerUpdate",
        "consistency": "swarmloc.cli.reproduce:Consistency",
        "shipped": "swarmloc.cli.reproduce:Shipped",
    },
    "bench": {
        "speed": "swarmloc.cli.bench_speed",
    },
    "data": {
        "import-util": "swarmloc.cli.data_import_util",
        "import-util-tdoa": "swarmloc.cli.data_import_util_tdoa",
    },
    "docs": {
        "readme": "swarmloc.cli.docs_readme",
        "tasks": "swarmloc.cli.docs_tasks",
        "tuning": "swarmloc.cli.docs_tuning",
    },
}

#: one line of help per group
GROUP_HELP = {
    "leaderboard": "Show, render or export the leaderboard.",
    "train": "Train a method (training seeds only).",
    "reproduce": "Reproduce a paper's tables with our implementations.",
    "bench": "Performance benchmarks.",
    "data": "Import external data sets (e.g. the UTIL flight logs).",
    "docs": "Regenerate the generated parts of the documentation.",
}

ENTRY_POINT_GROUP = "swarmloc.commands"


class Command(NamedTuple):
    """A loaded command: its options dataclass and its handler."""

    Options: type
    run: Callable[[Any], int | None]


def load_command(path: str) -> Command:
    """Import a command (``module`` or ``module:Class``) and check that it follows the convention.

    Raises:
        TypeError: the module lacks a dataclass ``Options`` or a callable ``run``, or the class is
            not a dataclass with a ``run`` method.
    """
    module_path, _, class_name = path.partition(":")
    module = importlib.import_module(module_path)
    if class_name:
        options = getattr(module, class_name, None)
        run = getattr(options, "run", None)
        wanted = f"command {path} must be a dataclass with a method `run(self) -> int`"
    else:
        options, run = getattr(module, "Options", None), getattr(module, "run", None)
        wanted = f"command module {path} must define a dataclass `Options` and a function `run(opts) -> int`"
    if not (isinstance(options, type) and hasattr(options, "__dataclass_fields__")) or not callable(run):
        raise TypeError(wanted)
    return Command(options, run)


def command_table() -> CommandTable:
    """``COMMANDS`` plus the commands registered under the ``swarmloc.commands`` entry points."""
    table = dict(COMMANDS)
    for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
        if ep.name in table:
            raise ValueError(f"plugin command {ep.name!r} ({ep.value}) clashes with a built-in command")
        table[ep.name] = ep.value
    return table


def _help_line(command: Command) -> str:
    doc = (command.Options.__doc__ or "").strip()
    return " ".join(doc.split("\n\n")[0].split())


#: a command's handler: the command as typed after ``swarmloc`` and its ``run``
Handler = tuple[str, Callable[[Any], "int | None"]]


def _parser_type(table: CommandTable, handlers: dict[type, Handler], group: bool, prefix: str = "") -> Any:
    """The tyro union of a command table; fills ``handlers`` (Options class → command, run)."""
    options = []
    for name, entry in table.items():
        if isinstance(entry, str):
            command = load_command(entry)
            handlers[command.Options] = (f"{prefix}{name}", command.run)
            options.append(Annotated[command.Options, tyro.conf.subcommand(name, description=_help_line(command))])
        else:
            members = _parser_type(entry, handlers, group=True, prefix=f"{prefix}{name} ")
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
        The exit status: 2 after ``error: swarmloc <command> needs the '<extra>' extra: …``
        when the command imports a package of an extra that is not installed.
    """
    handlers: dict[type, Handler] = {}
    parser = _parser_type(command_table(), handlers, group=False)
    parsed = tyro.cli(parser, args=argv, prog="swarmloc",
                      description="swarmloc: benchmark for learned cooperative localization of UAV swarms.")
    handler = handlers.get(type(parsed))
    if handler is None:
        raise RuntimeError(f"no command handles {type(parsed).__name__}")
    command, run = handler
    try:
        return int(run(parsed) or 0)
    except ImportError as err:
        extra = missing_extra(err, command)
        if extra is None:
            raise
        print(f"error: {needs_extra(command, extra)}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
