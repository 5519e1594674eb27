"""The ``swarmloc`` CLI: evaluate in a subprocess, plot, demo tables, subcommand registry."""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
from rich.console import Console

from swarmloc.bench import cli
from swarmloc.bench.demo import run_demo
from swarmloc.bench.results import load_results
from swarmloc.bench.runner import run_episodes
from swarmloc.bench.suites import Suite

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


def test_tasks_and_methods_commands(capsys):
    assert cli.main(["tasks"]) == 0
    assert "swarmloc/CascadedFault-v0" in capsys.readouterr().out
    assert cli.main(["methods"]) == 0
    assert "chi2-soft" in capsys.readouterr().out


@dataclass
class _Hello:
    """Say hello."""

    times: int = 1
    """How many times."""


def test_a_module_can_add_a_subcommand(capsys):
    seen = []

    @cli.command("hello-test", help="test command")
    def run_hello(cfg: _Hello) -> int:
        seen.append(cfg.times)
        return 3

    try:
        assert cli.main(["hello-test", "--times", "4"]) == 3
        assert seen == [4]
        with pytest.raises(ValueError, match="already registered"):
            cli.register_command("hello-test", _Hello, lambda cfg: 0)
    finally:
        cli.COMMANDS.pop("hello-test")


def test_demo_tables(tmp_path):
    suite = Suite("tiny", "0", (("swarmloc/NLOSStep-v0", 1_000_000), ("swarmloc/NLOSStep-v0", 1_000_001)))
    console = Console(record=True, width=160)
    results = run_demo(["uniform", "chi2-soft", "oracle"], suite, tmp_path, workers=1, plots=False,
                       console=console)
    text = console.export_text()
    assert "NLOSStep" in text and "oracle†" in text
    md = (tmp_path / "summary.md").read_text()
    assert "| chi2-soft | A |" in md and md.rstrip().splitlines()[-1].startswith("| oracle† |")
    assert sorted(p.name for p in (tmp_path / "results").glob("*.json")) == ["chi2-soft.json", "oracle.json",
                                                                            "uniform.json"]
    assert results["chi2-soft"].aggregates["swarmloc/NLOSStep-v0"]["normalized_score"].mean > 0.9
