"""The ``swarmloc`` CLI: evaluate in a subprocess, plot, demo tables, subcommand registry."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numba
import pytest
from rich.console import Console

from swarmloc import cli
from swarmloc.bench.reports.demo import PIPE_WIDTH, run_demo
from swarmloc.bench.evaluation.results import load_results
from swarmloc.bench.evaluation.runner import run_episodes
from swarmloc.bench.evaluation.suites import Suite

SWARMLOC = Path(sys.executable).parent / "swarmloc"


@pytest.fixture(scope="module")
def results_file(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("cli") / "uniform.json"
    command = [str(SWARMLOC), "evaluate", "--method", "uniform", "--suite", "quick", "--tasks",
               "swarmloc/Ideal-v0", "--out", str(out), "--no-progress"]
    proc = subprocess.run(command, capture_output=True, text=True, timeout=600,
                          env={**os.environ, "COLUMNS": "120"})
    assert proc.returncode == 0, proc.stderr
    assert "wrote" in proc.stderr
    return out


def test_evaluate_subprocess_writes_results(results_file):
    results = load_results(results_file)
    assert results.method.name == "uniform" and results.suite.name == "quick-subset"
    assert results.episode_keys() == [("swarmloc/Ideal-v0", 1_000_000 + i) for i in range(4)]
    # another process, batched the same way or not: the same metrics (what the verifier relies on)
    again = run_episodes("uniform", [("swarmloc/Ideal-v0", 1_000_002)])[0]["metrics"]
    assert again == results.episodes[2].metrics.model_dump()


def test_plot_command(results_file, tmp_path):
    assert cli.main(["plot", str(results_file), "--out", str(tmp_path / "plots")]) == 0
    names = sorted(p.name for p in (tmp_path / "plots").glob("*.png"))
    assert names == ["cdf_Ideal-v0.png", "error_Ideal-v0.png", "trajectory_Ideal-v0.png", "trust_Ideal-v0.png"]


def test_evaluate_refuses_bad_suite_and_task(tmp_path, capsys):
    assert cli.main(["evaluate", "--method", "uniform", "--suite", "nope", "--out", str(tmp_path / "r.json")]) == 2
    assert "known suites" in capsys.readouterr().err
    assert cli.main(["evaluate", "--method", "uniform", "--tasks", "Nope-v0", "--out", str(tmp_path / "r.json")]) == 2
    assert "choose from" in capsys.readouterr().err


@pytest.mark.parametrize("argv, named", [
    (["reproduce", "peer-update", "--tasks", "swarmloc/Nope-v9"], "unknown task ID 'swarmloc/Nope-v9'"),
    (["reproduce", "calibration", "--suite", "nope"], "unknown suite 'nope'"),
    (["reproduce", "immarkf", "--seeds", "0"], "got 0"),
])
def test_reproduce_refuses_bad_options_and_writes_nothing(argv, named, tmp_path, capsys):
    outs = ["--out-md", str(tmp_path / "c.md"), "--out-json", str(tmp_path / "c.json")] \
        if "calibration" in argv else ["--out", str(tmp_path / "r.md")]
    assert cli.main(argv + outs) == 2
    printed = capsys.readouterr().out
    assert printed.startswith("error: ") and named in printed
    assert list(tmp_path.iterdir()) == []


def test_tasks_and_methods_commands(capsys):
    assert cli.main(["tasks"]) == 0
    assert "swarmloc/CascadedFault-v0" in capsys.readouterr().out
    assert cli.main(["methods"]) == 0
    assert "chi2-soft" in capsys.readouterr().out


def test_a_module_can_add_a_subcommand(monkeypatch, capsys):
    # a command is a module with `Options` and `run`; tests/cli_hello_command.py is one
    monkeypatch.setitem(cli.COMMANDS, "hello-test", "cli_hello_command")
    assert cli.main(["hello-test", "--times", "4"]) == 3
    assert capsys.readouterr().out == "hello\n" * 4


def test_a_module_off_the_convention_is_refused(monkeypatch):
    monkeypatch.setitem(cli.COMMANDS, "broken", "lb_helpers")  # a module without Options / run
    with pytest.raises(TypeError, match="must define a dataclass `Options` and a function `run"):
        cli.main(["--help"])


def _leaves(table, prefix=()):
    for name, entry in table.items():
        if isinstance(entry, str):
            yield prefix + (name,), entry
        else:
            yield from _leaves(entry, prefix + (name,))


@pytest.mark.parametrize("path,module", list(_leaves(cli.COMMANDS)), ids=lambda v: " ".join(v) if isinstance(v, tuple) else "")
def test_every_command_parses_its_help(path, module, capsys):
    """Each leaf follows the convention and answers ``--help`` through the nested parser (no issue numbers)."""
    loaded = cli.load_command(module)
    assert loaded.Options.__doc__, f"{module}.Options needs a docstring (its help line)"
    with pytest.raises(SystemExit) as exit_info:
        cli.main([*path, "--help"])
    assert exit_info.value.code == 0
    text = capsys.readouterr().out
    assert "usage: swarmloc " + " ".join(path) in " ".join(text.split())
    assert "issue" not in text.lower()


def test_help_and_tasks_import_neither_torch_nor_numba():
    """``swarmloc --help`` and ``swarmloc tasks`` stay light: the heavy modules (Ray too) load only inside handlers."""
    probe = ("import sys\nfrom swarmloc.cli import main\n"
             "try:\n    main(sys.argv[1:])\nexcept SystemExit:\n    pass\n"
             "print('HEAVY', sorted(m for m in ('torch', 'numba', 'torchrl', 'tensordict', 'ray') if m in sys.modules))")
    for args in (["--help"], ["tasks"], ["bench", "speed", "--help"], ["train", "mappo", "--help"]):
        proc = subprocess.run([sys.executable, "-c", probe, *args], capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0, proc.stderr
        assert proc.stdout.strip().splitlines()[-1] == "HEAVY []", (args, proc.stdout[-300:])


def test_docs_tasks_writes_the_pages_and_checks_them(tmp_path, capsys):
    """``swarmloc docs tasks`` writes a page per registered task and the index; ``--check`` names a stale
    page and a page that no task generates."""
    from swarmloc.cli import docs_tasks
    from swarmloc.envs.tasks.catalogue import CATALOGUE

    out = tmp_path / "tasks"
    assert cli.main(["docs", "tasks", "--out", str(out), "--check"]) == 1  # no pages yet
    assert cli.main(["docs", "tasks", "--out", str(out)]) == 0
    assert len(list(out.glob("*.md"))) == len(CATALOGUE) + 1
    assert docs_tasks.run(docs_tasks.Options(out=out, check=True)) == 0
    (out / "Gone.md").write_text("a removed task\n", encoding="utf-8")
    capsys.readouterr()
    assert docs_tasks.run(docs_tasks.Options(out=out, check=True)) == 1
    assert "Gone.md" in capsys.readouterr().out
    (out / "Gone.md").unlink()
    (out / "Ideal.md").write_text("stale\n", encoding="utf-8")
    assert docs_tasks.run(docs_tasks.Options(out=out, check=True)) == 1
    assert "Ideal.md" in capsys.readouterr().out
    assert docs_tasks.run(docs_tasks.Options(out=out)) == 0
    assert docs_tasks.run(docs_tasks.Options(out=out, check=True)) == 0


def test_bench_speed_writes_json(tmp_path):
    out = tmp_path / "speed.json"
    # one numba thread: under ``make test`` the other xdist worker holds the second core, and
    # a two-thread pool on one free core waits at every parallel region's barrier (the
    # particle filters' rows took 51 s instead of 0.7 s beside a busy core). The figures are
    # not checked here, only the report.
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        assert cli.main(["bench", "speed", "--quick", "--json", str(out)]) == 0
    finally:
        numba.set_num_threads(threads)
    rows = json.loads(out.read_text())["rows"]
    impls = {r["impl"] for r in rows}
    assert {"filterpy", "reference", "kernel", "world"} <= impls
    assert all(r["env_steps_per_s"] > 0 for r in rows)


def test_demo_tables(tmp_path):
    suite = Suite("tiny", "0", (("swarmloc/NLOSStep-v0", 1_000_000), ("swarmloc/NLOSStep-v0", 1_000_001)))
    console = Console(record=True, width=PIPE_WIDTH)  # the demo's width on a pipe
    results = run_demo(["uniform", "chi2-soft", "oracle"], suite, tmp_path, workers=1, plots=False,
                       console=console)
    text = console.export_text()
    assert "NLOSStep" in text and "oracle†" in text
    # each method's summary line keeps its score and CI on one line
    assert re.search(r"│ chi2-soft +│ A +│ +1/1 +│ +\d+\.\d\d× +│ +\d+\.\d\d–\d+\.\d\d +│", text), text
    md = (tmp_path / "summary.md").read_text()
    assert "| chi2-soft | A |" in md and md.rstrip().splitlines()[-1].startswith("| oracle† |")
    assert sorted(p.name for p in (tmp_path / "results").glob("*.json")) == ["chi2-soft.json", "oracle.json",
                                                                            "uniform.json"]
    score = results["chi2-soft"].score
    assert score is not None and score.times > 1.0  # chi2-soft beats uniform on NLOSStep
    assert "normalized_score" not in results["chi2-soft"].aggregates["swarmloc/NLOSStep-v0"]


def test_plot_command_draws_every_channel_kind(tmp_path):
    # TDOA channels (the last kind) once had no trust-plot colour; chi2-gate reports its trust
    out = tmp_path / "tdoa.json"
    assert cli.main(["evaluate", "--method", "chi2-gate", "--suite", "quick-v1", "--tasks", "TDOA-v1",
                     "--out", str(out), "--no-progress"]) == 0
    assert cli.main(["plot", str(out), "--out", str(tmp_path / "plots")]) == 0
    assert (tmp_path / "plots" / "trust_TDOA-v1.png").is_file()
