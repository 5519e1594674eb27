"""Hostile submission: a method that reads the submitter's home and the data folder.

It lists the real home folder (it reads ``/etc/passwd``-free: the path comes from the test),
reads a secret planted there, lists swarmloc's user data folder and the folder the method
came from. In the sandbox ``HOME`` is the private tmp, and none of these host paths exist.
"""

from __future__ import annotations

from pathlib import Path

import lb_hostile
import pytest
from platformdirs import user_data_dir

pytestmark = pytest.mark.slow


def test_home_and_data_folder_are_not_there(tmp_path: Path) -> None:
    lb_hostile.require_sandbox()
    hostile = lb_hostile.Hostile.create(tmp_path)
    secret = Path.home() / f".secret-{hostile.marker}"
    secret.write_text("ssh key")
    try:
        entry = hostile.method(f"""
            report = [f"HOME={{os.environ.get('HOME')}}"]
            for path in ({str(secret)!r}, {str(Path.home())!r}, {user_data_dir("swarmloc")!r}, "/etc/shadow"):
                try:
                    seen = open(path).read() if os.path.isfile(path) else str(os.listdir(path))
                    report.append(f"{{path}}: {{seen}}")
                except OSError as err:
                    report.append(f"{{path}}: {{err.strerror}}")
            raise RuntimeError("; ".join(report))
        """)
        done = hostile.submit(entry)
    finally:
        secret.unlink()
    hostile.assert_refused(done, "HOME=/tmp", f"{secret}: No such file or directory",
                           f"{user_data_dir('swarmloc')}: No such file or directory", "/etc/shadow: No such file")
    assert "ssh key" not in done.output
