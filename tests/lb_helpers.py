"""Shared fixtures of the leaderboard tests: a tiny suite and results-file builders."""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import lb_fake_runner

from swarmloc.bench.evaluation.results import (
    EpisodeMetrics,
    MethodInfo,
    SuiteInfo,
    dumps_results,
    make_results,
    suite_sha256,
    write_results,
)
from swarmloc.leaderboard.errors import SandboxUnavailable
from swarmloc.leaderboard.verify.sandbox import require_sandbox
from swarmloc.leaderboard.verify.verification import VerifyLimits

TESTS_DIR = Path(__file__).resolve().parent
TASKS = ("swarmloc/Ideal-v0", "swarmloc/NLOS-v0")
SEEDS = (1000, 1001, 1002)
FAKE_RUNNER = "lb_fake_runner:run_episodes"
TEST_LIMITS = VerifyLimits(wall_time_s=20.0, memory_bytes=512 * 1024**2)
REQUIRE_SANDBOX_ENV = "SWARMLOC_REQUIRE_SANDBOX"


def sandbox_unavailable() -> str | None:
    """Why verification cannot be sandboxed here (None when bubblewrap works).

    With ``SWARMLOC_REQUIRE_SANDBOX=1`` (set by ``.ci/run``) a missing sandbox raises instead,
    so that CI never passes without testing it.
    """
    try:
        require_sandbox()
    except SandboxUnavailable as err:
        if os.environ.get(REQUIRE_SANDBOX_ENV) == "1":
            raise RuntimeError(f"{REQUIRE_SANDBOX_ENV}=1 but {err}") from None
        return str(err)
    return None


@dataclass(frozen=True)
class FakeSuite:
    """Satisfies the ``swarmloc.bench.evaluation.suites.get_suite`` contract."""

    name: str
    version: str
    sha256: str
    episodes: list[tuple[str, int]]


_EPISODES = [(t, s) for t in TASKS for s in SEEDS]
SUITE = FakeSuite("tiny-test", "1", suite_sha256(_EPISODES), _EPISODES)


def suite_lookup(name: str) -> FakeSuite:
    """The injected suite registry."""
    if name != SUITE.name:
        raise KeyError(f"unknown suite {name!r}; known: [{SUITE.name!r}]")
    return SUITE


def make_results_file(
    path: Path,
    entry_point: str = "lb_fake_runner:good",
    *,
    name: str = "good method",
    deterministic: bool = True,
    privileged: bool = False,
    track: str = "A",
    suite_version: str = "1",
    episodes: list[tuple[str, int]] | None = None,
    metrics_edit: Callable[[str, int, dict[str, Any]], None] | None = None,
    edit: Callable[[dict[str, Any]], None] | None = None,
) -> Path:
    """Write a results file whose metrics the fake runner reproduces.

    ``metrics_edit(task, seed, metrics)`` changes metrics before the aggregates are
    computed (a consistent file with tampered episodes); ``edit`` receives the final raw
    JSON dict and may change anything (aggregates included).
    """
    keys = _EPISODES if episodes is None else episodes

    def metrics(task: str, seed: int) -> EpisodeMetrics:
        values = lb_fake_runner.metrics_for(task, seed)
        if metrics_edit is not None:
            metrics_edit(task, seed, values)
        return EpisodeMetrics.of(**values)

    results = make_results(
        method=MethodInfo(name=name, entry_point=entry_point, privileged=privileged,
                          track=track, deterministic=deterministic),
        suite=SuiteInfo(name=SUITE.name, version=suite_version, sha256=SUITE.sha256),
        episodes=[
            {"task": t, "seed": s, "metrics": metrics(t, s)} for t, s in keys
        ],
    )
    if edit is None:
        return write_results(path, results)
    raw = json.loads(dumps_results(results))
    edit(raw)
    path.write_text(json.dumps(raw, indent=1))
    return path


def submit_options(db_url: str) -> dict[str, Any]:
    """Keyword arguments that point ``submit`` at the fakes."""
    return {
        "db_url": db_url,
        "suite_lookup": suite_lookup,
        "runner": FAKE_RUNNER,
        "runner_path": [TESTS_DIR],
        "search_path": [TESTS_DIR],
        "limits": TEST_LIMITS,
        "sample_seed": 7,
        # The sandbox's own tests (test_lb_hostile_*) require it; these run either way.
        "sandbox": sandbox_unavailable() is None,
    }
