"""The import rule of the rooms (docs/architecture.md): envs ← agents ← bench ← leaderboard ← cli.

The world knows nothing of methods, methods nothing of evaluation, evaluation nothing of the
leaderboard, the leaderboard never imports a method (it re-runs submissions through the bench
runner), and only the command line sees every room. Read from the source with ``ast`` (every ``import`` and ``from … import``, at module
level or inside functions), so a lazy import breaks the rule as much as a top-level one.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

#: each room and the rooms it may import
ALLOWED = {
    "envs": {"envs"},
    "agents": {"envs", "agents"},
    "bench": {"envs", "agents", "bench"},
    "leaderboard": {"envs", "bench", "leaderboard"},
    "cli": {"envs", "agents", "bench", "leaderboard", "cli"},
}
ROOMS = tuple(ALLOWED)


def _room_of(module: str) -> str | None:
    parts = module.split(".")
    if parts[0] != "swarmloc" or len(parts) < 2:
        return None
    return parts[1]


def _imports(path: Path, package: str) -> list[tuple[int, str]]:
    """``(line, module)`` of every swarmloc import in a file (relative ones resolved against ``package``)."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                found.append((node.lineno, ".".join(base + ([node.module] if node.module else []))))
            elif node.module:
                found.append((node.lineno, node.module))
    return found


def _files(room: str) -> list[Path]:
    return sorted(p for p in (REPO / room).rglob("*.py") if "__pycache__" not in p.parts)


def test_the_rooms_exist():
    for room in ROOMS:
        assert (REPO / room / "__init__.py").is_file(), f"room {room}/ is not a package"


@pytest.mark.parametrize("room", ROOMS)
def test_a_room_imports_only_the_rooms_below_it(room):
    allowed = ALLOWED[room]
    broken = []
    for path in _files(room):
        package = ".".join(["swarmloc", *path.relative_to(REPO).parts[:-1]])  # what a relative import starts from
        for line, module in _imports(path, package):
            target = _room_of(module)
            if target is not None and target not in allowed:
                broken.append(f"{path.relative_to(REPO)}:{line} imports {module}")
    assert not broken, f"{room}/ may import only {sorted(allowed)}:\n" + "\n".join(broken)


def test_the_rule_catches_a_violation(tmp_path):
    """The scan sees top-level, lazy and relative imports (so the test above can fail)."""
    source = tmp_path / "m.py"
    source.write_text("import os\nfrom swarmloc.leaderboard import store\n"
                      "def f():\n    import swarmloc.agents.registry\n    from ...bench import x\n")
    found = [module for _, module in _imports(source, "swarmloc.envs.sub")]
    assert found == ["os", "swarmloc.leaderboard", "swarmloc.agents.registry", "swarmloc.bench"]
