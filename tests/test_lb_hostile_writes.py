"""Hostile submission: a method that writes outside its private tmp during verification.

Its ``reset`` writes beside its own file, over its own source, into swarmloc's package and
into the Python environment, then raises a report of what happened. Sandboxed, the folder
beside it is an empty stand-in on the private tmpfs (the host's folder is not there), and
the three others fail ("Read-only file system", or "Permission denied" for the ``nobody``
a root-started sandbox runs as); the host sees no new or changed file. The control run
with ``--no-sandbox`` shows the attack is real.
"""

from __future__ import annotations

import re
from pathlib import Path

import lb_hostile
import pytest

import swarmloc.leaderboard

pytestmark = pytest.mark.slow

ATTACK = """
    report = []
    for target in TARGETS:
        try:
            with open(target, "a") as handle:
                handle.write("pwned")
            report.append(f"{target}: written")
        except OSError as err:
            report.append(f"{target}: {err.strerror}")
    raise RuntimeError("write attempts: " + "; ".join(report))
"""


def test_writes_outside_tmp_fail_and_leave_nothing(tmp_path: Path) -> None:
    lb_hostile.require_sandbox()
    hostile = lb_hostile.Hostile.create(tmp_path)
    method_file = tmp_path / "evil.py"
    package_file = Path(swarmloc.leaderboard.__file__).parent / f"PWNED_{hostile.marker}"
    prefix_file = Path(__import__("sys").prefix) / f"PWNED_{hostile.marker}"
    targets = [tmp_path / "PWNED", method_file, package_file, prefix_file]
    entry = hostile.method(ATTACK, preamble=f"TARGETS = {[str(t) for t in targets]!r}")
    source = method_file.read_text()
    done = hostile.submit(entry)
    hostile.assert_refused(done, "crashed during verification", "write attempts: ")
    refused = "(Read-only file system|Permission denied)"
    # Beside the method is the sandbox's tmpfs: writable (ours) or not ('nobody' under root).
    assert re.search(rf"{re.escape(str(tmp_path / 'PWNED'))}: (written|Permission denied)", done.output)
    for target in (method_file, package_file, prefix_file):
        assert re.search(rf"{re.escape(str(target))}: {refused}", done.output), target
    assert not (tmp_path / "PWNED").exists()  # the host's folder is not in the sandbox
    assert not package_file.exists() and not prefix_file.exists()
    assert method_file.read_text() == source


def test_the_same_attack_succeeds_without_the_sandbox(tmp_path: Path) -> None:
    hostile = lb_hostile.Hostile.create(tmp_path)
    entry = hostile.method(ATTACK, preamble=f"TARGETS = {[str(tmp_path / 'PWNED')]!r}")
    done = hostile.submit(entry, "--no-sandbox")
    assert done.code == 1 and f"{tmp_path / 'PWNED'}: written" in done.output, done.output
    assert (tmp_path / "PWNED").read_text() == "pwned"  # unsandboxed, the host file is written
