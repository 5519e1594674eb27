"""Starting a verification re-run: the worker, the method, their sandboxes and the pipes between them.

A re-run is two processes, each in a bubblewrap sandbox of its own
(:mod:`swarmloc.leaderboard.verify.sandbox`):

* the **worker** (``python -m swarmloc.leaderboard.verify.worker``) runs the runner and
  computes the metrics; it reads its request on standard input and answers on a pipe
  that only it holds;
* the **method** (``python -m swarmloc.bench.evaluation.remote_method``) imports and runs the
  submitted code, and answers the worker's ``reset``/``act``/``step`` calls over a second
  pair of pipes. Registered (shipped) methods run inside the worker instead.

Each sees swarmloc, the Python environment and its own files read-only, a private tmp,
no network, its own PID namespace; each caps its memory, processes and file sizes
before running anything submitted; the parent kills both at the wall-time limit. With
``sandbox=False`` (a user's own method where bubblewrap is unavailable) the same two
processes run as plain subprocesses with a clean environment and the same limits.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from swarmloc.leaderboard.submit.entry_points import parse_entry_point
from swarmloc.leaderboard.errors import VerificationFailed
from swarmloc.leaderboard.verify.sandbox import SandboxCommand, package_folders, require_sandbox, sandbox_command, view_for

WORKER_MODULE: str = "swarmloc.leaderboard.verify.worker"
METHOD_MODULE: str = "swarmloc.bench.evaluation.remote_method"

SANDBOX_HOME: str = "/tmp"
"""``HOME`` and ``TMPDIR`` inside the sandbox (its private tmpfs)."""

_EXIT_MEMORY = 3
_MAX_RESPONSE_BYTES = 64 * 1024 * 1024
_LOG_TAIL_CHARS = 2000


@dataclass(frozen=True)
class VerifyLimits:
    """Resources the verification processes may use.

    Attributes:
        wall_time_s: Wall-clock seconds for the whole sample (start-up included).
        memory_bytes: Address-space cap (``RLIMIT_AS``) of the worker and of the method's
            process, each.
        max_processes: Processes and threads each sandbox may hold (``RLIMIT_NPROC``);
            numpy, numba and torch start about one thread per core each.
        max_file_bytes: Largest file either process may write, its captured standard
            output and error included (``RLIMIT_FSIZE``).
    """

    wall_time_s: float = 900.0
    memory_bytes: int = 8 * 1024**3
    max_processes: int = 1024
    max_file_bytes: int = 64 * 1024**2

    def __post_init__(self) -> None:
        if not self.wall_time_s > 0:
            raise ValueError(f"wall_time_s must be positive, got {self.wall_time_s}")
        if self.memory_bytes < 64 * 1024**2:
            raise ValueError(f"memory_bytes must be at least 64 MiB, got {self.memory_bytes}")
        if self.max_processes < 16:
            raise ValueError(f"max_processes must be at least 16, got {self.max_processes}")
        if self.max_file_bytes < 1024**2:
            raise ValueError(f"max_file_bytes must be at least 1 MiB, got {self.max_file_bytes}")


def worker_environment(home: Path | str, pythonpath: Sequence[str], *, sandboxed: bool = False) -> dict[str, str]:
    """The complete environment of a verification process: nothing inherited but ``PATH``.

    Args:
        home: Its ``HOME`` and ``TMPDIR``.
        pythonpath: Directories for ``PYTHONPATH``.
        sandboxed: Inside bubblewrap: numba's cache then goes to the private tmp
            (seeded from swarmloc's own caches), since the source folders are read-only.
    """
    env = {
        "PATH": os.environ.get("PATH", os.defpath),
        "HOME": str(home),
        "TMPDIR": str(home),
        "LANG": "C.UTF-8",
        "LC_ALL": "C.UTF-8",
        "PYTHONHASHSEED": "0",
        "PYTHONDONTWRITEBYTECODE": "1",
        "PYTHONNOUSERSITE": "1",
        # glibc reserves 64 MiB of address space per thread arena; keep RLIMIT_AS meaningful.
        "MALLOC_ARENA_MAX": "2",
    }
    if sandboxed:
        env["NUMBA_CACHE_DIR"] = f"{home}/numba-cache"
    if pythonpath:
        env["PYTHONPATH"] = os.pathsep.join(pythonpath)
    return env


def numba_cache_sources() -> list[str]:
    """Folders of swarmloc's sources that hold numba caches (``__pycache__/*.nbi``)."""
    sources = []
    for root in package_folders():
        for folder, dirs, files in os.walk(root):
            dirs[:] = [d for d in dirs if not d.startswith(".")]
            if os.path.basename(folder) == "__pycache__" and any(f.endswith(".nbi") for f in files):
                sources.append(os.path.dirname(folder))
    return sorted(sources)


def _tail(path: Path) -> str:
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return ""
    return text[-_LOG_TAIL_CHARS:].strip()


def _signal_name(code: int) -> str:
    try:
        return signal.Signals(-code).name
    except ValueError:
        return f"signal {-code}"


def _kill(proc: subprocess.Popen[bytes] | None) -> None:
    """SIGKILL a process group started with ``start_new_session`` and reap its leader.

    For a sandbox the leader is bubblewrap; its death takes the sandbox's PID namespace,
    and every process in it, down with it.
    """
    if proc is None:
        return
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    proc.wait()


class _ResponseReader(threading.Thread):
    """Drains the worker's response pipe (up to the size limit) while the parent waits."""

    def __init__(self, fd: int) -> None:
        super().__init__(daemon=True)
        self.fd, self.data, self.too_large = fd, b"", False

    def run(self) -> None:
        chunks, size = [], 0
        while chunk := os.read(self.fd, 1 << 20):
            size += len(chunk)
            if size > _MAX_RESPONSE_BYTES:
                self.too_large = True  # keep draining, so that the worker can finish and exit
            else:
                chunks.append(chunk)
        self.data = b"" if self.too_large else b"".join(chunks)
        os.close(self.fd)


@dataclass(frozen=True)
class _Plan:
    """The two commands of a re-run (sandboxed or plain) and their environments."""

    worker: SandboxCommand
    method: SandboxCommand | None
    worker_env: dict[str, str]
    method_env: dict[str, str]

    def close(self) -> None:
        """Close the descriptors the sandboxes were handed."""
        for command in (self.worker, self.method):
            if command is not None:
                command.close()


def _start(command: SandboxCommand, env: dict[str, str], cwd: Path, log_path: Path, stdin: int,
           fds: Sequence[int]) -> subprocess.Popen[bytes]:
    """Start one process of a re-run in its own session, its output to ``log_path``."""
    with open(log_path, "wb") as log:
        return subprocess.Popen(command.argv, env=env, cwd=cwd, stdin=stdin, stdout=log, stderr=subprocess.STDOUT,
                                start_new_session=True, pass_fds=(*fds, *command.pass_fds))


def _limit_args(limits: VerifyLimits) -> list[str]:
    return ["--memory-bytes", str(limits.memory_bytes), "--max-processes", str(limits.max_processes),
            "--max-file-bytes", str(limits.max_file_bytes)]


def _plan(python: str, limits: VerifyLimits, fds: dict[str, int], *, sandboxed: bool, tmp: Path,
          runner_path: Sequence[Path], method_path: Sequence[Path], method_files: Sequence[Path],
          store_file: Path | None, isolated: bool, cache_sources: Sequence[str]) -> _Plan:
    worker = [python, "-m", WORKER_MODULE, "--response-fd", str(fds["response"]), *_limit_args(limits)]
    method = None
    if isolated:
        method = [python, "-m", METHOD_MODULE, "--read-fd", str(fds["method_read"]),
                  "--write-fd", str(fds["method_write"]), *_limit_args(limits)]
        method += [arg for source in cache_sources for arg in ("--numba-cache-source", source)]
    worker_path = [str(p) for p in runner_path]
    method_pythonpath = [str(p) for p in method_path]
    if not sandboxed:
        homes = tmp / "worker-home", tmp / "method-home"
        for home in homes:
            home.mkdir()
        return _Plan(SandboxCommand(worker), None if method is None else SandboxCommand(method),
                     worker_environment(homes[0], worker_path),
                     {**worker_environment(homes[1], method_pythonpath), "NUMBA_NUM_THREADS": "1"})
    bwrap = require_sandbox(python)
    worker_view = view_for([*runner_path], store_file, python)
    method_view = view_for([*method_path, *method_files], store_file, python)
    worker_view.check()
    method_view.check()
    worker_command = sandbox_command(worker, worker_view, bwrap=bwrap, python=python)
    try:
        method_command = None if method is None else sandbox_command(method, method_view, bwrap=bwrap, python=python)
    except BaseException:
        worker_command.close()
        raise
    return _Plan(
        worker_command, method_command,
        worker_environment(SANDBOX_HOME, worker_path, sandboxed=True),
        {**worker_environment(SANDBOX_HOME, method_pythonpath, sandboxed=True), "NUMBA_NUM_THREADS": "1"},
    )


def _failure_message(method: str, n_episodes: int, code: int, response: Any, limits: VerifyLimits,
                     logs: dict[str, Path], oversized: bool) -> str:
    """Why a re-run produced no episodes, with the processes' own output."""
    mib = limits.memory_bytes / 1024**2
    notes = [
        f"its {who} output reached the {limits.max_file_bytes / 1024**2:.0f} MiB file-size limit"
        for who, path in logs.items() if path.exists() and path.stat().st_size >= limits.max_file_bytes
    ]
    method_log = _tail(logs["method"]) if "method" in logs else ""
    extra = "".join(f"\n({note})" for note in notes)
    extra += f"\nthe method's output (last lines):\n{method_log}" if method_log else ""
    if oversized:
        return (f"verification worker for method {method!r} sent a response over "
                f"{_MAX_RESPONSE_BYTES} bytes; refused" + extra)
    if isinstance(response, dict) and response.get("kind") == "memory" or code == _EXIT_MEMORY:
        detail = response.get("message") if isinstance(response, dict) else None
        return (f"method {method!r} exceeded the memory limit of {mib:.0f} MiB while re-running "
                f"{n_episodes} episode(s)" + (f" ({detail})" if detail else "") + extra)
    if isinstance(response, dict) and not response.get("ok", True):
        detail = response.get("traceback") or response.get("message") or ""
        what = "returned malformed output" if response.get("kind") == "bad_output" else "crashed"
        return (f"method {method!r} {what} during verification: {response.get('message')}\n"
                f"{detail}".rstrip() + extra)
    how = f"died with {_signal_name(code)}" if code < 0 else f"exited with status {code}"
    hint = f" (possibly the memory limit of {mib:.0f} MiB)" if code < 0 else ""
    return (f"verification worker for method {method!r} {how}{hint} without a result; "
            f"its output:\n{_tail(logs['worker']) or '(empty)'}" + extra)


def run_in_worker(
    method: str,
    episodes: Sequence[tuple[str, int]],
    *,
    weights: Path | None = None,
    runner: str,
    runner_path: Sequence[str | Path] = (),
    method_path: Sequence[str | Path] = (),
    limits: VerifyLimits = VerifyLimits(),
    sandbox: bool = True,
    store_file: Path | None = None,
    python: str = sys.executable,
) -> tuple[list[dict], float]:
    """Re-run episodes in the sandboxed worker (and method process) and return its results.

    Args:
        method: Entry point as in the results file.
        episodes: (task, seed) pairs to run.
        weights: Weights file handed to the method's factory.
        runner: ``module:function`` the worker calls.
        runner_path: Directories on the worker's ``PYTHONPATH`` (runner code).
        method_path: Directories on the method's ``PYTHONPATH`` (its modules).
        limits: Wall-time, memory, process and file-size limits.
        sandbox: Run inside bubblewrap (False: plain subprocesses, limits only).
        store_file: The store's SQLite file, kept out of the sandbox's view.
        python: Interpreter of both processes.

    Returns:
        ``(episodes, wall_seconds)`` where each episode is ``{"task", "seed", "metrics"}``.

    Raises:
        SandboxUnavailable: ``sandbox`` is True but bubblewrap cannot run here, or a
            needed path would expose the store or the user's home.
        VerificationFailed: a process crashed, ran out of time or memory, or returned
            malformed output; the message carries the error and the method's output.
    """
    entry = parse_entry_point(method)
    isolated = entry.kind != "registered"
    target = method
    method_files: list[Path] = []
    if entry.kind == "file" and entry.file is not None and entry.attr is not None:
        target = f"{entry.file.resolve()}:{entry.attr}"
        method_files.append(entry.file.resolve())
    if weights is not None:
        method_files.append(Path(weights).resolve())
    cache_sources = numba_cache_sources() if sandbox else []
    request = {
        "runner": runner,
        "method": target,
        "weights": str(Path(weights).resolve()) if weights is not None else None,
        "sys_path": [],
        "episodes": [[task, seed] for task, seed in episodes],
        "numba_cache_sources": cache_sources,
        "method_channel": None,
    }
    response_read, response_write = os.pipe()
    pipes = [response_write]
    fds = {"response": response_write}
    if isolated:
        to_method_read, to_method_write = os.pipe()
        to_worker_read, to_worker_write = os.pipe()
        pipes += [to_method_read, to_method_write, to_worker_read, to_worker_write]
        fds |= {"method_read": to_method_read, "method_write": to_worker_write}
        request["method_channel"] = {"read_fd": to_worker_read, "write_fd": to_method_write}
    worker_proc = method_proc = None
    plan: _Plan | None = None
    with tempfile.TemporaryDirectory(prefix="swarmloc-verify-") as tmp_name:
        tmp = Path(tmp_name)
        logs = {"worker": tmp / "worker.log"} | ({"method": tmp / "method.log"} if isolated else {})
        try:
            plan = _plan(python, limits, fds, sandboxed=sandbox, tmp=tmp,
                         runner_path=[Path(p).resolve() for p in runner_path],
                         method_path=[Path(p).resolve() for p in method_path],
                         method_files=method_files, store_file=store_file, isolated=isolated,
                         cache_sources=cache_sources)
            started = time.monotonic()
            if plan.method is not None:
                method_proc = _start(plan.method, plan.method_env, tmp, logs["method"], subprocess.DEVNULL,
                                     (fds["method_read"], fds["method_write"]))
            worker_pass = (response_write, *((to_worker_read, to_method_write) if isolated else ()))
            worker_proc = _start(plan.worker, plan.worker_env, tmp, logs["worker"], subprocess.PIPE, worker_pass)
        except BaseException:
            _kill(method_proc)
            os.close(response_read)
            raise
        finally:
            for fd in pipes:  # the children hold their ends now
                os.close(fd)
            if plan is not None:
                plan.close()
        reader = _ResponseReader(response_read)
        reader.start()
        try:
            assert worker_proc.stdin is not None
            try:
                worker_proc.stdin.write(json.dumps(request).encode("utf-8"))
                worker_proc.stdin.close()
            except BrokenPipeError:
                pass  # the worker died at start-up; its exit status says why
            try:
                code = worker_proc.wait(timeout=limits.wall_time_s)
            except subprocess.TimeoutExpired:
                raise VerificationFailed(
                    f"method {method!r} exceeded the wall-time limit of {limits.wall_time_s:g} s "
                    f"while re-running {len(episodes)} episode(s); it was killed"
                ) from None
        finally:
            _kill(worker_proc)
            _kill(method_proc)
            # The pipe closes with the worker's sandbox; unsandboxed, a process it left
            # behind could hold it open, so the wait is bounded (the response is then cut).
            reader.join(timeout=10)
        wall = time.monotonic() - started
        response = None
        if not reader.too_large:
            try:
                response = json.loads(reader.data.decode("utf-8"))
            except (json.JSONDecodeError, UnicodeDecodeError):
                response = None
        if code == 0 and isinstance(response, dict) and response.get("ok"):
            return list(response.get("episodes", [])), wall
        raise VerificationFailed(
            _failure_message(method, len(episodes), code, response, limits, logs, reader.too_large)
        )


__all__ = [
    "METHOD_MODULE",
    "SANDBOX_HOME",
    "WORKER_MODULE",
    "VerifyLimits",
    "numba_cache_sources",
    "run_in_worker",
    "worker_environment",
]
