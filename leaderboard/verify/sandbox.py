"""The sandbox around verification runs: bubblewrap (``bwrap``) on Linux.

Submitted code runs only inside :func:`sandbox_command`'s wrapper, which gives it

* a **read-only root** built from scratch: the system directories (``/usr`` and its
  ``/bin``, ``/lib`` links), a few loader files from ``/etc``, the Python installation and
  its virtual environment, swarmloc's own packages, and the paths the caller names (the
  method's file or search path, the runner's path, the weights file) — nothing else, so
  neither the store, the user's home, nor the data directory is there to read;
* a **private writable tmp** (``/tmp``, also ``HOME``) and ``/dev/shm``, both size-capped
  tmpfs that vanish with the sandbox;
* **no network** (a new network namespace holds only a down loopback device);
* **its own PID namespace** (it sees and can signal only its own processes; when the
  run ends, the namespace's init exits and the kernel kills whatever is left), a new
  session (no terminal to inject into), no capabilities, no further user namespaces,
  and death with its parent. Started by root, the sandbox runs as a real ``nobody``
  (:mod:`swarmloc.leaderboard.verify.sandbox_userns`), since root is exempt from the
  process-count limit.

Memory, process-count and file-size limits are ``setrlimit`` calls made by the worker
on itself before it imports submitted code (:mod:`swarmloc.leaderboard.verify.worker`);
the wall-time limit is the parent's (:mod:`swarmloc.leaderboard.verify.verification`).

bubblewrap needs unprivileged user namespaces. Where it is missing or cannot
create them, :func:`require_sandbox` raises :class:`SandboxUnavailable` naming the tool,
the reason, and the opt-in (``--no-sandbox``) that runs a user's own method with the time
and memory limits only.
"""

from __future__ import annotations

import functools
import importlib.util
import os
import shutil
import subprocess
import sys
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from swarmloc.leaderboard.errors import SandboxUnavailable
from swarmloc.leaderboard.verify.sandbox_userns import DROP_TO_NOBODY, UserNamespaceError, user_namespace_for_root

BWRAP: str = "bwrap"
"""The bubblewrap executable (Debian/Ubuntu package ``bubblewrap``)."""

SANDBOX_UID: int = 65534
"""User and group ID inside the sandbox (``nobody``)."""

SWARMLOC_PACKAGES: tuple[str, ...] = (
    "swarmloc.envs", "swarmloc.agents", "swarmloc.bench", "swarmloc.leaderboard",
)
"""Packages whose source folders the worker imports (bound read-only)."""

# Top-level system folders: bound read-only when they are folders, recreated when links
# (merged-/usr systems link /bin, /lib, ... into /usr).
_SYSTEM_DIRS: tuple[str, ...] = ("/usr", "/bin", "/sbin", "/lib", "/lib32", "/lib64", "/libx32")
# What the dynamic loader and libc read from /etc; no passwords, no host names.
_SYSTEM_ETC: tuple[str, ...] = (
    "/etc/ld.so.cache", "/etc/ld.so.conf", "/etc/ld.so.conf.d", "/etc/alternatives", "/etc/localtime",
)
_INSTALL_HINT = "install it (Debian/Ubuntu: apt-get install bubblewrap; Fedora: dnf install bubblewrap)"
_OPT_IN = (
    "to verify your own method on your own store without the sandbox (time and memory limits "
    "only), pass --no-sandbox (sandbox=False)"
)


@dataclass(frozen=True)
class SandboxLimits:
    """Sizes of the sandbox's private file systems.

    Attributes:
        tmp_bytes: Size of the private ``/tmp`` (the method's ``HOME`` and ``TMPDIR``).
        shm_bytes: Size of ``/dev/shm``.
    """

    tmp_bytes: int = 512 * 1024**2
    shm_bytes: int = 64 * 1024**2

    def __post_init__(self) -> None:
        for name in ("tmp_bytes", "shm_bytes"):
            value = getattr(self, name)
            if value < 1024**2:
                raise ValueError(f"{name} must be at least 1 MiB, got {value}")


@dataclass(frozen=True)
class SandboxView:
    """What the sandboxed run sees of the host, all read-only at the same paths.

    Attributes:
        readable: Files and folders bound read-only (missing ones are skipped).
        protected: Paths that must stay invisible (the store, home, the data folder);
            a readable path that contains one of them is refused.
    """

    readable: tuple[Path, ...]
    protected: tuple[Path, ...] = field(default=())

    def check(self) -> None:
        """Refuse a readable path that would expose a protected one.

        Raises:
            SandboxUnavailable: naming the readable path and what it would expose.
        """
        for path in self.readable:
            for secret in self.protected:
                if secret == path or path in secret.parents:
                    where = "is" if secret == path else f"lies inside {path}, which is"
                    raise SandboxUnavailable(
                        f"the sandbox would show {secret} to the submitted code: it {where} a "
                        f"folder the method or runner needs; move the method's code (or the "
                        f"store) so that neither is inside the other"
                    )


def _exists(path: Path) -> bool:
    return os.path.lexists(path)


