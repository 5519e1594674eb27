"""The package as users install it: the wheel's files and metadata, and the extras the CLI names.

The wheel is built (a few seconds) from a copy of the files git knows, as a fresh clone
would build it; ``make wheel-check`` (.ci/wheel-check) installs and uses it.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import zipfile
from email.parser import Parser
from pathlib import Path

import pytest

from swarmloc import cli
from swarmloc.cli import extras

ROOT = Path(__file__).resolve().parents[1]
ROOMS = ("envs", "agents", "bench", "leaderboard")
#: the packages of each extra that the core install must not pull
OPTIONAL = {"torch", "tensordict", "torchrl", "tensorboard", "sqlalchemy", "captum", "ray", "psycopg"}


def _source_files() -> list[str]:
    """The files of the checkout that git knows (tracked and new, not ignored), as a clone would hold them."""
    out = subprocess.run(["git", "ls-files", "-co", "--exclude-standard"], cwd=ROOT, capture_output=True,
                         text=True, check=True).stdout
    return [f for f in out.splitlines() if (ROOT / f).is_file()]


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> tuple[zipfile.ZipFile, str, list[str]]:
    """The built wheel, the build's verbose log and the source files it was built from."""
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("needs a git checkout")
    tmp = tmp_path_factory.mktemp("wheel")
    files = _source_files()
    for name in files:
        (tmp / "src" / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / name, tmp / "src" / name)
    # what an earlier build of a since-deleted module leaves in a checkout: it must not ship
    stale = tmp / "src" / "build" / "lib" / "swarmloc" / "envs" / "deleted_module.py"
    stale.parent.mkdir(parents=True)
    stale.write_text("", encoding="utf-8")
    proc = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-v", "-w", str(tmp / "dist"),
                           str(tmp / "src")], check=False, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    (path,) = (tmp / "dist").glob("swarmloc-*.whl")
    with zipfile.ZipFile(path) as zf:
        yield zf, proc.stdout + proc.stderr, files


def test_every_code_folder_ships_as_a_package(wheel):
    zf, _, files = wheel
    names = set(zf.namelist())
    modules = [f for f in files if f.endswith(".py") and f.split("/")[0] in ROOMS]
    folders = {str(Path(f).parent) for f in modules}
    assert {"bench/evaluation", "bench/reproduce", "bench/training", "envs/recorded"} <= folders
    no_init = sorted(d for d in folders if f"{d}/__init__.py" not in files)
    assert not no_init, f"code folders without __init__.py (find_packages skips them): {no_init}"
    missing = sorted(f for f in modules if f"swarmloc/{f}" not in names)
    assert not missing, f"modules missing from the wheel: {missing}"
    assert "swarmloc/envs/deleted_module.py" not in names, "a stale build/lib leaked into the wheel"


def test_weights_results_and_static_files_ship(wheel):
    zf, _, files = wheel
    names = set(zf.namelist())
    data = [f for f in files if f.startswith(("agents/weights/", "bench/results/", "leaderboard/site/static/"))]
    missing = sorted(f for f in data if f"swarmloc/{f}" not in names)
    assert not missing, f"package data missing from the wheel: {missing}"
    results = [n for n in names if "/results/" in n and n.endswith(".json")]
    assert len(results) >= 20
    assert any(n.startswith("swarmloc/bench/results/standard-v1/") for n in results)
    assert any(n.startswith("swarmloc/agents/weights/") and n.endswith(".pt") for n in names)
    assert not [n for n in names if "__pycache__" in n or n.endswith((".pyc", ".nbi", ".nbc"))]


def test_metadata_license_and_a_core_without_torch(wheel):
    zf, log, _ = wheel
    (meta_name,) = [n for n in zf.namelist() if n.endswith(".dist-info/METADATA")]
    meta = Parser().parsestr(zf.read(meta_name).decode())
    assert meta["License-Expression"] == "MIT"
    assert any(n.endswith(".dist-info/licenses/LICENSE") for n in zf.namelist())
    core = [r for r in meta.get_all("Requires-Dist") if "extra ==" not in r]
    core_names = {re.split(r"[<>=!~\[; ]", r, maxsplit=1)[0].lower() for r in core}
    assert {"numpy", "numba", "scipy", "pydantic", "gymnasium", "pettingzoo"} <= core_names
    assert not core_names & OPTIONAL, f"the core install pulls {sorted(core_names & OPTIONAL)}"
    assert {"torchrl", "train", "leaderboard", "explain", "ray", "all", "dev"} <= set(meta.get_all("Provides-Extra"))
    # setuptools' complaints about our configuration (deprecated license table, data folders taken
    # for would-be packages, ...); its InformationOnly notes are not ours
    complaint = re.compile(r"DeprecationWarning|BuildBackendWarning|SetuptoolsWarning")
    ours = [line for line in log.splitlines() if complaint.search(line)]
    assert not ours, "\n".join(ours)


