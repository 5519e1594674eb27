"""The numba cache guard (``envs/world/kernel_cache.py``): an edited callee never leaves a stale cached caller."""

from __future__ import annotations

import importlib.metadata
import os
import subprocess
import sys
from pathlib import Path

from swarmloc.envs.world.kernel_cache import STAMP_NAME, drop_stale_kernel_cache, kernel_sources

CALLEE = "from numba import njit\n\n\n@njit(cache=True)\ndef f(x):\n    return x + {offset}\n"
CALLER = "from numba import njit\n\nfrom .callee import f\n\n\n@njit(cache=True)\ndef g(x):\n    return f(x) * 2.0\n"
NUMBA = importlib.metadata.version("numba")


def _package(tmp_path: Path, offset: float = 1.0) -> Path:
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "callee.py").write_text(CALLEE.format(offset=offset))
    (pkg / "caller.py").write_text(CALLER)
    (pkg / "plain.py").write_text("ANSWER = 42\n")
    return pkg


def _edit_callee(pkg: Path, offset: float) -> None:
    path = pkg / "callee.py"
    before = path.stat().st_mtime_ns
    path.write_text(CALLEE.format(offset=offset))
    os.utime(path, ns=(before + 2_000_000_000, before + 2_000_000_000))  # a new time even on coarse clocks


def _g_of_one(tmp_path: Path) -> float:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    done = subprocess.run([sys.executable, "-c", "from pkg.caller import g; print(g(1.0))"], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return float(done.stdout)


def _cache_files(pkg: Path) -> list[Path]:
    return sorted(p for p in (pkg / "__pycache__").iterdir() if p.suffix in (".nbi", ".nbc"))


def test_numba_keeps_a_stale_caller_and_the_guard_drops_it(tmp_path):
    pkg = _package(tmp_path)
    assert drop_stale_kernel_cache([pkg], NUMBA)  # no stamp yet: the first call starts one
    assert _g_of_one(tmp_path) == 4.0
    _edit_callee(pkg, 10.0)
    # what the guard is for: numba checks only the caller's own file and runs the old callee
    assert _g_of_one(tmp_path) == 4.0
    assert drop_stale_kernel_cache([pkg], NUMBA)
    assert not _cache_files(pkg)
    assert _g_of_one(tmp_path) == 22.0


def test_unchanged_sources_keep_the_cache(tmp_path):
    pkg = _package(tmp_path)
    drop_stale_kernel_cache([pkg], NUMBA)
    _g_of_one(tmp_path)
    cached = _cache_files(pkg)
    assert cached and not drop_stale_kernel_cache([pkg], NUMBA)
    # a touched file with the same bytes (a checkout, a save without edits) keeps the cache too
    os.utime(pkg / "caller.py", ns=(1, 1))
    assert not drop_stale_kernel_cache([pkg], NUMBA) and _cache_files(pkg) == cached
    # a module that no kernel imports does not count
    (pkg / "plain.py").write_text("ANSWER = 43\n")
    assert not drop_stale_kernel_cache([pkg], NUMBA) and _cache_files(pkg) == cached
    # a new numba compiles afresh
    assert drop_stale_kernel_cache([pkg], NUMBA + ".post1") and not _cache_files(pkg)
    assert len((pkg / "__pycache__" / STAMP_NAME).read_text().split()) == 2


def test_kernel_sources_follow_imports_across_the_packages():
    """Kernels freeze imported globals (channel kinds, RNG streams) into their code: those modules count."""
    root = Path(__file__).resolve().parents[1]
    found = {p.relative_to(root).as_posix() for p in kernel_sources([root / "envs", root / "agents"])}
    assert {"envs/filter/cekf.py", "envs/world/sim_kernel.py", "agents/estimators/pf/core.py", "agents/trust/integrity.py"} <= found
    assert {"envs/tasks/channels.py", "envs/tasks/rng.py", "agents/protocols.py"} <= found  # imported by kernels
    assert not {"envs/tasks/catalogue.py", "envs/world/kernel_cache.py", "bench/evaluation/runner.py"} & found