def package_folders(packages: Iterable[str] = SWARMLOC_PACKAGES) -> list[Path]:
    """Source folders of packages, found without importing them (missing ones skipped)."""
    folders: list[Path] = []
    for name in packages:
        try:
            spec = importlib.util.find_spec(name)
        except (ImportError, ValueError):
            continue
        if spec is not None and spec.submodule_search_locations is not None:
            folders += [Path(p) for p in spec.submodule_search_locations if os.path.isdir(p)]
    return folders


def python_paths(python: str = sys.executable) -> list[Path]:
    """The Python installation and environment a worker started with ``python`` needs.

    The interpreter's prefix and base prefix (a virtual environment and the installation
    it was made from), the interpreter's real folder, and every ``site-packages`` folder.
    """
    paths = [Path(sys.prefix), Path(sys.base_prefix), Path(sys.exec_prefix), Path(sys.base_exec_prefix)]
    paths += [Path(python).parent, Path(os.path.realpath(python)).parent]
    paths += [Path(p) for p in sys.path if p.endswith("site-packages") and os.path.isdir(p)]
    return paths


def protected_paths(store_file: Path | None = None) -> list[Path]:
    """Paths a verification run must never see: the store, home, swarmloc's data folder, the host's tmp."""
    from platformdirs import user_data_dir

    # The sandbox's own /tmp and /dev replace the host's: binding either would show them whole.
    paths = [Path.home(), Path(user_data_dir("swarmloc")), Path("/tmp"), Path("/dev"), Path("/proc")]
    data = os.environ.get("SWARMLOC_DATA")
    if data:
        paths.append(Path(data))
    if store_file is not None:
        paths.append(store_file)
    return [Path(os.path.abspath(p)) for p in paths]


def _minimal(paths: Iterable[Path]) -> list[Path]:
    """Absolute, de-duplicated paths with those inside another one dropped, sorted."""
    unique = sorted({Path(os.path.abspath(p)) for p in paths if _exists(p)})
    kept: list[Path] = []
    for path in unique:
        if not any(parent in path.parents for parent in kept):
            kept.append(path)
    return kept


def view_for(extra: Sequence[Path], store_file: Path | None = None,
             python: str = sys.executable) -> SandboxView:
    """The view of a verification run: system, Python, swarmloc, plus ``extra`` paths.

    Args:
        extra: The method's file or search path, the runner's path, the weights file.
        store_file: The SQLite store file, if the store is one (kept invisible).
        python: The worker's interpreter.

    Returns:
        The view (call :meth:`SandboxView.check` before use).
    """
    readable = [*python_paths(python), *package_folders(), *extra]
    return SandboxView(readable=tuple(_minimal(readable)), protected=tuple(protected_paths(store_file)))


def _root_arguments() -> list[str]:
    args: list[str] = []
    for name in _SYSTEM_DIRS:
        if os.path.islink(name):
            args += ["--symlink", os.readlink(name), name]
        elif os.path.isdir(name):
            args += ["--ro-bind", name, name]
    args += ["--perms", "0755", "--dir", "/etc"]
    for name in _SYSTEM_ETC:
        if _exists(Path(name)):
            args += ["--ro-bind", name, name]
    return args


@dataclass
class SandboxCommand:
    """A command line wrapped in bubblewrap, and the descriptors it needs.

    Attributes:
        argv: The full command line.
        pass_fds: Descriptors to pass to the child and close once it started
            (:meth:`close`): the user namespace a root parent prepared.
    """

    argv: list[str]
    pass_fds: tuple[int, ...] = ()

    def close(self) -> None:
        """Close the descriptors (once the child holds them)."""
        for fd in self.pass_fds:
            try:
                os.close(fd)
            except OSError:
                pass
        self.pass_fds = ()


def _unreadable_by_nobody(path: Path) -> bool:
    mode = path.stat().st_mode
    needed = 0o005 if path.is_dir() else 0o004
    return mode & needed != needed


def _user_arguments(command: Sequence[str], view: SandboxView, python: str) -> tuple[list[str], list[str], int | None]:
    """Namespace options, the command as run, and the namespace descriptor (root only).

    As root, the sandbox joins a user namespace in which it becomes a real ``nobody``
    (see :mod:`swarmloc.leaderboard.verify.sandbox_userns`); otherwise bubblewrap makes one that
    maps our own user to ``nobody``.
    """
    if os.geteuid() != 0:
        return (["--unshare-user", "--disable-userns", "--uid", str(SANDBOX_UID), "--gid", str(SANDBOX_UID),
                 "--cap-drop", "ALL"], list(command), None)
    for path in view.readable:
        if path.exists() and _unreadable_by_nobody(path):
            raise SandboxUnavailable(
                f"{path} is not readable by other users (mode {path.stat().st_mode & 0o777:o}); started by root, "
                f"the verification sandbox runs as 'nobody', so the method's files must be world-readable "
                f"(chmod o+rX {path})"
            )
    try:
        fd = user_namespace_for_root(python)
    except UserNamespaceError as err:
        raise SandboxUnavailable(f"cannot prepare the sandbox's user namespace as root: {err}") from None
    return (["--userns", str(fd), "--cap-drop", "ALL", "--cap-add", "CAP_SETUID", "--cap-add", "CAP_SETGID"],
            [python, "-I", "-S", "-c", DROP_TO_NOBODY, *command], fd)


