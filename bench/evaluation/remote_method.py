"""The submitted method in a sandbox of its own, driven by the verification worker over two pipes.

During verification the runner and the metrics run in the worker's sandbox, the submitted
method in a second one (``python -m swarmloc.bench.evaluation.remote_method``), and the two
share nothing but a pair of pipes that the parent created. Whatever the method does in
its process — patch the runner, rewrite metric functions, write a response file, kill
its parent — touches only its own sandbox: the worker computes every metric itself from
the actions the method returns.

Wire format, one frame per message (4-byte big-endian length, then the payload):

* worker → method: a pickle of ``(operation, arguments)``. Only the worker writes these,
  so only trusted data is unpickled (by the method's process).
* method → worker: a JSON header (4-byte length, UTF-8) followed by the arrays it lists,
  each in ``.npy`` format read with ``allow_pickle=False``: the worker never unpickles
  anything the method sends, and accepts only boolean and numeric arrays.

Operations: ``load(entry_point, weights)`` → a handle and the method's declared track,
privileged and deterministic flags; ``reset``, ``act``, ``step`` and ``observe_privileged``
on a handle, as in :mod:`swarmloc.agents.protocols`. An exception in the method comes
back as its type name, message and traceback; running out of memory stays a
``MemoryError``, and in ``reset`` ``ValueError`` and ``NotImplementedError`` keep their type
(the runner reads them as "cannot run this task").
"""

from __future__ import annotations

import argparse
import io
import json
import os
import pickle
import struct
import sys
import traceback
from collections.abc import Sequence
from typing import Any

import numpy as np

MAX_REPLY_BYTES: int = 64 * 1024**2
"""Largest message the worker accepts from the method."""

_HEADER = struct.Struct(">I")
_TEXT_CHARS = 4000
_ARRAY_KINDS = "biuf"  # bool, signed, unsigned, float: no objects, strings or records


class MethodFailed(RuntimeError):
    """The method raised (in its own process); the message carries its traceback."""


class MethodProtocolError(RuntimeError):
    """The method's process sent something that is not a valid reply, or closed its pipe."""


# --------------------------------------------------------------------------- frames


def write_frame(fd: int, payload: bytes) -> None:
    """Write one length-prefixed frame to a file descriptor."""
    view = memoryview(_HEADER.pack(len(payload)) + payload)
    while view:
        view = view[os.write(fd, view):]


def _read_exact(fd: int, size: int) -> bytes | None:
    chunks, left = [], size
    while left:
        chunk = os.read(fd, min(left, 1 << 20))
        if not chunk:
            return None
        chunks.append(chunk)
        left -= len(chunk)
    return b"".join(chunks)


def read_frame(fd: int, limit: int | None = None) -> bytes | None:
    """One frame's payload, or None when the pipe closed.

    Raises:
        MethodProtocolError: the announced length exceeds ``limit``, or the pipe closed
            in the middle of a frame.
    """
    head = _read_exact(fd, _HEADER.size)
    if head is None:
        return None
    (size,) = _HEADER.unpack(head)
    if limit is not None and size > limit:
        raise MethodProtocolError(f"the method sent a {size}-byte message; the limit is {limit} bytes")
    payload = _read_exact(fd, size)
    if payload is None:
        raise MethodProtocolError("the method's pipe closed in the middle of a message")
    return payload


def encode_reply(header: dict[str, Any], arrays: Sequence[np.ndarray | None] = ()) -> bytes:
    """A reply: JSON header (with ``arrays``: the length of each ``.npy`` blob, -1 for None)."""
    blobs = []
    for array in arrays:
        if array is None:
            blobs.append(b"")
            continue
        buffer = io.BytesIO()
        np.save(buffer, np.ascontiguousarray(array), allow_pickle=False)
        blobs.append(buffer.getvalue())
    header = {**header, "arrays": [len(b) if a is not None else -1 for a, b in zip(arrays, blobs)]}
    text = json.dumps(header).encode("utf-8")
    return _HEADER.pack(len(text)) + text + b"".join(blobs)


