"""Hostile submission: a fork bomb in ``reset``.

Every process forks forever and ignores failures. The sandbox's process limit
(``--max-processes``) caps the bomb, the wall-time limit ends the run, and the PID
namespace takes every forked process down with it: nothing is left, and the host's
process table never holds more than the limit.
"""

from __future__ import annotations

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
    done = hostile.submit(entry, "--time-limit-s", "12", "--max-processes", str(MAX_PROCESSES))
    hostile.assert_refused(done, "exceeded the wall-time limit of 12 s")
    assert done.seconds < 12 + 15, f"took {done.seconds:.0f} s"
