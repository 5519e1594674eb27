"""Per-step traces of evaluated episodes (for plots): the ``Trace`` record and its file.

The runner keeps the trace of the first seed of every task; ``swarmloc evaluate`` writes
them beside the results file as ``<stem>.traces.npz`` (written atomically), and
``swarmloc plot`` reads them back.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from swarmloc.bench.common.files import atomic_path
from swarmloc.bench.scoring import metrics as M
@dataclass
class Trace:
    """Per-step record of one episode, for plots (the first seed of each task).

    Attributes:
        method, task, seed: what ran.
        times: ``(T,)`` update times [s].
        estimate, truth: ``(T, N, 3)`` positions [m].
        applied: ``(T, N, L)`` applied trust, or None (estimator without weights).
        valid, label: ``(T, N, L)`` bool.
        kind: ``(N, L)`` channel kinds.
        scored: ``(N,)`` bool, scored UAVs.
        fault_window: ``(2,)`` the task's fault window (NaN if none).
    """

    method: str
    task: str
    seed: int
    times: np.ndarray
    estimate: np.ndarray
    truth: np.ndarray
    applied: np.ndarray | None
    valid: np.ndarray
    label: np.ndarray
    kind: np.ndarray
    scored: np.ndarray
    fault_window: np.ndarray

    _ARRAYS = ("times", "estimate", "truth", "applied", "valid", "label", "kind", "scored", "fault_window")

    @property
    def errors(self) -> np.ndarray:
        """``(T, N)`` position errors [m]."""
        return M.position_errors(self.estimate, self.truth)

    def to_arrays(self) -> dict[str, np.ndarray]:
        """Flat ``{"<task>|<field>": array}`` for ``np.savez``."""
        out = {f"{self.task}|{name}": getattr(self, name) for name in self._ARRAYS if getattr(self, name) is not None}
        out[f"{self.task}|meta"] = np.array([self.method, str(self.seed)])
        return out

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, np.ndarray]) -> list["Trace"]:
        """Inverse of :meth:`to_arrays` over every task in ``arrays``."""
        tasks = sorted({key.split("|", 1)[0] for key in arrays})
        traces = []
        for task in tasks:
            meta = arrays[f"{task}|meta"]
            fields = {name: arrays.get(f"{task}|{name}") for name in cls._ARRAYS}
            traces.append(cls(method=str(meta[0]), task=task, seed=int(meta[1]), **fields))
        return traces


def traces_path(results_path: str | os.PathLike[str]) -> Path:
    """Where the traces of a results file live: ``<results stem>.traces.npz`` beside it."""
    path = Path(results_path)
    return path.with_name(f"{path.stem}.traces.npz")


def write_traces(path: str | os.PathLike[str], traces: Sequence[Trace]) -> Path:
    """Write traces atomically (``swarmloc.bench.common.files``)."""
    target = Path(path)
    arrays: dict[str, np.ndarray] = {}
    for tr in traces:
        arrays.update(tr.to_arrays())
    with atomic_path(target, suffix=".npz") as tmp:
        np.savez_compressed(tmp, **arrays)
    return target


def read_traces(path: str | os.PathLike[str]) -> list[Trace]:
    """Read traces written by :func:`write_traces`."""
    with np.load(path, allow_pickle=False) as data:
        return Trace.from_arrays({key: data[key] for key in data.files})
