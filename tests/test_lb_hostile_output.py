"""Hostile submission: a method that prints hundreds of megabytes.

Its output goes to a log file the parent reads back only in part; the file-size limit
(``--max-file-mb``) stops it growing, the print fails with "File too large", and the
refusal says that the output limit was reached. The submitter's terminal gets a tail.
"""

from __future__ import annotations

from pathlib import Path

import lb_hostile
import pytest

pytestmark = pytest.mark.slow


def test_flooding_stdout_is_cut_at_the_file_size_limit(tmp_path: Path) -> None:
    lb_hostile.require_sandbox()
    hostile = lb_hostile.Hostile.create(tmp_path)
    entry = hostile.method("""
        line = "spam " * 200_000 + "\\n"
        for _ in range(500):
            sys.stdout.write(line)
            sys.stderr.write(line)
    """)
    done = hostile.submit(entry, "--max-file-mb", "4")
    hostile.assert_refused(done, "File too large", "its method output reached the 4 MiB file-size limit")
    assert len(done.output) < 100_000, f"{len(done.output)} characters reached the terminal"
