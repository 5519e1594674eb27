"""Hostile submission: a method that sleeps forever (and ignores SIGTERM).

The wall-time limit kills both sandboxes with SIGKILL: refused within the limit (plus
start-up), nothing left running.
"""

from __future__ import annotations

from pathlib import Path

import lb_hostile
import pytest

pytestmark = pytest.mark.slow


def test_sleeping_forever_is_killed_at_the_time_limit(tmp_path: Path) -> None:
    lb_hostile.require_sandbox()
    hostile = lb_hostile.Hostile.create(tmp_path)
    entry = hostile.method("""
        import signal, time
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        time.sleep(10**6)
    """)
    done = hostile.submit(entry, "--time-limit-s", "8")
    hostile.assert_refused(done, "exceeded the wall-time limit of 8 s while re-running 1 episode(s); it was killed")
    assert done.seconds < 8 + 15, f"took {done.seconds:.0f} s"
