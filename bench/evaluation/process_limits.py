"""Limits of a process that runs untrusted code: resources, numba's cache, out-of-memory errors.

The verification worker and the method process (``remote_method``) each start in a sandbox of
their own and cap themselves before running anything submitted.
"""

from __future__ import annotations

import errno
import hashlib
import resource
import shutil
from collections.abc import Sequence
from pathlib import Path


def apply_limits(memory_bytes: int, max_processes: int = 0, max_file_bytes: int = 0) -> None:
    """Cap this process and its children (soft and hard limits; 0 leaves one unset).

    Args:
        memory_bytes: Address space (``RLIMIT_AS``).
        max_processes: Processes and threads of this user in the sandbox (``RLIMIT_NPROC``).
        max_file_bytes: Largest file any write may grow, standard output included
            (``RLIMIT_FSIZE``; Python ignores ``SIGXFSZ``, so writes fail with ``EFBIG``).
    """
    if memory_bytes > 0:
        resource.setrlimit(resource.RLIMIT_AS, (memory_bytes, memory_bytes))
    if max_processes > 0:
        resource.setrlimit(resource.RLIMIT_NPROC, (max_processes, max_processes))
    if max_file_bytes > 0:
        resource.setrlimit(resource.RLIMIT_FSIZE, (max_file_bytes, max_file_bytes))
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))


def seed_numba_cache(sources: Sequence[str], cache_dir: str) -> None:
    """Copy numba's on-disk caches of ``sources`` into ``cache_dir`` (``NUMBA_CACHE_DIR``).

    Inside the sandbox the source folders are read-only, so numba cannot use their
    ``__pycache__``; copying the index and data files to where ``NUMBA_CACHE_DIR`` points
    (numba's layout: ``<folder name>_<sha1 of the folder path>``) saves recompiling every
    kernel. Files are copied one way only: nothing the sandbox writes reaches the host.
    """
    for source in sources:
        pycache = Path(source) / "__pycache__"
        if not pycache.is_dir():
            continue
        sub = f"{Path(source).name}_{hashlib.sha1(str(source).encode()).hexdigest()}"
        target = Path(cache_dir) / sub
        target.mkdir(parents=True, exist_ok=True)
        for item in pycache.iterdir():
            if item.suffix in (".nbi", ".nbc"):
                shutil.copy2(item, target / item.name)


_OUT_OF_MEMORY_SIGNS = ("failed to map segment", "cannot allocate memory", "bad_alloc",
                        "out of memory", "unable to allocate")


def is_out_of_memory(err: BaseException) -> bool:
    """True when an error (or its cause chain) comes from hitting the address-space cap.

    Besides ``MemoryError``, a capped process sees ``ENOMEM`` from the OS, shared libraries
    that fail to map ("failed to map segment") and C++ ``std::bad_alloc`` surfacing as
    ``RuntimeError``.
    """
    seen: set[int] = set()
    current: BaseException | None = err
    while current is not None and id(current) not in seen:
        seen.add(id(current))
        if isinstance(current, MemoryError):
            return True
        if isinstance(current, OSError) and current.errno == errno.ENOMEM:
            return True
        if any(sign in str(current).lower() for sign in _OUT_OF_MEMORY_SIGNS):
            return True
        current = current.__cause__ or current.__context__
    return False
