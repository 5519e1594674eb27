"""Hostile submission: a fork bomb in ``reset``.

Every process forks forever and ignores failures. The sandbox's process limit
(``--max-processes``) caps the bomb, the wall-time limit ends the run, and the PID
namespace takes every forked process down with it: nothing is left, and the host's
process table never holds more than the limit.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

import lb_hostile
import pytest

pytestmark = pytest.mark.slow

MAX_PROCESSES = 64


def test_fork_bomb_is_capped_and_reaped(tmp_path: Path) -> None:
    lb_hostile.require_sandbox()
    hostile = lb_hostile.Hostile.create(tmp_path)
    entry = hostile.method("""
        import time
        while True:
            try:
                os.fork()
            except OSError:
                time.sleep(0.01)
    """)
    counts: list[int] = []
    stop = threading.Event()

    def watch() -> None:  # the bomb's processes as the host sees them, while it runs
        while not stop.is_set():
            counts.append(len(lb_hostile.processes_marked(hostile.marker)))
            time.sleep(0.05)

    watcher = threading.Thread(target=watch)
    watcher.start()
    try:
        done = hostile.submit(entry, "--time-limit-s", "8", "--max-processes", str(MAX_PROCESSES))
    finally:
        stop.set()
        watcher.join()
    hostile.assert_refused(done, "exceeded the wall-time limit of 8 s")
    assert done.seconds < 8 + 15, f"took {done.seconds:.0f} s"
    assert 10 < max(counts) <= MAX_PROCESSES, f"the bomb reached {max(counts)} processes"
