"""Hostile submission: a method that allocates 30 GB, and one that fills its tmp.

The address-space limit (``--memory-limit-mb``) turns the allocation into a MemoryError,
reported as the memory limit; the file-size limit stops a file in the private tmp at
``--max-file-mb`` (the tmpfs itself is capped too), so neither reaches the host.
"""

from __future__ import annotations

from pathlib import Path

import lb_hostile
import pytest

pytestmark = pytest.mark.slow


def test_allocating_30_gb_hits_the_memory_limit(tmp_path: Path) -> None:
    lb_hostile.require_sandbox()
    hostile = lb_hostile.Hostile.create(tmp_path)
    entry = hostile.method("""
        hog = bytearray(30 * 1024**3)
        raise AssertionError(f"allocated {len(hog)} bytes")
    """)
    done = hostile.submit(entry, "--memory-limit-mb", "1024")
    hostile.assert_refused(done, "exceeded the memory limit of 1024 MiB while re-running 1 episode(s)")


def test_filling_the_private_tmp_hits_the_file_size_limit(tmp_path: Path) -> None:
    lb_hostile.require_sandbox()
    hostile = lb_hostile.Hostile.create(tmp_path)
    entry = hostile.method("""
        with open("/tmp/fill", "wb") as handle:
            while True:
                handle.write(b"x" * 1024**2)
    """)
    done = hostile.submit(entry, "--max-file-mb", "8")
    hostile.assert_refused(done, "File too large")
