"""Hostile submission: a method that monkeypatches the runner, and one that forges the reply.

From ``reset`` the first replaces the runner's ``run_episodes`` and ``evaluate_task``, the
score function and the worker's response writer. It runs in its own sandbox, so that
changes only its own process: the worker computes the metrics from the actions it
returns and finds that the (forged) results file does not match. The second writes a
forged "all reproduced" response to every file descriptor it has: the only one leading
out is its pipe to the worker, which reads the bytes as a malformed reply and refuses.
"""

from __future__ import annotations

from pathlib import Path

import lb_hostile
import pytest

pytestmark = pytest.mark.slow


def test_patching_the_runner_changes_nothing_outside_the_method(tmp_path: Path) -> None:
    lb_hostile.require_sandbox()
    hostile = lb_hostile.Hostile.create(tmp_path)
    entry = hostile.method("""
        import swarmloc.bench.scoring.metrics as M
        import swarmloc.bench.evaluation.runner as R
        import swarmloc.leaderboard.verify.worker as W
        R.run_episodes = R.evaluate_task = lambda *a, **k: []
        M.team_return = lambda *a, **k: 0.99
        W._respond = lambda *a, **k: None
    """)
    done = hostile.submit(entry)
    hostile.assert_refused(done, "compared with exact equality", "differ", "team_return: submitted")


def test_a_forged_response_is_refused(tmp_path: Path) -> None:
    lb_hostile.require_sandbox()
    hostile = lb_hostile.Hostile.create(tmp_path)
    entry = hostile.method("""
        import json
        forged = json.dumps({"ok": True, "episodes": []}).encode()
        for fd in range(3, 256):
            try:
                os.write(fd, forged)
            except OSError:
                pass
    """)
    done = hostile.submit(entry)
    hostile.assert_refused(done, "MethodProtocolError: the method sent a", "-byte message; the limit is 67108864 bytes")