def test_leaderboard_show_shipped_loads_the_shipped_results(tmp_path):
    """``swarmloc leaderboard show --shipped``: the board of the shipped results from an empty store
    (the wheel check runs it on the installed package)."""
    import io

    from rich.console import Console

    from swarmloc.cli import leaderboard_show

    console = Console(record=True, width=100, file=io.StringIO())
    url = f"sqlite:///{tmp_path / 'board.db'}"
    assert leaderboard_show.run(leaderboard_show.Options(db_url=url, suite="standard-v1", shipped=True), console) == 0
    text = console.export_text()
    assert "not stored" not in text
    assert all(f" {name} " in text for name in ("mappo-set-gru", "chi2-soft", "uniform"))
    assert leaderboard_show.run(leaderboard_show.Options(db_url=url, suite="nope", shipped=True), console) == 2
    assert "no shipped results of suite 'nope'" in console.export_text()


def _pyproject_extras() -> dict[str, set[str]]:
    """extra → the top-level modules it installs, its included extras resolved (from pyproject.toml)."""
    tomllib = pytest.importorskip("tomllib")
    table = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]["optional-dependencies"]

    def modules(extra: str) -> set[str]:
        out: set[str] = set()
        for req in table[extra]:
            name = re.split(r"[<>=!~\[; ]", req, maxsplit=1)[0].lower()
            if name == "swarmloc":
                for sub in req.split("[", 1)[1].split("]", 1)[0].split(","):
                    out |= modules(sub.strip())
            else:
                out.add(name.replace("-", "_"))
        return out

    return {extra: modules(extra) for extra in table}


def test_extra_modules_match_pyproject():
    declared = _pyproject_extras()
    for extra, modules in extras.EXTRA_MODULES.items():
        assert extra in declared, f"{extra!r} is no extra of pyproject.toml"
        assert modules == declared[extra], (extra, sorted(modules), sorted(declared[extra]))
    assert set(extras.COMMAND_EXTRA.values()) <= set(extras.EXTRA_MODULES)
    assert set(extras.COMMAND_EXTRA) <= set(cli.COMMANDS)


@pytest.mark.parametrize(("module", "command", "extra"), [
    ("torch", "evaluate", "torchrl"),
    ("torch", "train mappo", "train"),
    ("tensorboard", "train mappo", "train"),
    ("captum", "explain", "explain"),
    ("torch", "explain", "explain"),
    ("sqlalchemy", "leaderboard show", "leaderboard"),
    ("torch", "submit", "torchrl"),
    ("ray", "evaluate", "ray"),
    ("torch", "demo", "all"),
    ("torch.utils", "reproduce madrl", "torchrl"),
])
def test_missing_extra_names_the_command_s_extra(module, command, extra):
    assert extras.missing_extra(ModuleNotFoundError(f"No module named {module!r}", name=module), command) == extra


def test_missing_extra_follows_the_cause_and_ignores_other_modules():
    try:
        try:
            raise ModuleNotFoundError("No module named 'ray'", name="ray")
        except ImportError as err:
            raise ImportError("the ray backend needs Ray") from err
    except ImportError as err:
        assert extras.missing_extra(err, "evaluate") == "ray"
    assert extras.missing_extra(ModuleNotFoundError("No module named 'jax'", name="jax"), "evaluate") is None
    assert extras.missing_extra(ValueError("torch"), "evaluate") is None


def _run_without(module: str):
    """A command handler that fails as it would without ``module`` installed."""
    def run(opts) -> int:
        raise ModuleNotFoundError(f"No module named {module!r}", name=module)
    return run


def test_cli_names_the_missing_extra(monkeypatch, capsys):
    from swarmloc.cli import tasks

    monkeypatch.setattr(tasks, "run", _run_without("sqlalchemy"))
    assert cli.main(["tasks"]) == 2
    assert "error: swarmloc tasks needs the 'leaderboard' extra: pip install 'swarmloc[leaderboard]'" \
        in capsys.readouterr().err
    monkeypatch.setattr(tasks, "run", _run_without("jax"))  # not ours to name: the error stands
    with pytest.raises(ModuleNotFoundError, match="jax"):
        cli.main(["tasks"])
