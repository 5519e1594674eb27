"""Hostile submission: a method that opens network connections during verification.

The test listens on the host's loopback; the method connects to that port, to an outside
address and to a Unix socket beside its file. The sandbox has its own network namespace
(only an isolated loopback), so every attempt fails and the listener sees no connection.
"""

from __future__ import annotations

import socket
from pathlib import Path

import lb_hostile
import pytest

pytestmark = pytest.mark.slow


def test_no_connection_leaves_the_sandbox(tmp_path: Path) -> None:
    lb_hostile.require_sandbox()
    hostile = lb_hostile.Hostile.create(tmp_path)
    listener = socket.create_server(("127.0.0.1", 0))
    listener.setblocking(False)
    unix_path = tmp_path / "s.sock"
    unix_listener = socket.socket(socket.AF_UNIX)
    unix_listener.bind(str(unix_path))
    unix_listener.listen()
    unix_listener.setblocking(False)
    port = listener.getsockname()[1]
    entry = hostile.method(f"""
        import socket
        report = []
        for address in (("127.0.0.1", {port}), ("1.1.1.1", 53)):
            try:
                socket.create_connection(address, timeout=3).sendall(b"stolen")
                report.append(f"{{address}}: connected")
            except OSError as err:
                report.append(f"{{address}}: {{err.strerror or err}}")
        try:
            client = socket.socket(socket.AF_UNIX)
            client.connect({str(unix_path)!r})
            report.append("unix: connected")
        except OSError as err:
            report.append(f"unix: {{err.strerror}}")
        raise RuntimeError("network: " + "; ".join(report))
    """)
    try:
        done = hostile.submit(entry)
        for server in (listener, unix_listener):
            with pytest.raises(BlockingIOError):
                server.accept()  # nobody ever connected
    finally:
        listener.close()
        unix_listener.close()
    hostile.assert_refused(done, f"('127.0.0.1', {port}): Connection refused",
                           "('1.1.1.1', 53): Network is unreachable",
                           "unix: No such file or directory")