def decode_reply(payload: bytes) -> tuple[dict[str, Any], list[np.ndarray | None]]:
    """Parse a reply without unpickling anything.

    Raises:
        MethodProtocolError: malformed header, lengths that do not add up, or an array
            that is not boolean or numeric.
    """
    try:
        (size,) = _HEADER.unpack_from(payload)
        header = json.loads(payload[_HEADER.size:_HEADER.size + size].decode("utf-8"))
        if not isinstance(header, dict) or not isinstance(header.get("arrays"), list):
            raise TypeError("header is not an object with an 'arrays' list")
        lengths = header["arrays"]
        arrays: list[np.ndarray | None] = []
        offset = _HEADER.size + size
        for length in lengths:
            if length == -1:
                arrays.append(None)
                continue
            if not isinstance(length, int) or length < 0 or offset + length > len(payload):
                raise ValueError(f"array length {length!r} does not fit the {len(payload)}-byte message")
            array = np.lib.format.read_array(io.BytesIO(payload[offset:offset + length]), allow_pickle=False)
            if array.dtype.kind not in _ARRAY_KINDS:
                raise TypeError(f"the method returned an array of dtype {array.dtype}; "
                                f"only boolean and numeric arrays are allowed")
            arrays.append(array)
            offset += length
    except MethodProtocolError:
        raise
    except Exception as err:  # noqa: BLE001 - anything malformed is the method's fault
        raise MethodProtocolError(f"malformed reply from the method's process: {err}") from None
    return header, arrays


# --------------------------------------------------------------------------- the method's side


def _error_header(err: BaseException) -> dict[str, Any]:
    from swarmloc.agents.protocols import UnsupportedTask
    from swarmloc.bench.evaluation.process_limits import is_out_of_memory

    if is_out_of_memory(err):
        kind = "memory"
    elif isinstance(err, UnsupportedTask):
        kind = "unsupported"
    elif isinstance(err, NotImplementedError):
        kind = "not_implemented"
    elif isinstance(err, ValueError):
        kind = "value"
    else:
        kind = "other"
    return {
        "ok": False, "kind": kind, "type": type(err).__name__,
        "message": str(err)[:_TEXT_CHARS],
        "traceback": "".join(traceback.format_exception(err))[-_TEXT_CHARS:],
    }


def _flops_per_channel(method: Any) -> float | None:
    value = getattr(method, "flops_per_channel", None)
    return None if value is None else float(value)


def _handle(instances: dict[int, Any], operation: str, args: tuple[Any, ...]) -> bytes:
    """Run one operation on the method; the reply to send back."""
    from swarmloc.agents.protocols import EstimatorOutput
    from swarmloc.agents.registry import load_method

    if operation == "load":
        entry_point, weights, version = args
        loaded = load_method(entry_point, weights, version)
        handle = len(instances) + 1
        instances[handle] = loaded
        return encode_reply({
            "ok": True, "handle": handle, "track": loaded.track, "name": loaded.name,
            "privileged": loaded.privileged, "deterministic": loaded.deterministic,
            "flops_per_channel": _flops_per_channel(loaded.method),
        })
    handle, *rest = args
    loaded = instances[handle]
    method = loaded.method
    if operation == "reset":
        method.reset(*rest)
        return encode_reply({"ok": True, "flops_per_channel": _flops_per_channel(method)})
    if operation == "observe_privileged":
        method.observe_privileged(*rest)
        return encode_reply({"ok": True})
    if operation == "act":
        return encode_reply({"ok": True}, [np.asarray(method.act(*rest))])
    if operation == "step":
        out = method.step(*rest)
        if not isinstance(out, EstimatorOutput):
            raise TypeError(f"estimator {loaded.name!r} returned {type(out).__name__}; expected EstimatorOutput")
        fields = (out.positions, out.cov, out.weights, out.flops)
        return encode_reply({"ok": True}, [None if f is None else np.asarray(f) for f in fields])
    raise ValueError(f"unknown operation {operation!r}; known: load, reset, observe_privileged, act, step")


