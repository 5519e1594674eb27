"""Atomic file writes: a reader sees the old file or the new one, never half of one.

Every file the bench and the leaderboard write (results, traces, weights, reports,
benchmark JSON) goes through here. The data goes to a temporary file in the target's
folder, is flushed and fsynced, gets the permissions a plain ``open()`` would give, and
is ``os.replace``-d over the target; the folder is fsynced where the platform allows.
On any error the temporary file is removed and the target is untouched.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path


def _default_mode() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def _fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:  # platforms without directory handles
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str], suffix: str = ".tmp") -> Iterator[Path]:
    """A temporary path to write to; on success it replaces ``path`` atomically.

    For writers that want a file name (``torch.save``, ``np.savez``, ``Figure.savefig``)::

        with atomic_path("weights.pt") as tmp:
            torch.save(state, tmp)

    Args:
        path: the destination; its folder must exist.
        suffix: the temporary file's suffix (some writers append an extension unless the
            name already ends with it, e.g. ``.npz`` for ``np.savez``).

    Yields:
        The temporary path (in the destination's folder, so the rename is atomic).
    """
    target = Path(path)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=suffix, dir=target.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        with open(tmp, "rb+") as handle:
            os.fsync(handle.fileno())
        os.chmod(tmp, _default_mode())  # mkstemp creates 0600
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync_dir(target.parent)


def write_bytes_atomic(path: str | os.PathLike[str], data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; returns the path."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text_atomic(path: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically; returns the path."""
    return write_bytes_atomic(path, text.encode("utf-8"))
