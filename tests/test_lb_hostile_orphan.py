"""Hostile submission: a method that leaves processes behind to outlive verification.

It starts a detached daemon (double fork, new session) and an exec'd ``python -c sleep``
with the test's marker in its command line, then returns normally so that the run goes
on (and is refused for its forged metrics). When the run ends the method's PID namespace
goes, and every process in it: none is left on the host.
"""

from __future__ import annotations

from pathlib import Path

import lb_hostile
import pytest

pytestmark = pytest.mark.slow


def test_no_process_outlives_verification(tmp_path: Path) -> None:
    lb_hostile.require_sandbox()
    hostile = lb_hostile.Hostile.create(tmp_path)
    entry = hostile.method(f"""
        import subprocess, time
        if os.fork() == 0:
            os.setsid()
            if os.fork() == 0:
                time.sleep(600)
            os._exit(0)
        subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)", "{hostile.marker}"],
                         start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    """)
    done = hostile.submit(entry)
    hostile.assert_refused(done, "compared with exact equality", "differ")
