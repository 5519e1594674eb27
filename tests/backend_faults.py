"""Methods that fail on purpose, for the execution-backend fault tests (``test_backends.py``).

Loaded as ``/abs/path/tests/backend_faults.py:<factory>`` so that every worker — spawned
process or Ray worker — imports this file from the same place. Both wrap ``chi2-gate``,
so their metrics, when they run, are chi2-gate's.

* ``dies_once`` — the first process to reset it kills itself (SIGKILL), once per marker
  folder (``$SWARMLOC_FAULT_DIR``); the retried job then runs normally.
* ``raises_on_three_uavs`` — raises in ``reset`` on tasks with three UAVs
  (``GradualFault-v0``), runs elsewhere.
* ``hangs`` — appends its process ID to ``$SWARMLOC_FAULT_DIR/hanging`` in ``reset``,
  then sleeps for ten minutes (a job that is surely outstanding at Ctrl-C).
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path
from typing import Any

from swarmloc.agents.registry import load_method

FAULT_DIR_ENV = "SWARMLOC_FAULT_DIR"
MARKER = "died"
HANGING = "hanging"


class _Wrapped:
    """chi2-gate's policy behind a hook run at every reset."""

    privileged = False
    deterministic = True

    def __init__(self, on_reset) -> None:
        self._inner = load_method("chi2-gate").method
        self._on_reset = on_reset
        self.flops_per_channel = getattr(self._inner, "flops_per_channel", 0.0)

    def reset(self, batch_size: int, layout: Any, keys: Any) -> None:
        self._on_reset(layout)
        self._inner.reset(batch_size, layout, keys)

    def act(self, inp: Any) -> Any:
        return self._inner.act(inp)


def _die_once(layout: Any) -> None:
    marker = Path(os.environ[FAULT_DIR_ENV]) / MARKER
    try:
        fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    except FileExistsError:
        return
    os.write(fd, str(os.getpid()).encode())
    os.close(fd)
    os.kill(os.getpid(), signal.SIGKILL)


def _raise_on_three(layout: Any) -> None:
    if layout.kind.shape[0] == 3:
        raise RuntimeError("this method breaks on three UAVs")


def _hang(layout: Any) -> None:
    with open(Path(os.environ[FAULT_DIR_ENV]) / HANGING, "a") as log:
        log.write(f"{os.getpid()}\n")
    time.sleep(600)


def dies_once() -> _Wrapped:
    """chi2-gate whose first reset kills its process."""
    return _Wrapped(_die_once)


def raises_on_three_uavs() -> _Wrapped:
    """chi2-gate that raises on three-UAV tasks."""
    return _Wrapped(_raise_on_three)


def hangs() -> _Wrapped:
    """chi2-gate that never gets past its reset."""
    return _Wrapped(_hang)
