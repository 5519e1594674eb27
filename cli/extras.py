"""Which install extra a command needs when one of its optional modules is missing.

The core install (``pip install swarmloc``) serves the environments and the light commands;
the rest comes with extras (pyproject.toml, ``[project.optional-dependencies]``). A command
that imports a module of a missing extra raises ``ModuleNotFoundError``; the command line
catches it where it dispatches and says which extra to install instead of a traceback::

    error: swarmloc evaluate needs the 'torchrl' extra: pip install 'swarmloc[torchrl]'

This module imports nothing heavy: ``swarmloc --help`` loads it.
"""

from __future__ import annotations

#: the top-level modules that each extra installs (its own packages and those of the extras it includes),
#: smallest first: a module missing outside a command's own extra names the first extra that brings it
EXTRA_MODULES: dict[str, frozenset[str]] = {
    "torchrl": frozenset({"torch", "tensordict", "torchrl"}),
    "leaderboard": frozenset({"sqlalchemy"}),
    "ray": frozenset({"ray"}),
    "bench": frozenset({"filterpy", "vmas", "mpe2"}),
    "postgresql": frozenset({"sqlalchemy", "psycopg"}),
    "train": frozenset({"torch", "tensordict", "torchrl", "tensorboard"}),
    "explain": frozenset({"torch", "tensordict", "torchrl", "captum"}),
    "factorgraph": frozenset({"gtsam"}),
    "tune": frozenset({"optuna"}),
    "all": frozenset({"torch", "tensordict", "torchrl", "tensorboard", "sqlalchemy", "captum", "gtsam", "optuna"}),
}

#: the extra of a command (by its first word) that covers everything it imports in the common case
COMMAND_EXTRA: dict[str, str] = {
    "train": "train",
    "explain": "explain",
    "submit": "leaderboard",
    "leaderboard": "leaderboard",
    "demo": "all",  # the learned methods and the leaderboard
    "bench": "bench",
    "tune": "tune",
}


def missing_module(err: BaseException) -> str | None:
    """The top-level name of the module whose absence caused ``err``, or None.

    Follows ``__cause__`` / ``__context__``, so an ``ImportError`` re-raised with a message of
    its own (``raise ImportError(...) from err``) still names the missing module.
    """
    seen: set[int] = set()
    current: BaseException | None = err
    while current is not None and id(current) not in seen:
        seen.add(id(current))
        if isinstance(current, ModuleNotFoundError) and current.name:
            return current.name.split(".")[0]
        current = current.__cause__ or current.__context__
    return None


def missing_extra(err: BaseException, command: str = "") -> str | None:
    """The extra to install after ``err``, or None when ``err`` is not a missing optional module.

    Args:
        err: the exception a command raised.
        command: the command as typed after ``swarmloc`` (``"train mappo"``); its extra is
            named when it brings the missing module (``train`` rather than ``torchrl``).

    Returns:
        An extra of :data:`EXTRA_MODULES`, or None.
    """
    module = missing_module(err)
    if module is None:
        return None
    own = COMMAND_EXTRA.get(command.split(" ")[0])
    if own is not None and module in EXTRA_MODULES[own]:
        return own
    return next((extra for extra, modules in EXTRA_MODULES.items() if module in modules), None)


def needs_extra(command: str, extra: str) -> str:
    """The one-line message for a command that needs an extra that is not installed."""
    return f"swarmloc {command} needs the '{extra}' extra: pip install 'swarmloc[{extra}]'"
