"""MkDocs hook: let mkdocstrings read the ``swarmloc`` packages from their source folders.

There is no ``swarmloc/`` folder: setup.py installs ``envs/``, ``agents/``, ``bench/`` and
``leaderboard/`` as ``swarmloc.envs`` and so on, and an editable install maps them with an
import hook that griffe (mkdocstrings' Python reader) cannot follow. Before mkdocstrings
starts, this hook lays out the namespace griffe looks for, ``<tmp>/swarmloc/<room>`` as
links to the four folders, and puts ``<tmp>`` first on the Python handler's ``paths``.
griffe then reads the sources statically: nothing is imported, so the build needs neither
numba nor torch.
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

from mkdocs.config.defaults import MkDocsConfig
from mkdocs.plugins import event_priority

ROOMS = ("envs", "agents", "bench", "leaderboard", "cli")

_staged: list[Path] = []


@event_priority(100)  # before mkdocstrings reads its handler options
def on_config(config: MkDocsConfig) -> MkDocsConfig:
    root = Path(config.config_file_path).resolve().parent
    stage = Path(tempfile.mkdtemp(prefix="swarmloc-griffe-"))
    _staged.append(stage)
    (stage / "swarmloc").mkdir()
    for room in ROOMS:
        (stage / "swarmloc" / room).symlink_to(root / room, target_is_directory=True)
    python = config.plugins["mkdocstrings"].config.handlers.setdefault("python", {})
    python["paths"] = [str(stage), *python.get("paths", [])]
    return config


def on_shutdown() -> None:
    while _staged:
        shutil.rmtree(_staged.pop(), ignore_errors=True)
