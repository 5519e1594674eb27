"""A throwaway PostgreSQL server for the store tests: ``initdb`` + ``pg_ctl`` in a temporary folder.

The server listens only on a Unix socket inside its folder (no TCP port, so parallel test
workers never collide), trusts local connections, and is stopped and deleted afterwards.
Binaries come from ``PATH`` or Debian's ``/usr/lib/postgresql/<version>/bin`` (package
``postgresql``, which ``.ci/run`` installs). As root — CI runs as root — the server runs as
the ``postgres`` user (or ``nobody``), since PostgreSQL refuses to run as root.

Set ``SWARMLOC_REQUIRE_POSTGRES=1`` (``.ci/run`` does) to turn a missing server or driver
into a test failure instead of a skip.
"""

from __future__ import annotations

import glob
import os
import pwd
import shutil
import subprocess
import tempfile
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

REQUIRE_ENV = "SWARMLOC_REQUIRE_POSTGRES"
SUPERUSER = "swarmloc"


def find_bindir() -> Path | None:
    """Folder holding ``initdb`` and ``pg_ctl``: PATH first, then the newest Debian version."""
    on_path = shutil.which("initdb")
    if on_path and shutil.which("pg_ctl"):
        return Path(os.path.realpath(on_path)).parent
    candidates = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"),
                        key=lambda p: int(Path(p).parent.parent.name) if Path(p).parent.parent.name.isdigit() else 0)
    return Path(candidates[-1]).parent if candidates else None


def unavailable_reason() -> str | None:
    """Why no throwaway server can be started here (None when it can)."""
    try:
        import psycopg  # noqa: F401
    except ImportError:
        return "the PostgreSQL driver psycopg is not installed (pip install -e '.[dev]' installs it)"
    if find_bindir() is None:
        return ("PostgreSQL server binaries (initdb, pg_ctl) are not on PATH nor in "
                "/usr/lib/postgresql/*/bin; install Debian's 'postgresql' package (.ci/run does)")
    return None


def _server_user() -> str | None:
    """The account the server runs as when we are root (None: run as ourselves)."""
    if os.geteuid() != 0:
        return None
    for name in ("postgres", "nobody"):
        try:
            pwd.getpwnam(name)
            return name
        except KeyError:
            continue
    raise RuntimeError("running as root, and neither a 'postgres' nor a 'nobody' account exists to run the server")


@dataclass
class ThrowawayPostgres:
    """A running server; :meth:`new_database` hands out empty databases."""

    bindir: Path
    root: Path
    user: str | None

    @property
    def socket_dir(self) -> Path:
        return self.root / "socket"

    def _run(self, *args: str) -> subprocess.CompletedProcess[str]:
        done = subprocess.run([str(self.bindir / args[0]), *args[1:]], user=self.user, capture_output=True,
                              text=True, timeout=120, check=False, cwd=self.root)
        if done.returncode != 0:
            raise RuntimeError(f"{' '.join(args)} failed ({done.returncode}): {done.stderr.strip() or done.stdout}")
        return done

    def url(self, database: str) -> str:
        """SQLAlchemy URL of a database on this server (psycopg 3, over the Unix socket)."""
        return f"postgresql+psycopg://{SUPERUSER}@/{database}?host={self.socket_dir}"

    def new_database(self) -> str:
        """Create an empty database; return its URL."""
        import psycopg

        name = f"t_{uuid.uuid4().hex[:16]}"
        with psycopg.connect(host=str(self.socket_dir), user=SUPERUSER, dbname="postgres", autocommit=True) as conn:
            conn.execute(f'CREATE DATABASE "{name}"')
        return self.url(name)


@contextmanager
def throwaway_postgres() -> Iterator[ThrowawayPostgres]:
    """Start a server in a temporary folder; stop it and delete everything on exit."""
    bindir = find_bindir()
    if bindir is None:
        raise RuntimeError(unavailable_reason() or "no PostgreSQL binaries")
    user = _server_user()
    root = Path(tempfile.mkdtemp(prefix="swarmloc-pg-"))
    server = ThrowawayPostgres(bindir, root, user)
    try:
        (root / "socket").mkdir()
        if user is not None:
            entry = pwd.getpwnam(user)
            for path in (root, root / "socket"):
                os.chown(path, entry.pw_uid, entry.pw_gid)
        server._run("initdb", "-D", str(root / "data"), "-U", SUPERUSER, "--auth=trust",
                    "-E", "UTF8", "--locale=C", "--no-sync")
        options = f"-c listen_addresses='' -k {root / 'socket'} -c fsync=off -c max_connections=50"
        server._run("pg_ctl", "-D", str(root / "data"), "-o", options, "-l", str(root / "server.log"),
                    "-w", "-t", "60", "start")
        yield server
    finally:
        if (root / "data" / "postmaster.pid").exists():
            subprocess.run([str(bindir / "pg_ctl"), "-D", str(root / "data"), "-m", "immediate", "-w", "stop"],
                           user=user, capture_output=True, timeout=60, check=False, cwd=root)
        shutil.rmtree(root, ignore_errors=True)
