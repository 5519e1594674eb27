"""Reader for the Crazyflie µSD-card event log (``usddeck`` firmware), formats v1 and v2.

A log is one little-endian byte stream:

=========  ==================================================================
header     ``u8`` magic ``0xBC``, ``u16`` format version (1 or 2), ``u16`` number
           of event types E, then E descriptors: ``u16`` event id, the event
           name (NUL-terminated), ``u16`` number of variables V, and V variable
           descriptors ``"group.name(T)"`` (NUL-terminated), T a Python
           ``struct`` type character (``B b H h I i f e``).
records    ``u16`` event id, the timestamp, then the variables packed in the
           declared order with no padding. v1 timestamps are ``u32``
           milliseconds (FreeRTOS ticks); v2 timestamps are ``u64`` microseconds.
trailer    ``u32`` CRC-32 (IEEE 802.3, as ``zlib.crc32``) of every byte before it.
=========  ==================================================================

Records of different event types interleave, so their boundaries are found by one
walk over the event ids; the payloads are then decoded per event type in one
vectorized gather through a packed numpy structured dtype.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = [
    "MAGIC",
    "EventType",
    "UsdLog",
    "UsdLogChecksumError",
    "UsdLogError",
    "decode_usd_log",
    "read_usd_log",
]

MAGIC = 0xBC

# struct type character -> little-endian numpy type, as written by the firmware
_TYPE_CODES: dict[str, str] = {
    "B": "<u1",
    "b": "<i1",
    "H": "<u2",
    "h": "<i2",
    "I": "<u4",
    "i": "<i4",
    "f": "<f4",
    "e": "<f2",
}

# format version -> (record timestamp type, microseconds per timestamp tick)
_TIMESTAMP_FORMATS: dict[int, tuple[str, int]] = {
    1: ("<u4", 1000),
    2: ("<u8", 1),
}

_PREAMBLE = struct.Struct("<BHH")
_TRAILER = struct.Struct("<I")
_U16 = struct.Struct("<H")


class UsdLogError(ValueError):
    """The bytes are not a well-formed Crazyflie µSD event log.

    The message names the byte offset and what was expected there.
    """


class UsdLogChecksumError(UsdLogError):
    """The CRC-32 trailer does not match the data: the log is corrupt or truncated."""


@dataclass(frozen=True)
class EventType:
    """One event type declared in the log header.

    Attributes:
        event_id: the id that prefixes each record of this type.
        name: the event name, e.g. ``"estGyroscope"``.
        variables: ``(name, type character)`` per variable, in record order.
    """

    event_id: int
    name: str
    variables: tuple[tuple[str, str], ...]

    @property
    def payload_dtype(self) -> np.dtype:
        """Packed (unaligned) numpy dtype of the variables of one record."""
        return np.dtype([(name, _TYPE_CODES[code]) for name, code in self.variables])


@dataclass(frozen=True)
class UsdLog:
    """A decoded µSD event log.

    Attributes:
        version: the format version of the file (1 or 2).
        event_types: the event types in header order.
        events: per event name, a structured array of its records in file order,
            with field ``timestamp_us`` (``uint64``, µs since boot; v1 milliseconds are
            scaled by 1000) followed by one field per variable, named as logged
            (e.g. ``"gyro.x"``). Declared events without records give empty arrays.
    """

    version: int
    event_types: tuple[EventType, ...]
    events: dict[str, np.ndarray]


def read_usd_log(path: str | Path, *, check_crc: bool = True) -> UsdLog:
    """Read and decode a Crazyflie µSD event log file.

    Args:
        path: the binary log as written by the µSD deck (e.g. ``log00``).
        check_crc: verify the CRC-32 trailer before decoding (default). Turn off
            only to inspect a damaged log; the record structure is still checked.

    Returns:
        The decoded log.

    Raises:
        UsdLogError: the file is not a well-formed v1/v2 log (the message names the
            offset and what was expected); ``UsdLogChecksumError`` for a CRC mismatch.
    """
    return decode_usd_log(Path(path).read_bytes(), check_crc=check_crc)


def decode_usd_log(data: bytes, *, check_crc: bool = True) -> UsdLog:
    """Decode the bytes of a Crazyflie µSD event log.

    Args:
        data: the whole file content.
        check_crc: verify the CRC-32 trailer before decoding (default).

    Returns:
        The decoded log.

    Raises:
        UsdLogError: malformed header or records, unsupported version; the message
            names the offset and what was expected. ``UsdLogChecksumError`` when the
            CRC-32 trailer does not match.
    """
    minimum = _PREAMBLE.size + _TRAILER.size
    if len(data) < minimum:
        raise UsdLogError(
            f"log is {len(data)} bytes; a µSD event log needs at least {minimum} "
            "(magic, version, event count, CRC-32 trailer)"
        )
    magic, version, n_event_types = _PREAMBLE.unpack_from(data, 0)
    if magic != MAGIC:
        raise UsdLogError(f"offset 0: magic byte is 0x{magic:02X}, expected 0x{MAGIC:02X}")
    if version not in _TIMESTAMP_FORMATS:
        raise UsdLogError(
            f"offset 1: format version {version} is not supported; "
            f"allowed versions: {sorted(_TIMESTAMP_FORMATS)}"
        )
    end = len(data) - _TRAILER.size
    if check_crc:
        _check_crc(data, end)
    event_types, offset = _parse_header(data, n_event_types, end)
    timestamp_code, tick_us = _TIMESTAMP_FORMATS[version]
    offsets = _record_offsets(data, offset, end, event_types, np.dtype(timestamp_code).itemsize)
    events = {
        et.name: _gather(data, offsets[et.event_id], et, timestamp_code, tick_us)
        for et in event_types
    }
    return UsdLog(version=version, event_types=event_types, events=events)


def _check_crc(data: bytes, end: int) -> None:
    (expected,) = _TRAILER.unpack_from(data, end)
    actual = zlib.crc32(memoryview(data)[:end])
    if actual != expected:
        raise UsdLogChecksumError(
            f"CRC-32 mismatch: trailer at offset {end} holds 0x{expected:08X} but the "
            f"{end} bytes before it give 0x{actual:08X}; the log is corrupt or truncated"
        )


def _parse_header(data: bytes, n_event_types: int, end: int) -> tuple[tuple[EventType, ...], int]:
    """Parse the event descriptors; return them and the offset of the first record."""
    offset = _PREAMBLE.size
    event_types: list[EventType] = []
    for _ in range(n_event_types):
        event_id, offset = _read_u16(data, offset, end, "event id")
        name, offset = _read_cstring(data, offset, end, "event name")
        n_variables, offset = _read_u16(data, offset, end, f"variable count of event {name!r}")
        variables = []
        for _ in range(n_variables):
            start = offset
            descriptor, offset = _read_cstring(data, offset, end, f"variable of event {name!r}")
            variables.append(_parse_variable(descriptor, start))
        names = [v for v, _ in variables]
        if len(set(names)) != len(names) or "timestamp_us" in names:
            raise UsdLogError(
                f"event {name!r} declares variables {names}: names must be unique "
                "and not 'timestamp_us'"
            )
        event_types.append(EventType(event_id, name, tuple(variables)))
    ids = [et.event_id for et in event_types]
    names = [et.name for et in event_types]
    if len(set(ids)) != len(ids) or len(set(names)) != len(names):
        raise UsdLogError(f"header declares duplicate event ids or names: ids {ids}, names {names}")
    return tuple(event_types), offset


def _parse_variable(descriptor: str, offset: int) -> tuple[str, str]:
    """Split ``"group.name(T)"`` into ``("group.name", "T")``."""
    name, code = descriptor[:-3], descriptor[-2:-1]
    if len(descriptor) < 4 or descriptor[-3] != "(" or descriptor[-1] != ")":
        raise UsdLogError(
            f"offset {offset}: variable descriptor {descriptor!r} is not of the form 'name(T)'"
        )
    if code not in _TYPE_CODES:
        raise UsdLogError(
            f"offset {offset}: variable {name!r} has type {code!r}; "
            f"allowed types: {''.join(_TYPE_CODES)}"
        )
    return name, code


def _read_u16(data: bytes, offset: int, end: int, what: str) -> tuple[int, int]:
    if offset + _U16.size > end:
        raise UsdLogError(
            f"offset {offset}: expected the {what} (u16), "
            f"but the header runs past the data end at {end}"
        )
    return _U16.unpack_from(data, offset)[0], offset + _U16.size


def _read_cstring(data: bytes, offset: int, end: int, what: str) -> tuple[str, int]:
    nul = data.find(b"\x00", offset, end)
    if nul < 0:
        raise UsdLogError(
            f"offset {offset}: expected the {what} (NUL-terminated), "
            f"found no NUL before the data end at {end}"
        )
    try:
        text = data[offset:nul].decode("ascii")
    except UnicodeDecodeError:
        raw = data[offset:nul]
        raise UsdLogError(f"offset {offset}: the {what} {raw!r} is not ASCII") from None
    return text, nul + 1


def _record_offsets(
    data: bytes,
    offset: int,
    end: int,
    event_types: tuple[EventType, ...],
    timestamp_size: int,
) -> dict[int, np.ndarray]:
    """Walk the records from ``offset`` to ``end``; return record offsets per event id."""
    record_size = {
        et.event_id: _U16.size + timestamp_size + et.payload_dtype.itemsize for et in event_types
    }
    found: dict[int, list[int]] = {event_id: [] for event_id in record_size}
    while offset < end:
        if offset + _U16.size > end:
            raise UsdLogError(
                f"offset {offset}: expected a record (u16 event id), but only "
                f"{end - offset} byte(s) remain before the CRC-32 trailer at {end}"
            )
        event_id = data[offset] | data[offset + 1] << 8
        size = record_size.get(event_id)
        if size is None:
            raise UsdLogError(
                f"offset {offset}: record has event id {event_id}; "
                f"the header declares ids {sorted(record_size)}"
            )
        found[event_id].append(offset)
        offset += size
    if offset != end:
        last = found[event_id][-1]
        raise UsdLogError(
            f"offset {last}: record of event id {event_id} needs {record_size[event_id]} bytes "
            f"but the data ends at {end} (before the CRC-32 trailer); the log is truncated"
        )
    return {event_id: np.asarray(offs, dtype=np.int64) for event_id, offs in found.items()}


def _gather(
    data: bytes, offsets: np.ndarray, event_type: EventType, timestamp_code: str, tick_us: int
) -> np.ndarray:
    """Decode the records at ``offsets`` into a structured array (see ``UsdLog.events``)."""
    payload = event_type.payload_dtype
    record = np.dtype(
        [("event_id", "<u2"), ("timestamp", timestamp_code)]
        + [(name, payload.fields[name][0]) for name in payload.names]
    )
    raw = np.frombuffer(data, dtype=np.uint8)
    rows = raw[offsets[:, None] + np.arange(record.itemsize)]
    records = rows.view(record).reshape(len(offsets))
    out = np.empty(len(offsets), dtype=[("timestamp_us", "<u8")] + payload.descr)
    out["timestamp_us"] = records["timestamp"].astype(np.uint64) * np.uint64(tick_us)
    for name in payload.names:
        out[name] = records[name]
    return out
