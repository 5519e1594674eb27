"""The bench room's ``swarmloc`` subcommands (imported by ``swarmloc.bench.cli.main`` by convention).

Command *groups* such as ``swarmloc train <what>`` and ``swarmloc reproduce <paper>``
collect subcommands from several modules: :func:`register_subcommand` adds one member to
a group and re-registers the group as a nested tyro union that dispatches on the parsed
config's type. Registered here:

* ``swarmloc train pfnn`` — fit the PF-NN network offline (``bench/train_pfnn.py``);
* ``swarmloc reproduce pfnn`` — pf-nn Tables 4 and 5 (``bench/reproduce_pfnn.py``);
* ``swarmloc data import-util`` — import a UTIL flight log (``bench/data_cli.py``).

Heavy modules are imported inside the handlers, so ``swarmloc --help`` stays fast.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Union

import tyro

from swarmloc.bench.cli import COMMANDS, register_command

#: group → subcommand name → (config type, handler)
GROUPS: dict[str, dict[str, tuple[type, Callable[[Any], int | None]]]] = {}
#: group → subcommand name → its one line of help
_MEMBER_HELP: dict[str, dict[str, str]] = {}
_GROUP_HELP = {"train": "Train a method (training seeds only).",
               "reproduce": "Reproduce a paper's tables with our implementations.",
               "data": "Import external data sets (e.g. the UTIL flight logs)."}


def register_subcommand(group: str, name: str, config: type, handler: Callable[[Any], int | None],
                        help: str = "") -> None:
    """Add ``swarmloc <group> <name>``; the group is (re-)registered as a nested command.

    Args:
        group: the group command (``train``, ``reproduce`` …).
        name: the member's name.
        config: its dataclass type.
        handler: called with a parsed ``config``; returns the exit status (None = 0).
        help: one line of help for the member (default: the config's docstring).
    """
    members = GROUPS.setdefault(group, {})
    members[name] = (config, handler)
    _MEMBER_HELP.setdefault(group, {})[name] = help
    options = tuple(Annotated[cls, tyro.conf.subcommand(n, description=_MEMBER_HELP[group][n] or None)]
                    for n, (cls, _) in members.items())
    # a suppressed None keeps a one-member union a union (a subcommand level, not flattened)
    nested = Annotated[Union[options + (Annotated[None, tyro.conf.Suppress],)],  # type: ignore[valid-type]
                       tyro.conf.arg(name="")]

    def dispatch(cfg: Any) -> int | None:
        for cls, fn in members.values():
            if isinstance(cfg, cls):
                return fn(cfg)
        raise RuntimeError(f"no {group} subcommand handles {type(cfg).__name__}")

    COMMANDS.pop(group, None)  # the group's previous union (fewer members)
    register_command(group, nested, dispatch, _GROUP_HELP.get(group, ""))


# --------------------------------------------------------------------------- pf-nn


def _train_pfnn_args() -> type:
    from swarmloc.bench.train_pfnn import TrainPfnnArgs

    return TrainPfnnArgs


def run_train_pfnn(cfg: Any) -> int:
    """``swarmloc train pfnn``: fit and write the weights (+ provenance)."""
    from swarmloc.bench.train_pfnn import train_pfnn

    try:
        train_pfnn(cfg)
    except ValueError as err:
        print(f"error: {err}")
        return 2
    return 0


@dataclass
class ReproducePfnnArgs:
    """pf-nn Tables 4 (accuracy) and 5 (time per step) on Indoor-v0, beside the paper's numbers."""

    out: Path = Path("pfnn.md")
    """Markdown file to write (a folder: <out>/pfnn.md); raw numbers go beside it as .json."""
    seeds: int = 32
    """Indoor-v0 test seeds (1_000_000 …)."""
    duration: float | None = None
    """Episode length [s] (default: the task's 100 s)."""
    timing_steps: int = 300
    """Steps of the Table 5 timing episode."""
    oracle: bool = True
    """Also run the privileged online-trained PF-NN (shown apart)."""


def run_reproduce_pfnn(cfg: ReproducePfnnArgs) -> int:
    """``swarmloc reproduce pfnn``: write the report and print it."""
    from swarmloc.bench.reproduce_pfnn import reproduce_pfnn

    try:
        path = reproduce_pfnn(cfg.out, cfg.seeds, cfg.duration, cfg.timing_steps, cfg.oracle)
    except (ValueError, FileNotFoundError) as err:
        print(f"error: {err}")
        return 2
    print(path.read_text())
    return 0


register_subcommand("train", "pfnn", _train_pfnn_args(), run_train_pfnn,
                    "Fit the PF-NN weight-correction network offline on training seeds.")
register_subcommand("reproduce", "pfnn", ReproducePfnnArgs, run_reproduce_pfnn,
                    "pf-nn Tables 4 and 5 on Indoor-v0.")

# ``swarmloc data import-util`` (bench/data_cli.py) registers itself into the ``data`` group
from swarmloc.bench import data_cli  # noqa: E402,F401
# ``swarmloc train mappo`` and ``swarmloc reproduce madrl`` (bench/mappo_cli.py)
from swarmloc.bench import mappo_cli  # noqa: E402,F401
# ``swarmloc reproduce immarkf | federated | dtvirm`` (bench/papers_cli.py)
from swarmloc.bench import papers_cli  # noqa: E402,F401
