"""Harness of the hostile-submission tests (``tests/test_lb_hostile_*.py``): real submissions.

Each test writes a method file whose ``reset`` attacks, a results file for it on the real
``standard-v0`` suite, and submits it with the real ``swarmloc submit`` command in a
subprocess. Verification then runs the real runner in the worker's sandbox and the
method in its own, on the one episode the sampler seed :data:`SAMPLE_SEED` picks (with
``--sample-frac 0.001 --min-episodes 1``), so each run takes seconds.

Results files carry the fake runner's plausible metrics for every episode (validation
passes; verification of an honest method would not), except that :func:`write_results`
can put the true metrics of the sampled episode in, computed here with the real runner
— which also fills numba's on-disk cache that the sandboxes copy.

Evidence of containment is collected on the host: the store's full dump before and
after, files the attack meant to create, and processes left running — every hostile
method first renames its process (``/proc/self/comm``) to the test's :attr:`Hostile.marker`
so that its forks stay recognizable.
"""

from __future__ import annotations

import functools
import json
import os
import subprocess
import sys
import textwrap
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import lb_fake_runner
import pytest
from lb_helpers import sandbox_unavailable

from swarmloc.bench.evaluation.results import EpisodeMetrics, MethodInfo, SuiteInfo, dumps_results, make_results
from swarmloc.leaderboard.store.database import LeaderboardStore
from swarmloc.leaderboard.verify.verification import sample_episodes

SUITE = "standard-v0"
SAMPLE_SEED = 5
"""Sampler seed whose one-episode sample is a short task (``NLOS-v0``)."""
SUBMIT_LIMITS = ("--time-limit-s", "60", "--memory-limit-mb", "2048", "--max-file-mb", "16")


def require_sandbox() -> None:
    """Skip the calling test when bubblewrap cannot run here (fail instead in CI)."""
    reason = sandbox_unavailable()
    if reason is not None:
        pytest.skip(reason)


@functools.cache
def _suite() -> Any:
    from swarmloc.bench.evaluation.suites import get_suite

    return get_suite(SUITE)


def sampled_episode() -> tuple[str, int]:
    """The (task, seed) that verification re-runs with ``--seed SAMPLE_SEED``."""
    (episode,) = sample_episodes(_suite().episodes, 0.001, 1, SAMPLE_SEED)
    return episode


@functools.cache
def true_metrics(entry_point: str) -> dict[str, float | None]:
    """The real runner's metrics of the sampled episode for ``entry_point``, in this process."""
    from swarmloc.bench.evaluation.runner import run_episodes

    (episode,) = run_episodes(entry_point, [sampled_episode()])
    return episode["metrics"]


def write_results(path: Path, entry_point: str, *, track: str = "A", honest: bool = False,
                  name: str = "hostile") -> Path:
    """A valid results file on the whole suite for ``entry_point``.

    Args:
        path: Where to write it.
        entry_point: The method, as submitted.
        track: Its track.
        honest: Put the true metrics of the sampled episode in (verification then passes
            for a method that behaves); otherwise every episode has the fake metrics.
        name: The method's name in the file.
    """
    real = {sampled_episode(): true_metrics(entry_point)} if honest else {}
    episodes = [
        {"task": task, "seed": seed,
         "metrics": EpisodeMetrics.of(**real.get((task, seed), lb_fake_runner.metrics_for(task, seed)))}
        for task, seed in _suite().episodes
    ]
    results = make_results(
        method=MethodInfo(name=name, entry_point=entry_point, privileged=False, track=track, deterministic=True),
        suite=SuiteInfo(name=_suite().name, version=_suite().version, sha256=_suite().sha256), episodes=episodes,
    )
    path.write_text(dumps_results(results), encoding="utf-8")
    return path


def dump_store(db_url: str) -> list[tuple[Any, ...]]:
    """Everything the store holds: every field of every submission and its aggregates."""
    with LeaderboardStore(db_url) as store:
        return [tuple(sorted((k, repr(v)) for k, v in vars(e).items())) for e in store.entries()]


def processes_marked(marker: str) -> list[str]:
    """Processes whose name or command line carries ``marker`` (``pid: command``)."""
    found = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            comm = Path(f"/proc/{pid}/comm").read_text(errors="replace").strip()
            cmdline = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if marker in comm or marker in cmdline:
            found.append(f"{pid}: {comm} {cmdline[:200]}")
    return found