def sandbox_command(command: Sequence[str], view: SandboxView, limits: SandboxLimits = SandboxLimits(),
                    bwrap: str = BWRAP, python: str = sys.executable) -> SandboxCommand:
    """``command`` wrapped in bubblewrap with the isolation described in the module docstring.

    Args:
        command: The worker's command line (its executable must be inside ``view``).
        view: What it may read.
        limits: Sizes of the private ``/tmp`` and ``/dev/shm``.
        bwrap: The bubblewrap executable.
        python: Interpreter of the helpers a root parent runs.

    Returns:
        The command (close it once started: it may hold a descriptor).

    Raises:
        SandboxUnavailable: started by root, a bound path is not readable by ``nobody``,
            or the user namespace cannot be made.
    """
    system = set(_SYSTEM_DIRS)
    binds: list[str] = []
    made: set[Path] = {Path("/"), Path("/tmp")}
    for path in view.readable:
        if str(path) in system or any(str(parent) in system and not os.path.islink(str(parent))
                                      for parent in path.parents):
            continue  # already visible through a system folder
        # The folders above a bound path are made empty and traversable (not copies of,
        # say, /root's mode 0700, which 'nobody' could not pass).
        for parent in reversed(path.parents):
            if parent not in made:
                made.add(parent)
                binds += ["--perms", "0755", "--dir", str(parent)]
        binds += ["--ro-bind", str(path), str(path)]
    user, run, fd = _user_arguments(command, view, python)
    argv = [
        bwrap,
        *user,
        "--unshare-pid", "--unshare-net", "--unshare-ipc", "--unshare-uts", "--unshare-cgroup-try",
        "--die-with-parent", "--new-session",
        "--hostname", "swarmloc-sandbox",
        *_root_arguments(),
        "--proc", "/proc",
        "--dev", "/dev",
        "--perms", "1777", "--size", str(limits.shm_bytes), "--tmpfs", "/dev/shm",
        "--perms", "1777", "--size", str(limits.tmp_bytes), "--tmpfs", "/tmp",
        *binds,  # after the tmpfs, so that files under the host's /tmp show through it
        "--remount-ro", "/",
        "--chdir", "/tmp",
        "--",
        *run,
    ]
    return SandboxCommand(argv, () if fd is None else (fd,))


@functools.cache
def _probe(bwrap_path: str, python: str) -> str | None:
    """None when a Python interpreter starts inside the sandbox, else bwrap's complaint."""
    try:
        command = sandbox_command([python, "-I", "-c", "pass"], view_for([], python=python), bwrap=bwrap_path,
                                  python=python)
    except SandboxUnavailable as err:
        return str(err)
    try:
        done = subprocess.run(command.argv, capture_output=True, text=True, timeout=60,
                              stdin=subprocess.DEVNULL, check=False, pass_fds=command.pass_fds)
    except (OSError, subprocess.TimeoutExpired) as err:
        return str(err)
    finally:
        command.close()
    if done.returncode == 0:
        return None
    return (done.stderr.strip() or done.stdout.strip() or f"exit status {done.returncode}")[-500:]


def require_sandbox(python: str = sys.executable) -> str:
    """The path of a working ``bwrap``, or :class:`SandboxUnavailable` saying why not.

    The first call runs a tiny sandboxed Python once (cached) so that a kernel without
    unprivileged user namespaces is reported before any verification starts.

    Raises:
        SandboxUnavailable: not Linux, ``bwrap`` not on ``PATH``, or it cannot build the
            sandbox here; the message names the tool, the fix and the opt-in.
    """
    if not sys.platform.startswith("linux"):
        raise SandboxUnavailable(
            f"verification runs submitted code inside bubblewrap ('{BWRAP}'), which needs Linux; "
            f"this is {sys.platform}. {_OPT_IN[0].upper()}{_OPT_IN[1:]}"
        )
    path = shutil.which(BWRAP)
    if path is None:
        raise SandboxUnavailable(
            f"verification runs submitted code inside bubblewrap ('{BWRAP}'), which is not on "
            f"PATH; {_INSTALL_HINT}. {_OPT_IN[0].upper()}{_OPT_IN[1:]}"
        )
    problem = _probe(path, python)
    if problem is not None:
        raise SandboxUnavailable(
            f"bubblewrap ({path}) cannot build the verification sandbox here: {problem}. It needs "
            f"unprivileged user namespaces (sysctl kernel.unprivileged_userns_clone=1 or "
            f"user.max_user_namespaces > 0, and no AppArmor rule against bwrap). "
            f"{_OPT_IN[0].upper()}{_OPT_IN[1:]}"
        )
    return path


__all__ = [
    "BWRAP",
    "SANDBOX_UID",
    "SWARMLOC_PACKAGES",
    "SandboxCommand",
    "SandboxLimits",
    "SandboxView",
    "package_folders",
    "protected_paths",
    "python_paths",
    "require_sandbox",
    "sandbox_command",
    "view_for",
]