def serve(read_fd: int, write_fd: int) -> int:
    """Answer the worker's requests until it closes the pipe; the method's process main loop."""
    instances: dict[int, Any] = {}
    while True:
        payload = read_frame(read_fd)
        if payload is None:
            return 0
        operation, args = pickle.loads(payload)
        try:
            reply = _handle(instances, operation, args)
        except BaseException as err:  # noqa: BLE001 - every failure of the method is reported
            reply = encode_reply(_error_header(err))
        write_frame(write_fd, reply)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the method's process: limits first, then the request loop."""
    from swarmloc.bench.evaluation.process_limits import apply_limits, seed_numba_cache

    parser = argparse.ArgumentParser(prog="python -m swarmloc.bench.evaluation.remote_method")
    parser.add_argument("--read-fd", type=int, required=True)
    parser.add_argument("--write-fd", type=int, required=True)
    parser.add_argument("--memory-bytes", type=int, default=0)
    parser.add_argument("--max-processes", type=int, default=0)
    parser.add_argument("--max-file-bytes", type=int, default=0)
    parser.add_argument("--numba-cache-source", action="append", default=[])
    args = parser.parse_args(argv)
    apply_limits(args.memory_bytes, args.max_processes, args.max_file_bytes)
    cache_dir = os.environ.get("NUMBA_CACHE_DIR")
    if cache_dir and args.numba_cache_source:
        seed_numba_cache(args.numba_cache_source, cache_dir)
    return serve(args.read_fd, args.write_fd)


# --------------------------------------------------------------------------- the worker's side


class MethodChannel:
    """The worker's end of the pipes to the method's process."""

    def __init__(self, read_fd: int, write_fd: int) -> None:
        self.read_fd, self.write_fd = read_fd, write_fd

    def call(self, operation: str, *args: Any) -> tuple[dict[str, Any], list[np.ndarray | None]]:
        """Send one operation and wait for its reply.

        Raises:
            MethodFailed: the method raised (``ValueError``, ``NotImplementedError`` and
                ``UnsupportedTask`` from ``reset`` keep their type).
            MethodProtocolError: the method's process died, closed its pipe, or replied
                with something malformed.
        """
        try:
            write_frame(self.write_fd, pickle.dumps((operation, args), protocol=pickle.HIGHEST_PROTOCOL))
            payload = read_frame(self.read_fd, MAX_REPLY_BYTES)
        except OSError as err:
            raise MethodProtocolError(
                f"the method's process is gone ({err.strerror}) during {operation}(); it exited, "
                f"was killed, or ran out of its limits"
            ) from None
        if payload is None:
            raise MethodProtocolError(
                f"the method's process closed its pipe during {operation}(); it exited, was killed, "
                f"or ran out of its limits"
            )
        header, arrays = decode_reply(payload)
        if header.get("ok") is True:
            return header, arrays
        raise self._error(operation, header)

    @staticmethod
    def _error(operation: str, header: dict[str, Any]) -> Exception:
        message = str(header.get("message", ""))[:_TEXT_CHARS]
        text = (f"the method raised {str(header.get('type', 'an error'))[:100]} in {operation}(): {message}\n"
                f"--- traceback in the method's process ---\n{str(header.get('traceback', ''))[-_TEXT_CHARS:]}")
        kind = header.get("kind")
        if kind == "memory":
            return MemoryError(text)
        if operation == "reset":
            if kind == "unsupported":
                from swarmloc.agents.protocols import UnsupportedTask

                return UnsupportedTask(message)
            if kind == "not_implemented":
                return NotImplementedError(message)
            if kind == "value":
                return ValueError(message)
        return MethodFailed(text)


