"""``swarmloc data import-util-tdoa``: decode one UTIL TDOA µSD log (and its constellation's survey).

Writes the CSV layout that the real TDOA flight tasks replay
(``swarmloc.envs.recorded.tdoa_import``); use ``DIR = <data>/util-tdoa`` and set
``SWARMLOC_DATA=<data>``. The UTIL data has no licence: never commit it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import tyro


@dataclass
class Options:
    """Import a UTIL TDOA µSD log (e.g. 0426-traj11) into <DIR>/<flight>/ (for the UTIL TDOA tasks)."""

    raw_log: Annotated[Path, tyro.conf.Positional, tyro.conf.arg(metavar="RAW_LOG")]
    """The binary µSD log from the UTIL repository's history (e.g. 0426-traj11.bin)."""
    flight: Annotated[str, tyro.conf.arg(metavar="NAME")]
    """Flight folder name, e.g. c0426-tdoa2-traj11-wood-card-plastic-metal (the tasks' names, see `swarmloc tasks`)."""
    out: Annotated[Path, tyro.conf.arg(metavar="DIR")]
    """The dataset folder that receives <flight>/ (usually <data>/util-tdoa)."""
    survey: Annotated[Path | None, tyro.conf.arg(metavar="NPZ")] = None
    """The session's converted anchor survey (anchor_0426.npz); writes anchors_<constellation>.csv."""
    constellation: str | None = None
    """Constellation name for the anchors file (c0425, c0426, c0607); required with --survey."""
    overwrite: bool = False
    """Replace an existing flight folder."""


def run(opts: Options) -> int:
    """Run the importer; a bad input prints the reason and exits with status 2."""
    from swarmloc.envs.recorded.cfusdlog import UsdLogError
    from swarmloc.envs.recorded.tdoa_import import TdoaImportError, import_util_tdoa

    try:
        counts = import_util_tdoa(opts.raw_log, opts.out, opts.flight, survey=opts.survey,
                                  constellation=opts.constellation, overwrite=opts.overwrite)
    except (OSError, UsdLogError, TdoaImportError) as err:
        print(f"error: {err}")
        return 2
    print(f"imported {opts.raw_log} into {opts.out}:")
    width = max(map(len, counts))
    for name, rows in counts.items():
        print(f"  {name:<{width}}  {rows:>7} rows")
    print("UTIL data has no licence: internal benchmarking only; cite Zhao et al., IJRR 2024.")
    return 0
