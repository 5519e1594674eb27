"""Honest methods through the sandbox: verified bit for bit and stored.

The same path as the hostile tests (``lb_hostile``: the real ``swarmloc submit``, the real
runner in the worker's sandbox, the method in its own), with true metrics for the
sampled episode: a Track A module in the working directory submitted as the README does
(``swarmloc submit mine.json``, nothing else), and a Track B estimator from a file. A store
inside the working directory is refused, since the method's sandbox would then show it.
"""

from __future__ import annotations

from pathlib import Path

import lb_hostile
import pytest

from swarmloc.leaderboard.store.database import LeaderboardStore

pytestmark = pytest.mark.slow

TRUST = '''\
import numpy as np


class ConstantTrust:
    privileged = False
    flops_per_channel = 2.0

    def reset(self, batch_size, layout, keys):
        self.shape = None

    def act(self, inp):
        return np.full(inp.nis.shape, 0.75)


def make():
    return ConstantTrust()
'''

ESTIMATOR = '''\
from swarmloc.agents.registry import load_method


def make():
    return load_method("dead-reckoning").method
'''


def test_a_module_in_the_working_directory_is_verified_and_stored(tmp_path: Path,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    lb_hostile.require_sandbox()
    hostile = lb_hostile.Hostile.create(tmp_path)
    work = tmp_path / "work"  # not the store's folder: the sandbox would refuse to show that
    work.mkdir()
    (work / "my_trust.py").write_text(TRUST)
    monkeypatch.syspath_prepend(str(work))  # to compute the true metrics here, as `swarmloc evaluate` would
    done = hostile.submit("my_trust:make", honest=True, cwd=work)
    assert done.code == 0, done.output
    assert "stored submission #2 'hostile'" in done.output and "all metrics reproduced" in done.output
    with LeaderboardStore(hostile.db_url) as store:
        entry = store.get(2)
    assert entry.entry_point == "my_trust:make" and entry.track == "A" and entry.verified_episodes == 1
    refused = lb_hostile.Hostile(work, hostile.marker, f"sqlite:///{work / 'lb.db'}", []).submit(
        "my_trust:make", honest=True)
    assert refused.code == 1 and f"the sandbox would show {work / 'lb.db'} to the submitted code" in refused.output


def test_a_track_b_estimator_is_verified_and_stored(tmp_path: Path) -> None:
    lb_hostile.require_sandbox()
    hostile = lb_hostile.Hostile.create(tmp_path)
    (tmp_path / "estimator.py").write_text(ESTIMATOR)
    entry = f"{tmp_path / 'estimator.py'}:make"
    done = hostile.submit(entry, honest=True, track="B")
    assert done.code == 0, done.output
    assert "all metrics reproduced" in done.output
    with LeaderboardStore(hostile.db_url) as store:
        assert store.get(2).track == "B"
