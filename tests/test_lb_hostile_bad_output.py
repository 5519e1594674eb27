"""Hostile submission: methods whose actions are NaN, the wrong shape, or not numbers.

Each reaches the runner through the method's pipe: a non-numeric array is refused at the
pipe (the worker never unpickles what the method sends), a wrong shape is refused by the
environment, and NaN trust does not reproduce the submitted metrics.
"""

from __future__ import annotations

from pathlib import Path

import lb_hostile
import pytest

pytestmark = pytest.mark.slow

CASES = {
    "nan": ("return np.full(inp.nis.shape, np.nan)", "nan"),
    "wrong shape": ("return np.ones(3)", "shape"),
    "strings": ("return np.full(inp.nis.shape, 'trust me')", "only boolean and numeric arrays are allowed"),
    "object": ("return np.array([object()], dtype=object)", "Object arrays cannot be saved when allow_pickle=False"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_bad_actions_are_refused(case: str, tmp_path: Path) -> None:
    lb_hostile.require_sandbox()
    act, reason = CASES[case]
    hostile = lb_hostile.Hostile.create(tmp_path)
    entry = hostile.method("pass", act=act)
    done = hostile.submit(entry)
    hostile.assert_refused(done, reason)
