"""Which loader turns a ``RecordedFlight`` into a ``Recording``: the one place that dispatches on the data set.

* ``util-twr`` — the UTIL two-way-ranging flight (``util_flight.load_recording``: one range
  channel per anchor, a calibration log's per-anchor bias);
* ``util-tdoa`` — the UTIL TDOA flights (``tdoa_flight.load_tdoa_recording``: one channel
  per anchor pair of the task's ``Sensors.tdoa``, the README's filtering rules).

``RecordedWorld`` (``replay``) replays either: both give a ``Recording`` whose per-channel
arrays have the task's L columns. ``flight_data_missing`` says, without raising, whether a
task's data is absent here and why.
"""

from __future__ import annotations

from pathlib import Path

from swarmloc.envs.tasks.specs import RecordedFlight, TaskSpec
from swarmloc.envs.recorded.util_flight import Recording, load_recording


def _flight(spec: TaskSpec) -> RecordedFlight:
    flight = spec.trajectory
    if not isinstance(flight, RecordedFlight):
        raise ValueError(f"{spec.task_id} is not a recorded flight (trajectory {flight.kind!r})")
    if (flight.dataset == "util-tdoa") != (spec.sensors.tdoa is not None):
        raise ValueError(f"{spec.task_id}: a {flight.dataset} flight needs "
                         f"{'sensors.tdoa pairs' if flight.dataset == 'util-tdoa' else 'anchor ranges, not TDOA'}")
    return flight


def dataset_folder(spec: TaskSpec, data_dir: str | Path | None = None) -> Path:
    """The imported data set folder of a recorded task (``.../util-twr`` or ``.../util-tdoa``).

    Raises:
        FileNotFoundError: the folder is missing (the message says where the data comes from).
    """
    if _flight(spec).dataset == "util-tdoa":
        from swarmloc.envs.recorded.tdoa_import import find_tdoa_data

        return find_tdoa_data(data_dir)
    from swarmloc.envs.recorded.util_import import find_util_data

    return find_util_data(data_dir)


def load_flight(spec: TaskSpec, data_dir: str | Path | None = None) -> tuple[Path, Recording]:
    """The data set folder and the ``Recording`` of a recorded task, on its filter steps.

    Raises:
        FileNotFoundError: the data is missing; ValueError: the window does not fit the log.
    """
    flight = _flight(spec)
    folder = dataset_folder(spec, data_dir)
    if flight.dataset == "util-tdoa":
        from swarmloc.envs.recorded.tdoa_flight import load_tdoa_recording

        tdoa = spec.sensors.tdoa
        return folder, load_tdoa_recording(folder, flight.log, float(flight.start), spec.n_steps, float(spec.dt),
                                           flight.anchors, tuple(tdoa.pairs), float(tdoa.sigma))
    return folder, load_recording(folder, flight.log, float(flight.start), spec.n_steps, float(spec.dt),
                                  flight.calibration, flight.anchors)


def flight_data_missing(spec: TaskSpec, data_dir: str | Path | None = None) -> str | None:
    """Why a recorded task cannot run here (None: its folder, logs and anchor file are all present).

    The message names where the data comes from and the command that imports it.
    """
    flight = _flight(spec)
    if flight.dataset == "util-tdoa":
        from swarmloc.envs.recorded.tdoa_import import IMPORT_COMMAND
        from swarmloc.envs.recorded.tdoa_import import TDOA_SOURCE as SOURCE
        what = "UTIL TDOA flight"
    else:
        from swarmloc.envs.recorded.util_import import IMPORT_COMMAND
        from swarmloc.envs.recorded.util_import import UTIL_SOURCE as SOURCE
        what = "UTIL TWR log"
    try:
        folder = dataset_folder(spec, data_dir)
    except FileNotFoundError as exc:
        return str(exc)
    for log in (flight.log, flight.calibration):
        if log is not None and not (folder / log).is_dir():
            return (f"{what} {log!r} is missing from {folder}.\nThe data comes from {SOURCE}\n"
                    f"Import it with `{IMPORT_COMMAND}` using DIR = {folder}.")
    if not (folder / flight.anchors).is_file():
        how = f"Import it with `{IMPORT_COMMAND}` using DIR = {folder}."
        if flight.dataset == "util-twr" and flight.anchors != "anchors.csv":
            how = (f"It is the session's survey in the Vicon frame: the anchors_c0607.csv that `swarmloc data "
                   f"import-util-tdoa RAW_LOG --survey anchor_0607.npz --constellation c0607 ...` writes, "
                   f"copied to {folder / flight.anchors}.")
        return f"anchor file {flight.anchors!r} is missing from {folder}.\nThe data comes from {SOURCE}\n{how}"
    return None


__all__ = ["dataset_folder", "flight_data_missing", "load_flight"]
