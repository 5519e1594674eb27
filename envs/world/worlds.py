"""Which world a task runs in: simulated (``World``) or replayed from data (``RecordedWorld``).

``make_world(spec, B)`` is the one place that decides; the link-trust core, the adapters
and the bench runner build worlds through it. A task whose trajectory is a
``RecordedFlight`` needs an imported data set that the repository does not ship:
``data_missing(spec)`` says, without raising, whether it is absent and why.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Union

from swarmloc.envs.tasks.specs import TaskSpec
from swarmloc.envs.world.sim import World

if TYPE_CHECKING:
    from swarmloc.envs.recorded.replay import RecordedWorld

#: what ``make_world`` returns; both expose the world interface the core uses
AnyWorld = Union[World, "RecordedWorld"]


def is_recorded(spec: TaskSpec) -> bool:
    """Whether ``spec`` replays a recorded flight (its world needs external data)."""
    return spec.trajectory.kind == "recorded"


def make_world(spec: TaskSpec, batch_size: int, data_dir: str | Path | None = None) -> AnyWorld:
    """The world of ``spec`` for ``batch_size`` episodes.

    Args:
        spec: the task.
        batch_size: B.
        data_dir: for recorded tasks, the folder that contains the data set (default:
            ``$SWARMLOC_DATA``, else ``../shared/data`` beside the checkout); ignored otherwise.

    Returns:
        A ``World`` for simulated tasks, a ``RecordedWorld`` for recorded flights.

    Raises:
        FileNotFoundError: a recorded task's data is missing (the message names the source
            repository, commits, paths and the import command).
    """
    if is_recorded(spec):
        from swarmloc.envs.recorded.replay import RecordedWorld

        return RecordedWorld(spec, batch_size, data_dir=data_dir)
    return World(spec, batch_size)


def data_missing(spec: TaskSpec, data_dir: str | Path | None = None) -> str | None:
    """Why ``spec`` cannot run here, or None if it can (simulated tasks always can).

    Args:
        spec: the task.
        data_dir: as in ``make_world``.

    Returns:
        None, or the message ``make_world`` would raise (where the data comes from and how
        to import it).
    """
    if not is_recorded(spec):
        return None
    from swarmloc.envs.recorded.flights import flight_data_missing

    return flight_data_missing(spec, data_dir)


__all__ = ["AnyWorld", "data_missing", "is_recorded", "make_world"]
