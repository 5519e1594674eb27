"""Re-run of submitted episodes inside the sandbox: ``python -m swarmloc.leaderboard.verify.worker``.

Started by :mod:`swarmloc.leaderboard.verify.verification` inside bubblewrap (see
:mod:`swarmloc.leaderboard.verify.sandbox`) with a clean environment. Before importing anything
of the runner or the method it caps its own resources (:func:`apply_limits`: address
space, processes, file size, no core dumps), then reads a JSON request from standard
input, calls the runner, and writes a JSON response to the file descriptor
``--response-fd`` — a pipe to the parent that no other process in the sandbox holds:

request::

    {"runner": "module:function", "method": "<entry point>", "weights": path | null,
     "sys_path": [dirs], "episodes": [[task, seed], ...],
     "numba_cache_sources": [dirs], "method_channel": {"read_fd": int, "write_fd": int} | null}

response::

    {"ok": true, "episodes": [{"task", "seed", "metrics": {...}}, ...]}
    {"ok": false, "kind": "memory" | "exception" | "bad_output", "message": str, "traceback": str}

When ``method_channel`` is given, the submitted method is not imported here: it runs in
a sandbox of its own (:mod:`swarmloc.bench.evaluation.remote_method`) and the runner gets a
stand-in that forwards every call over the channel, so the method can neither patch the
runner nor forge this response.

The runner is called as ``runner(method, episodes)`` (plus ``weights=path`` when a weights
file was submitted) and must return one ``{"task", "seed", "metrics"}`` mapping per episode.

Exit codes: 0 success, 2 bad invocation, 3 memory limit exceeded, 4 the runner or method
raised, 5 the runner returned malformed output. Only the standard library (and
``process_limits``, which imports nothing else) is imported at start-up, so the limits apply
to the method and runner, not to the worker's own set-up.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import sys
import traceback
from collections.abc import Mapping
from typing import Any

from swarmloc.bench.evaluation.process_limits import apply_limits, is_out_of_memory, seed_numba_cache

EXIT_OK = 0
EXIT_USAGE = 2
EXIT_MEMORY = 3
EXIT_EXCEPTION = 4
EXIT_BAD_OUTPUT = 5

_TRACEBACK_CHARS = 4000


class BadOutput(Exception):
    """The runner returned something that is not a list of episode results."""


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


def _failure(kind: str, err: BaseException) -> dict[str, Any]:
    # A method that failed in its own process brings its own traceback in the message;
    # the worker's (runner internals, then the pipe) would only repeat it.
    remote = type(err).__module__ == "swarmloc.bench.evaluation.remote_method"
    text = "" if remote else "".join(traceback.format_exception(err))
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
    method = request["method"]
    channel = request.get("method_channel")
    if channel:
        from swarmloc.bench.evaluation.remote_method import install_remote_method

        method = install_remote_method(method, int(channel["read_fd"]), int(channel["write_fd"]))
    runner = load_callable(request["runner"])
    episodes = [(str(task), int(seed)) for task, seed in request["episodes"]]
    kwargs = {"weights": request["weights"]} if request.get("weights") else {}
    try:
        output = runner(method, episodes, **kwargs)
    finally:
        if channel:
            from swarmloc.bench.evaluation.remote_method import close_remote_methods

            close_remote_methods()
    try:
        items = list(output)
    except TypeError:
        raise BadOutput(f"runner returned {type(output).__name__}; expected a list") from None
    return [normalize_episode(item) for item in items]


def _respond(fd: int, payload: Mapping[str, Any]) -> None:
    data = json.dumps(payload, allow_nan=True).encode("utf-8")
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]
    os.close(fd)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the worker process; see the module docstring."""
    parser = argparse.ArgumentParser(prog="python -m swarmloc.leaderboard.verify.worker")
    parser.add_argument("--response-fd", type=int, required=True, help="pipe for the JSON response")
    parser.add_argument("--memory-bytes", type=int, default=0, help="RLIMIT_AS cap (0: none)")
    parser.add_argument("--max-processes", type=int, default=0, help="RLIMIT_NPROC cap (0: none)")
    parser.add_argument("--max-file-bytes", type=int, default=0, help="RLIMIT_FSIZE cap (0: none)")
    args = parser.parse_args(argv)
    os.set_inheritable(args.response_fd, False)  # no process the runner starts gets the response pipe
    apply_limits(args.memory_bytes, args.max_processes, args.max_file_bytes)
    request = json.loads(sys.stdin.buffer.read())
    cache_dir = os.environ.get("NUMBA_CACHE_DIR")
    if cache_dir and request.get("numba_cache_sources"):
        seed_numba_cache(request["numba_cache_sources"], cache_dir)
    try:
        episodes = run(request)
    except BadOutput as err:
        _respond(args.response_fd, _failure("bad_output", err))
        return EXIT_BAD_OUTPUT
    except BaseException as err:  # noqa: BLE001 - any failure of submitted code is reported
        if is_out_of_memory(err):
            _respond(args.response_fd, _failure("memory", err))
            return EXIT_MEMORY
        _respond(args.response_fd, _failure("exception", err))
        return EXIT_EXCEPTION
    _respond(args.response_fd, {"ok": True, "episodes": episodes})
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
