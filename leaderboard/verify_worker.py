"""Sandboxed re-run of submitted episodes: ``python -m swarmloc.leaderboard.verify_worker``.

Started by :mod:`swarmloc.leaderboard.verify` in a fresh process with a clean
environment (no store URL, a private temporary HOME). It caps its own address space
with ``RLIMIT_AS`` *before* importing anything of the method, reads a JSON request,
calls the runner, and writes a JSON response:

request::

    {"runner": "module:function", "method": "<entry point>", "weights": path | null,
     "sys_path": [dirs], "episodes": [[task, seed], ...]}

response::

    {"ok": true, "episodes": [{"task", "seed", "metrics": {...}}, ...]}
    {"ok": false, "kind": "memory" | "exception" | "bad_output", "message": str, "traceback": str}

The runner is called as ``runner(method, episodes)`` (plus ``weights=path`` when a weights
file was submitted) and must return one ``{"task", "seed", "metrics"}`` mapping per episode.

Exit codes: 0 success, 2 bad invocation, 3 memory limit exceeded, 4 the runner or method
raised, 5 the runner returned malformed output. Only the standard library is imported
here, so the limit applies to the method, not to the worker.
"""

from __future__ import annotations

import argparse
import errno
import importlib
import json
import os
import resource
import sys
import traceback
from collections.abc import Mapping
from typing import Any

EXIT_OK = 0
EXIT_USAGE = 2
EXIT_MEMORY = 3
EXIT_EXCEPTION = 4
EXIT_BAD_OUTPUT = 5

_TRACEBACK_CHARS = 4000


class BadOutput(Exception):
    """The runner returned something that is not a list of episode results."""


def limit_memory(max_bytes: int) -> None:
    """Cap this process's address space (soft and hard) at ``max_bytes``."""
    resource.setrlimit(resource.RLIMIT_AS, (max_bytes, max_bytes))


def load_callable(spec: str) -> Any:
    """Import ``module:attr.path`` and return the attribute."""
    module_name, sep, attr_path = spec.partition(":")
    if not sep or not module_name or not attr_path:
        raise ValueError(f"runner {spec!r} must look like 'module:function'")
    obj: Any = importlib.import_module(module_name)
    for part in attr_path.split("."):
        obj = getattr(obj, part)
    if not callable(obj):
        raise TypeError(f"runner {spec!r} is not callable")
    return obj


def _number(value: Any, where: str) -> float | None:
    if value is None:
        return None
    if isinstance(value, (str, bytes)):
        raise BadOutput(f"{where} is the string {value!r}; expected a number or None")
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise BadOutput(f"{where} is {value!r}; expected a number or None") from None
    return number


def normalize_episode(item: Any) -> dict[str, Any]:
    """Turn one runner output item into plain JSON data ``{"task", "seed", "metrics"}``."""
    if hasattr(item, "model_dump"):
        item = item.model_dump()
    if not isinstance(item, Mapping):
        raise BadOutput(f"runner returned {type(item).__name__}; expected a mapping per episode")
    try:
        task, seed, metrics = item["task"], item["seed"], item["metrics"]
    except KeyError as err:
        raise BadOutput(f"runner output item lacks the key {err.args[0]!r}") from None
    if hasattr(metrics, "model_dump"):
        metrics = metrics.model_dump()
    if not isinstance(metrics, Mapping):
        raise BadOutput(f"metrics of ({task!r}, {seed!r}) is {type(metrics).__name__}, not a mapping")
    clean = {
        str(name): _number(value, f"metric {name!r} of ({task!r}, {seed!r})")
        for name, value in metrics.items()
    }
    return {"task": str(task), "seed": int(seed), "metrics": clean}


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


def _write(path: str, payload: Mapping[str, Any]) -> None:
    tmp = f"{path}.tmp"
    with open(tmp, "w", encoding="utf-8") as handle:
        json.dump(payload, handle, allow_nan=True)
    os.replace(tmp, path)


def _failure(kind: str, err: BaseException) -> dict[str, Any]:
    text = "".join(traceback.format_exception(err))
    return {
        "ok": False,
        "kind": kind,
        "message": f"{type(err).__name__}: {err}"[:_TRACEBACK_CHARS],
        "traceback": text[-_TRACEBACK_CHARS:],
    }


def run(request: Mapping[str, Any]) -> list[dict[str, Any]]:
    """Call the requested runner on the requested episodes and normalize its output."""
    for entry in reversed(request.get("sys_path", [])):
        sys.path.insert(0, str(entry))
    runner = load_callable(request["runner"])
    episodes = [(str(task), int(seed)) for task, seed in request["episodes"]]
    kwargs = {"weights": request["weights"]} if request.get("weights") else {}
    output = runner(request["method"], episodes, **kwargs)
    try:
        items = list(output)
    except TypeError:
        raise BadOutput(f"runner returned {type(output).__name__}; expected a list") from None
    return [normalize_episode(item) for item in items]


def main(argv: list[str] | None = None) -> int:
    """Entry point of the worker process; see the module docstring."""
    parser = argparse.ArgumentParser(prog="python -m swarmloc.leaderboard.verify_worker")
    parser.add_argument("--request", required=True, help="JSON request file")
    parser.add_argument("--response", required=True, help="where to write the JSON response")
    parser.add_argument("--memory-bytes", type=int, default=0, help="RLIMIT_AS cap (0: none)")
    args = parser.parse_args(argv)
    if args.memory_bytes > 0:
        limit_memory(args.memory_bytes)
    with open(args.request, encoding="utf-8") as handle:
        request = json.load(handle)
    try:
        episodes = run(request)
    except BadOutput as err:
        _write(args.response, _failure("bad_output", err))
        return EXIT_BAD_OUTPUT
    except BaseException as err:  # noqa: BLE001 - any failure of submitted code is reported
        if is_out_of_memory(err):
            _write(args.response, _failure("memory", err))
            return EXIT_MEMORY
        _write(args.response, _failure("exception", err))
        return EXIT_EXCEPTION
    _write(args.response, {"ok": True, "episodes": episodes})
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
