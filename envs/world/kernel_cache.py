"""Stale numba kernels: drop the on-disk cache when any kernel source has changed.

numba's disk cache (``@njit(cache=True)``, files ``__pycache__/*.nbi`` / ``*.nbc``) checks
only the source file that *defines* a cached function. A kernel compiles its callees into
itself, so after an edit of a callee in another module (``cekf.py`` under ``sim_kernel.py``,
``envs`` kernels under ``agents`` ones) the caller's cached machine code still runs the old
callee: wrong numbers, silently, after a ``git pull`` of an editable install or a
``pip install -U`` (pip leaves the cache files behind). ``tests/test_kernel_cache.py``
reproduces this with two modules.

The guard fingerprints every module of ``swarmloc.envs`` and ``swarmloc.agents`` that
mentions ``njit`` and every package module those import (numba freezes imported globals
into the code), with numba's version, and keeps the fingerprint beside the cache
(``envs/__pycache__/swarmloc-kernels.sha256``), with the files' sizes and times as a fast
path (5 ms while nothing was touched). When the fingerprint differs it deletes the cache
files of both packages before any kernel is loaded; the kernels then compile afresh (a few
minutes, once) and the new fingerprint is written. Concurrent processes (pytest-xdist
workers, pool workers) may all delete: that only costs a compile, never a stale kernel.
Where the package folders are not writable nothing is deleted, and numba keeps its cache
elsewhere (its ``NUMBA_CACHE_DIR`` rules); that case is not guarded.
"""

from __future__ import annotations

import ast
import hashlib
import os
from collections.abc import Iterable
from pathlib import Path

#: the fingerprint file, in the first folder's ``__pycache__``
STAMP_NAME = "swarmloc-kernels.sha256"
CACHE_SUFFIXES = (".nbi", ".nbc")


def _imported_files(path: Path, roots: dict[str, Path]) -> set[Path]:
    """The files of ``roots`` (package name → folder) that ``path`` imports, relative or absolute."""
    root_name, root = next((n, r) for n, r in roots.items() if path.is_relative_to(r))
    package = [root_name, *path.relative_to(root).parent.parts]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            base = package[: len(package) - node.level + 1] if node.level else []
            module = base + (node.module.split(".") if node.module else [])
            candidates = [module] + [module + [alias.name] for alias in node.names]
        elif isinstance(node, ast.Import):
            candidates = [alias.name.split(".") for alias in node.names]
        else:
            continue
        for parts in candidates:
            if parts[:1] == ["swarmloc"]:
                parts = parts[1:]
            if not parts or parts[0] not in roots:
                continue
            target = roots[parts[0]].joinpath(*parts[1:])
            for candidate in (target.with_suffix(".py"), target / "__init__.py"):
                if candidate.is_file():
                    found.add(candidate)
    return found


def kernel_sources(roots: Iterable[Path]) -> list[Path]:
    """The ``.py`` files under ``roots`` whose code a cached kernel can hold, sorted: those that mention
    ``njit`` and every package module they import, transitively (numba freezes imported globals such
    as channel-kind constants into the compiled code, so their modules count too)."""
    named = {Path(r).name: Path(r) for r in roots}
    this = Path(__file__).resolve()  # names njit in its prose only
    todo = [path for root in named.values() for path in sorted(root.rglob("*.py"))
            if "__pycache__" not in path.parts and path.resolve() != this
            and "njit" in path.read_text(encoding="utf-8")]
    found: set[Path] = set()
    while todo:
        path = todo.pop()
        if path not in found:
            found.add(path)
            todo.extend(_imported_files(path, named) - found)
    return sorted(found)


def sources_fingerprint(roots: Iterable[Path], numba_version: str) -> str:
    """sha256 over numba's version and the relative path and bytes of every kernel source under ``roots``."""
    roots = [Path(r) for r in roots]
    digest = hashlib.sha256(numba_version.encode())
    for path in kernel_sources(roots):
        root = next(r for r in roots if path.is_relative_to(r))
        digest.update(f"\0{root.name}/{path.relative_to(root).as_posix()}\0".encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def _files_signature(roots: list[Path], numba_version: str) -> str:
    """sha256 over numba's version and the path, size and time of every ``.py`` file under ``roots`` (cheap)."""
    digest = hashlib.sha256(numba_version.encode())
    for root in roots:
        for path in sorted(root.rglob("*.py")):
            st = path.stat()
            name = f"{root.name}/{path.relative_to(root).as_posix()}"
            digest.update(f"{name}\0{st.st_size}\0{st.st_mtime_ns}\n".encode())
    return digest.hexdigest()


def drop_stale_kernel_cache(roots: Iterable[Path], numba_version: str) -> bool:
    """Delete the numba cache files under ``roots`` if the kernel sources changed since they were written.

    The stamp holds the sources' fingerprint and, as a fast path, a signature of the files'
    sizes and times: while no file under ``roots`` is touched, nothing is read or parsed.

    Args:
        roots: the package folders whose kernels call each other (``envs``, ``agents``).
        numba_version: numba's version (a new numba recompiles too).

    Returns:
        True when the cache files were deleted and the stamp renewed; False when the kernel
        sources are those the cache was written for, or the folders are not writable.
    """
    roots = [Path(r) for r in roots]
    stamp = roots[0] / "__pycache__" / STAMP_NAME
    signature = _files_signature(roots, numba_version)
    try:
        kept_signature, kept_fingerprint = stamp.read_text(encoding="ascii").split()
    except (OSError, ValueError):  # no stamp yet: whatever cache is there came from unknown sources
        kept_signature = kept_fingerprint = ""
    if signature == kept_signature:
        return False
    fingerprint = sources_fingerprint(roots, numba_version)
    stale = fingerprint != kept_fingerprint
    try:
        if stale:
            for root in roots:
                for cached in root.rglob("__pycache__/*"):
                    if cached.suffix in CACHE_SUFFIXES:
                        cached.unlink(missing_ok=True)
        stamp.parent.mkdir(exist_ok=True)
        partial = stamp.with_name(f"{STAMP_NAME}.{os.getpid()}")
        partial.write_text(f"{signature}\n{fingerprint}\n", encoding="ascii")
        os.replace(partial, stamp)
    except OSError:
        return False
    return stale


def guard_kernel_cache() -> bool:
    """``drop_stale_kernel_cache`` for the installed ``swarmloc.envs`` and ``swarmloc.agents`` (once per process).

    ``swarmloc.envs`` runs it on import, before any kernel module can load: every kernel module
    (the ``agents`` ones too) imports from ``swarmloc.envs``. numba's version comes from its
    package metadata, so the guard does not import numba (``swarmloc --help`` stays light).
    """
    global _GUARDED
    if _GUARDED:
        return False
    _GUARDED = True
    import importlib.metadata
    import importlib.util

    agents = importlib.util.find_spec("swarmloc.agents")
    roots = [Path(__file__).parents[1]]  # the whole envs room
    if agents is not None and agents.submodule_search_locations:
        roots.append(Path(next(iter(agents.submodule_search_locations))))
    return drop_stale_kernel_cache(roots, importlib.metadata.version("numba"))


_GUARDED = False
