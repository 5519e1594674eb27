"""A user namespace for sandboxes started by root, in which the sandbox runs as a real ``nobody``.

Why: the kernel exempts the global root user from ``RLIMIT_NPROC`` — also inside a user
namespace, where bubblewrap's own ``--unshare-user`` maps the sandbox's user to root
outside. So a fork bomb in a sandbox started by root would not be capped. Instead, root
builds the namespace itself (:func:`user_namespace_for_root`) with two users mapped to
themselves, root and ``nobody`` (65534): bubblewrap joins it (``--userns``), sets the
sandbox up as root (which can still reach a Python under ``/root``), and the sandboxed
command first becomes ``nobody`` for good (:data:`DROP_TO_NOBODY`, a few lines run before
anything else). The process-count limit then applies, and files are read with the
permissions of ``nobody``. Creating further user namespaces inside it is disabled, as
bubblewrap's ``--disable-userns`` would.

Unprivileged users need none of this: bubblewrap's ``--unshare-user`` already runs the
sandbox as their own, limited, user.
"""

from __future__ import annotations

import os
import subprocess
import sys

NOBODY: int = 65534

# Run in a helper process: enter a new user namespace, wait for the parent to write its
# ID maps, then forbid nested user namespaces in it (as root of the namespace).
_HELPER = r"""
import ctypes, os, sys
libc = ctypes.CDLL(None, use_errno=True)
if libc.unshare(0x10000000) != 0:  # CLONE_NEWUSER
    print("unshare failed:", os.strerror(ctypes.get_errno()), flush=True)
    sys.exit(1)
print("ready", flush=True)
sys.stdin.readline()
with open("/proc/sys/user/max_user_namespaces", "w") as limit:
    limit.write("0")
print("done", flush=True)
sys.stdin.read()
"""

DROP_TO_NOBODY: str = (
    f"import os, sys; os.setgroups([]); os.setresgid({NOBODY}, {NOBODY}, {NOBODY}); os.setresuid({NOBODY}, {NOBODY}, {NOBODY}); "
    "os.execv(sys.argv[1], sys.argv[1:])"
)
"""``python -c`` program that becomes ``nobody`` (losing every capability) and execs its arguments."""


class UserNamespaceError(RuntimeError):
    """The user namespace for root's sandbox could not be made."""


def user_namespace_for_root(python: str = sys.executable) -> int:
    """A new user namespace mapping root and nobody to themselves; an open descriptor of it.

    Args:
        python: Interpreter that runs the helper process.

    Returns:
        A file descriptor (close it after starting bubblewrap with ``--userns FD``).

    Raises:
        UserNamespaceError: not root, or the kernel refused (the reason is in the message).
    """
    if os.geteuid() != 0:
        raise UserNamespaceError(f"only root maps IDs freely; this process runs as UID {os.geteuid()}")
    helper = subprocess.Popen([python, "-I", "-S", "-c", _HELPER], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True)
    assert helper.stdin is not None and helper.stdout is not None
    try:
        answer = helper.stdout.readline().strip()
        if answer != "ready":
            raise UserNamespaceError(answer or helper.communicate(timeout=10)[1].strip() or "the helper exited")
        mapping = f"0 0 1\n{NOBODY} {NOBODY} 1\n"
        for name in ("uid_map", "gid_map"):
            with open(f"/proc/{helper.pid}/{name}", "w") as handle:
                handle.write(mapping)
        helper.stdin.write("mapped\n")
        helper.stdin.flush()
        answer = helper.stdout.readline().strip()
        if answer != "done":
            raise UserNamespaceError(f"could not disable nested user namespaces: {answer or 'the helper exited'}")
        return os.open(f"/proc/{helper.pid}/ns/user", os.O_RDONLY | os.O_CLOEXEC)
    except OSError as err:
        raise UserNamespaceError(f"could not map IDs in the new user namespace: {err}") from None
    finally:
        helper.kill()
        helper.wait()


__all__ = ["DROP_TO_NOBODY", "NOBODY", "UserNamespaceError", "user_namespace_for_root"]
