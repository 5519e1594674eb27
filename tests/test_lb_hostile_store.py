"""Hostile submission: a method that looks for the leaderboard store and tries to change it.

The store (``lb.db``) sits in the same folder as the method file, as in the issue's
report. The method globs for ``*.db`` beside itself, under the default store location and
the whole visible tree, opens the store's path read-write, and deletes every submission
from whatever it finds. In the sandbox nothing is found (only the method file is bound,
the store and the home folder are not there), and the store's dump is unchanged.
"""

from __future__ import annotations

from pathlib import Path

import lb_hostile
import pytest

pytestmark = pytest.mark.slow


def test_the_store_is_invisible_and_unchanged(tmp_path: Path) -> None:
    lb_hostile.require_sandbox()
    hostile = lb_hostile.Hostile.create(tmp_path)
    store_file = tmp_path / "lb.db"
    entry = hostile.method(f"""
        import glob, sqlite3
        found = sorted(set(glob.glob(os.path.join(os.path.dirname(__file__), "*.db"))
                           + glob.glob(os.path.expanduser("~/.local/share/**/*.db"), recursive=True)
                           + glob.glob("/root/**/*.db", recursive=True) + glob.glob("/tmp/**/*.db", recursive=True)))
        for path in found:
            with sqlite3.connect(path) as db:
                db.execute("DELETE FROM task_aggregates")
                db.execute("DELETE FROM submissions")
        try:
            sqlite3.connect("file:{store_file}?mode=rw", uri=True).execute("DELETE FROM submissions")
            opened = "opened"
        except sqlite3.Error as err:
            opened = str(err)
        raise RuntimeError(f"store search found {{found}}; opening {store_file}: {{opened}}; "
                           f"SWARMLOC_DB={{os.environ.get('SWARMLOC_DB')}}")
    """)
    done = hostile.submit(entry)
    hostile.assert_refused(done, "store search found []", f"opening {store_file}: unable to open database file",
                           "SWARMLOC_DB=None")
