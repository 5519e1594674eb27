"""``swarmloc data import-util``: decode one UTIL TWR µSD log and the anchor survey.

Writes the CSV layout that ``UTILFlight-v0`` replays (``swarmloc.envs.recorded.util_import``).
Use ``DIR = <data>/util-twr`` and set ``SWARMLOC_DATA=<data>``. The UTIL data has no
licence: never commit it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import tyro


@dataclass
class Options:
    """Import a UTIL TWR µSD log (e.g. twr-obs-log1, log00) and the anchor survey (for UTILFlight-v0)."""

    raw_log: Annotated[Path, tyro.conf.Positional, tyro.conf.arg(metavar="RAW_LOG")]
    """The binary µSD log from the UTIL repository's history (e.g. twr-obs-log1.bin)."""
    anchors: Annotated[Path, tyro.conf.arg(metavar="SURVEY")]
    """The anchor survey file (anchor_0607.txt)."""
    out: Annotated[Path, tyro.conf.arg(metavar="DIR")]
    """The dataset folder that receives <log>/ and anchors.csv (usually <data>/util-twr)."""


def run(opts: Options) -> int:
    """Run the importer; a bad input prints the reason and exits with status 2."""
    from swarmloc.envs.recorded.cfusdlog import UsdLogError
    from swarmloc.envs.recorded.util_import import UtilImportError, main_import_util

    try:
        main_import_util(opts.raw_log, opts.anchors, opts.out)
    except (OSError, UsdLogError, UtilImportError) as err:
        print(f"error: {err}")
        return 2
    return 0
