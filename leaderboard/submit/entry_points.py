"""Method entry points: parse them and find their source without running any code.

Three forms are accepted:

* ``package.module:factory`` — importable from an installed package or a search path;
* ``path/to/file.py:factory`` — a file anywhere on disk;
* ``name`` — a method registered by swarmloc (e.g. ``uniform``, ``huber+smooth``).

The leaderboard process never imports submitted code: sources are located with
``importlib.machinery.PathFinder`` (which reads directories, not modules) and only the
sandboxed verification worker imports and runs the method.
"""

from __future__ import annotations

import hashlib
import re
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from importlib.machinery import PathFinder
from pathlib import Path
from typing import Literal

MAX_ENTRY_POINT_CHARS: int = 512

_DOTTED = r"[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*"
_MODULE_FORM = re.compile(rf"^(?P<module>{_DOTTED}):(?P<attr>{_DOTTED})$")
_FILE_FORM = re.compile(rf"^(?P<file>[^:\x00-\x1f]+\.py):(?P<attr>{_DOTTED})$")
_REGISTERED_FORM = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+\-]{0,127}$")


@dataclass(frozen=True)
class EntryPoint:
    """A parsed entry point.

    Attributes:
        text: The entry point as given.
        kind: ``"module"``, ``"file"`` or ``"registered"``.
        module: Dotted module name (``module`` form), the file's stem (``file`` form),
            or ``None`` (``registered``).
        attr: Factory attribute path, or ``None`` for registered names.
        file: The ``.py`` file for the ``file`` form, else ``None``.
    """

    text: str
    kind: Literal["module", "file", "registered"]
    module: str | None = None
    attr: str | None = None
    file: Path | None = None

    def for_runner(self) -> tuple[str, list[str]]:
        """The method string a runner can import, plus directories to put on ``sys.path``.

        A file entry point ``dir/x.py:make`` becomes ``x:make`` with ``dir`` on the path.
        """
        if self.kind == "file":
            assert self.file is not None
            return f"{self.module}:{self.attr}", [str(self.file.resolve().parent)]
        return self.text, []


def parse_entry_point(text: str) -> EntryPoint:
    """Parse an entry point string.

    Args:
        text: ``package.module:factory``, ``path/to/file.py:factory`` or a registered name.

    Returns:
        The parsed entry point.

    Raises:
        ValueError: naming the string and the accepted forms.
    """
    allowed = (
        "allowed forms: 'package.module:factory', 'path/to/file.py:factory', "
        "or a registered method name (letters, digits, '_', '.', '-', '+')"
    )
    if not isinstance(text, str) or not text or len(text) > MAX_ENTRY_POINT_CHARS:
        raise ValueError(
            f"entry point {text!r} must be a non-empty string of at most "
            f"{MAX_ENTRY_POINT_CHARS} characters; {allowed}"
        )
    if match := _FILE_FORM.match(text):
        file = Path(match["file"])
        return EntryPoint(text, "file", module=file.stem, attr=match["attr"], file=file)
    if match := _MODULE_FORM.match(text):
        return EntryPoint(text, "module", module=match["module"], attr=match["attr"])
    if _REGISTERED_FORM.match(text):
        return EntryPoint(text, "registered")
    raise ValueError(f"entry point {text!r} is not valid; {allowed}")


def locate_source(entry: EntryPoint, search_path: Sequence[str | Path] = ()) -> Path | None:
    """Find the source file that defines an entry point's factory, importing nothing.

    Args:
        entry: A parsed entry point.
        search_path: Extra directories searched before ``sys.path``.

    Returns:
        The ``.py`` file, or ``None`` for registered names and modules that cannot be
        found without importing (namespace packages, extension modules, zip imports).
    """
    if entry.kind == "file":
        return entry.file if entry.file is not None and entry.file.is_file() else None
    if entry.kind != "module" or entry.module is None:
        return None
    path: list[str] = [str(p) for p in search_path] + list(sys.path)
    spec = None
    for part in entry.module.split("."):
        spec = PathFinder.find_spec(part if spec is None else f"{spec.name}.{part}", path)
        if spec is None:
            return None
        if spec.submodule_search_locations is not None:
            path = list(spec.submodule_search_locations)
    if spec is None or spec.origin is None or not spec.origin.endswith(".py"):
        return None
    return Path(spec.origin)


def sha256_file(path: str | Path, chunk_bytes: int = 1 << 20) -> str:
    """Hex SHA-256 of a file, read in chunks."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        while chunk := handle.read(chunk_bytes):
            digest.update(chunk)
    return digest.hexdigest()


__all__ = ["EntryPoint", "locate_source", "parse_entry_point", "sha256_file"]
