"""Provenance: which code, libraries and machine produced a file.

Results files, trained weights and reports record it, so that any number can be traced
back to the commit that made it. Versions come from package metadata: neither numpy nor
torch is imported here.
"""

from __future__ import annotations

import os
import platform
import subprocess
from collections.abc import Sequence
from datetime import datetime, timezone
from importlib import metadata as importlib_metadata
from pathlib import Path

from pydantic import AwareDatetime, BaseModel, ConfigDict, Field

_FROZEN = ConfigDict(extra="forbid", frozen=True, ser_json_inf_nan="constants")


class MachineInfo(BaseModel):
    """Where the evaluation ran: ``platform.platform()`` and ``os.cpu_count()``."""

    model_config = _FROZEN

    platform: str = Field(min_length=1, max_length=256)
    cpu_count: int = Field(ge=1)


class Provenance(BaseModel):
    """How the results were produced.

    Attributes:
        package_version: Installed swarmloc version.
        git_commit: Commit of the swarmloc checkout, when it is one.
        created_utc: Time the results were produced (timezone-aware, UTC).
        python_version, numpy_version, torch_version: Library versions (torch may be absent).
        machine: Platform string and CPU count.
    """

    model_config = _FROZEN

    package_version: str = Field(min_length=1, max_length=64)
    git_commit: str | None = Field(default=None, pattern=r"^[0-9a-f]{7,64}$")
    created_utc: AwareDatetime
    python_version: str = Field(min_length=1, max_length=64)
    numpy_version: str = Field(min_length=1, max_length=64)
    torch_version: str | None = Field(default=None, max_length=64)
    machine: MachineInfo


def git_commit() -> str | None:
    """Commit of the checkout this file lives in, or None outside a git checkout."""
    try:
        out = subprocess.run(
            ["git", "rev-parse", "HEAD"],
            cwd=Path(__file__).resolve().parent,
            capture_output=True,
            text=True,
            timeout=5,
            check=True,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    commit = out.stdout.strip()
    return commit or None


def source_commit(paths: Sequence[str]) -> str:
    """``git rev-parse HEAD``, with ``-dirty`` when any of ``paths`` differs from it (``unknown`` outside git).

    For records of long runs (trained weights): call it when the run starts, since HEAD
    may move while it runs.

    Args:
        paths: the code the run depends on, relative to the repository root.
    """
    root = Path(__file__).resolve().parents[2]
    head = git_commit()
    if head is None:
        return "unknown"
    try:
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", *paths],
                               cwd=root, capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return head + ("-dirty" if dirty else "")


def dist_version(name: str) -> str | None:
    """Installed version of a distribution without importing it (None when absent)."""
    try:
        return importlib_metadata.version(name)
    except importlib_metadata.PackageNotFoundError:
        return None


def collect_provenance() -> Provenance:
    """Describe the current process: package, git commit, library versions, machine.

    Versions come from package metadata, so neither numpy nor torch is imported here.
    """
    return Provenance(
        package_version=dist_version("swarmloc") or "0+unknown",
        git_commit=git_commit(),
        created_utc=datetime.now(timezone.utc),
        python_version=platform.python_version(),
        numpy_version=dist_version("numpy") or "unknown",
        torch_version=dist_version("torch"),
        machine=MachineInfo(platform=platform.platform(), cpu_count=os.cpu_count() or 1),
    )
