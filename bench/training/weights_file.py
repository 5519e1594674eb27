"""Writing shipped weights and the record beside them, the way every ``swarmloc train`` command does.

The weights go to ``out`` and their record to ``out`` with ``.json``, each atomically: a reader
never sees half a file, and an interrupted run leaves the old pair. The record opens with what
every record holds (the method, the command that reproduces the weights, the provenance of the
run and the weights' SHA-256), then the fit's own fields in the order given.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from swarmloc.bench.common.files import write_bytes_atomic
from swarmloc.bench.common.provenance import collect_provenance


def write_npz_with_record(out: Path, save_npz: Callable[[Path], None], method: str, command: str,
                          **fields: Any) -> bytes:
    """Write the weights ``save_npz(path)`` produces (an ``.npz``) to ``out`` and their JSON record beside them.

    Args:
        out: the weights path; the record goes to ``out.with_suffix(".json")``.
        save_npz: writes the weights to the path it is given (a scratch file next to ``out``).
        method: the registered method the weights serve.
        command: the command line that reproduces them.
        **fields: the rest of the record, after ``method``, ``command``, ``provenance``, ``weights_sha256``.

    Returns:
        The bytes written to ``out``.
    """
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.stem}.building.npz")
    save_npz(tmp)
    data = tmp.read_bytes()
    tmp.unlink()
    write_bytes_atomic(out, data)
    record = {"method": method, "command": command, "provenance": collect_provenance().model_dump(mode="json"),
              "weights_sha256": hashlib.sha256(data).hexdigest(), **fields}
    write_bytes_atomic(out.with_suffix(".json"), (json.dumps(record, indent=2) + "\n").encode())
    return data
