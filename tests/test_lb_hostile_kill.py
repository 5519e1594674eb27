"""Hostile submission: a method that signals its parent and every process it can name.

It kills its parent, every other process it sees in ``/proc``, and a sentinel process the
test started on the host (its PID written into the method). In its PID namespace only
its own sandbox exists (bubblewrap's init, which ignores the signal, and itself): the
sentinel, the worker and ``swarmloc submit`` survive, and the run is refused.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import lb_hostile
import pytest

pytestmark = pytest.mark.slow


def test_signals_reach_nothing_outside_the_sandbox(tmp_path: Path) -> None:
    lb_hostile.require_sandbox()
    hostile = lb_hostile.Hostile.create(tmp_path)
    sentinel = subprocess.Popen(["sleep", "300"])
    try:
        entry = hostile.method(f"""
            import signal
            visible = sorted(int(p) for p in os.listdir("/proc") if p.isdigit())
            outcome = []
            for pid in (os.getppid(), {sentinel.pid}):
                try:
                    os.kill(pid, signal.SIGKILL)
                    outcome.append(f"kill {{pid}}: sent")
                except OSError as err:
                    outcome.append(f"kill {{pid}}: {{err.strerror}}")
            for pid in visible:
                if pid not in (1, os.getpid()):
                    os.kill(pid, signal.SIGKILL)
            raise RuntimeError(f"visible pids {{visible}}; " + "; ".join(outcome))
        """)
        done = hostile.submit(entry)
        assert sentinel.poll() is None, "the sentinel on the host was killed"
    finally:
        sentinel.kill()
        sentinel.wait()
    hostile.assert_refused(done, "visible pids [1, 2]", f"kill {sentinel.pid}: No such process")