class _RemoteMethod:
    """Attributes every stand-in shares: what the method declared when it was loaded."""

    def __init__(self, channel: MethodChannel, header: dict[str, Any]) -> None:
        self._channel = channel
        self._handle = int(header["handle"])
        self.name = str(header.get("name", "method"))[:128]
        self.privileged = bool(header.get("privileged", False))
        self.deterministic = bool(header.get("deterministic", True))
        self._set_flops(header)

    def _set_flops(self, header: dict[str, Any]) -> None:
        value = header.get("flops_per_channel")
        if value is None:
            self.__dict__.pop("flops_per_channel", None)
        else:
            self.flops_per_channel = float(value)

    def observe_privileged(self, info: Any) -> None:
        self._channel.call("observe_privileged", self._handle, info)


class RemotePolicy(_RemoteMethod):
    """A Track A link-trust policy running in the method's process."""

    def reset(self, batch_size: int, layout: Any, keys: np.ndarray) -> None:
        header, _ = self._channel.call("reset", self._handle, batch_size, layout, keys)
        self._set_flops(header)

    def act(self, inp: Any) -> np.ndarray:
        _, arrays = self._channel.call("act", self._handle, inp)
        return arrays[0]


class RemoteEstimator(_RemoteMethod):
    """A Track B estimator running in the method's process."""

    def reset(self, facts: Any, x0: np.ndarray) -> None:
        header, _ = self._channel.call("reset", self._handle, facts, x0)
        self._set_flops(header)

    def step(self, meas: Any) -> Any:
        from swarmloc.agents.protocols import EstimatorOutput

        _, arrays = self._channel.call("step", self._handle, meas)
        if len(arrays) != 4 or arrays[0] is None:
            raise MethodProtocolError("the method's step() reply lacks the positions array")
        positions, cov, weights, flops = arrays
        return EstimatorOutput(positions=positions, cov=cov, weights=weights, flops=flops)


class RemoteFactory:
    """What the runner imports instead of the submitted factory: loads the method remotely."""

    def __init__(self, entry_point: str, channel: MethodChannel) -> None:
        self.entry_point, self.channel = entry_point, channel

    def __call__(self, weights: str | None = None, version: int | None = None) -> RemotePolicy | RemoteEstimator:
        header, _ = self.channel.call("load", self.entry_point, weights, version)
        if header.get("track") == "A":
            return RemotePolicy(self.channel, header)
        if header.get("track") == "B":
            return RemoteEstimator(self.channel, header)
        raise MethodProtocolError(f"the method's process reported track {header.get('track')!r}; expected 'A' or 'B'")


REMOTE_MODULE: str = "swarmloc_remote_method"
"""Module name under which the worker registers the stand-in factory for the runner."""

_CHANNELS: list[MethodChannel] = []


def install_remote_method(entry_point: str, read_fd: int, write_fd: int) -> str:
    """Register a stand-in factory for ``entry_point``; the method string to give the runner."""
    import types

    for fd in (read_fd, write_fd):
        os.set_inheritable(fd, False)  # the pipes are the worker's alone
    channel = MethodChannel(read_fd, write_fd)
    _CHANNELS.append(channel)
    module = types.ModuleType(REMOTE_MODULE, "Stand-in for the submitted method (see method_process).")
    module.make = RemoteFactory(entry_point, channel)  # type: ignore[attr-defined]
    sys.modules[REMOTE_MODULE] = module
    return f"{REMOTE_MODULE}:make"


def close_remote_methods() -> None:
    """Close the pipes to the method's process (it exits when it reads end-of-file)."""
    while _CHANNELS:
        channel = _CHANNELS.pop()
        for fd in (channel.read_fd, channel.write_fd):
            try:
                os.close(fd)
            except OSError:
                pass


__all__ = [
    "MAX_REPLY_BYTES",
    "MethodChannel",
    "MethodFailed",
    "MethodProtocolError",
    "RemoteEstimator",
    "RemoteFactory",
    "RemotePolicy",
    "close_remote_methods",
    "decode_reply",
    "encode_reply",
    "install_remote_method",
    "read_frame",
    "serve",
    "write_frame",
]


if __name__ == "__main__":
    sys.exit(main())