@dataclass(frozen=True)
class Submission:
    """What ``swarmloc submit`` did."""

    code: int
    output: str
    seconds: float


@dataclass
class Hostile:
    """One hostile method in a test's folder, and a store seeded with one honest entry."""

    folder: Path
    marker: str
    db_url: str
    before: list[tuple[Any, ...]]

    @classmethod
    def create(cls, folder: Path) -> Hostile:
        """A fresh folder holding the store (``lb.db``), beside which the method will sit."""
        db_url = f"sqlite:///{folder / 'lb.db'}"
        with LeaderboardStore(db_url) as store:
            store.add(_seed_entry())
        return cls(folder, f"ev{uuid.uuid4().hex[:10]}", db_url, dump_store(db_url))

    def method(self, reset_body: str, *, act: str = "return np.ones(inp.nis.shape)", preamble: str = "",
               stem: str = "evil") -> str:
        """Write a Track A method whose ``reset`` runs ``reset_body``; its entry point."""
        source = HOSTILE_TEMPLATE.format(
            marker=self.marker, preamble=textwrap.dedent(preamble),
            reset=textwrap.indent(textwrap.dedent(reset_body), " " * 8),
            act=textwrap.indent(textwrap.dedent(act), " " * 8),
        )
        path = self.folder / f"{stem}.py"
        path.write_text(source, encoding="utf-8")
        return f"{path}:make"

    def submit(self, entry_point: str, *extra: str, honest: bool = False, track: str = "A",
               cwd: Path | None = None, timeout: float = 300) -> Submission:
        """Write the results file and run ``swarmloc submit RESULTS`` (in ``cwd``, default the folder)."""
        results = write_results(self.folder / "results.json", entry_point, honest=honest, track=track)
        script = Path(sys.executable).parent / "swarmloc"
        command = [str(script)] if script.exists() else [
            sys.executable, "-c", "import sys; from swarmloc.cli import main; sys.exit(main())"]
        args = [*command, "submit", str(results), "--db-url", self.db_url, "--seed", str(SAMPLE_SEED),
                "--sample-frac", "0.001", "--min-episodes", "1", *SUBMIT_LIMITS, *extra]
        env = {k: v for k, v in os.environ.items() if not k.startswith("SWARMLOC_DB")}
        env["COLUMNS"] = "400"  # one line per message: the assertions read whole sentences
        started = time.monotonic()
        done = subprocess.run(args, capture_output=True, text=True, timeout=timeout, env=env,
                              cwd=cwd or self.folder, check=False)
        return Submission(done.returncode, done.stdout + done.stderr, time.monotonic() - started)

    def assert_refused(self, submission: Submission, *reasons: str) -> None:
        """Refused with every reason in the output, nothing stored, nothing left running."""
        assert submission.code == 1, submission.output
        assert "submission refused" in submission.output, submission.output
        for reason in reasons:
            assert reason in submission.output, f"{reason!r} not in:\n{submission.output}"
        self.assert_contained()

    def assert_contained(self) -> None:
        """The store holds only its seed entry and no process of the method survives."""
        assert dump_store(self.db_url) == self.before
        deadline = time.monotonic() + 5.0  # SIGKILLed processes may take a moment to be reaped
        while (left := processes_marked(self.marker)) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not left, f"processes left running: {left}"


HOSTILE_TEMPLATE = '''\
import os, sys, numpy as np
{preamble}

class Hostile:
    privileged = False
    flops_per_channel = 1.0

    def reset(self, batch_size, layout, keys):
        with open("/proc/self/comm", "w") as comm:
            comm.write("{marker}")
{reset}

    def act(self, inp):
{act}


def make():
    return Hostile()
'''


def _seed_entry() -> Any:
    from datetime import datetime, timezone

    from swarmloc.leaderboard.store.records import LeaderboardEntry

    text = json.dumps({"seed": True})
    return LeaderboardEntry(
        name="seed entry", authors="", url=None, description="", track="A", privileged=False,
        deterministic=True, entry_point="uniform", method_hash="0" * 64, weights_sha256=None,
        suite_name=SUITE, suite_version=_suite().version, suite_sha256=_suite().sha256, verified=False,
        trusted=True, verification_seed=None, verified_episodes=0, score=None, delay_ms=None, energy_j=None,
        jitter=None, package_version="0", git_commit=None, results_json=text,
        created_utc=datetime(2026, 1, 1, tzinfo=timezone.utc),
    )

