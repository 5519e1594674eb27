"""What evaluation jobs return, gathered: one task's outcome, one method's run on a suite.

The runner (``runner.py``) makes (method, task, seed-chunk) jobs and an execution backend
(``backends.py``) runs them; the pieces here put the returned chunks back together in
suite order — per task (:class:`TaskOutcome`) and per method (:class:`MethodRun`, which
assembles the results file) — and say which tasks failed (:class:`EvaluationFailed`).
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from swarmloc.agents.registry import LoadedMethod
from swarmloc.bench.evaluation.backends import Job
from swarmloc.bench.evaluation.results import MethodInfo, Results, SuiteInfo, make_results, write_results
from swarmloc.bench.evaluation.suites import Suite, restrict_tasks
from swarmloc.bench.evaluation.traces import Trace, traces_path, write_traces


@dataclass
class TaskOutcome:
    """Per-episode results of several methods on one task's seeds.

    Attributes:
        task: task ID; seeds: the seeds, in order.
        episodes: method → one metrics dict per seed.
        traces: method → trace of the first seed (when requested).
        unsupported: method → why it cannot run this task (its metrics are all null).
        cpu_seconds: method → CPU time of its rollout (references excluded).
    """

    task: str
    seeds: list[int]
    episodes: dict[str, list[dict[str, float | None]]] = field(default_factory=dict)
    traces: dict[str, Trace] = field(default_factory=dict)
    unsupported: dict[str, str] = field(default_factory=dict)
    cpu_seconds: dict[str, float] = field(default_factory=dict)


@dataclass
class MethodRun:
    """One method's evaluation on a suite.

    Attributes:
        loaded: the method's metadata (and an instance, unused after loading).
        episodes: ``[{"task", "seed", "metrics"}]`` in suite order (tasks in ``failed`` left out).
        traces: first-seed traces per task.
        weights: the weights file, if any.
        unsupported: task → why the method cannot run it (null metrics there).
        failed: task → the error of a job that failed there (its episodes are missing).
        cpu_seconds: CPU time of its rollouts over the suite.
    """

    loaded: LoadedMethod
    episodes: list[dict[str, Any]]
    traces: list[Trace]
    weights: str | None = None
    unsupported: dict[str, str] = field(default_factory=dict)
    failed: dict[str, str] = field(default_factory=dict)
    cpu_seconds: float = 0.0

    def results(self, suite: Suite) -> Results:
        """Assemble the results file (aggregates, provenance) of this run.

        Raises:
            EvaluationFailed: some task failed (see :meth:`partial_results`).
        """
        if self.failed:
            raise EvaluationFailed(self.loaded.name, self.failed, self.partial_results(suite))
        return make_results(method_info(self.loaded, self.weights), suite_info(suite), self.episodes)

    def partial_results(self, suite: Suite) -> Results | None:
        """The results of the tasks that did not fail, as suite ``<name>-subset`` (None when every task failed)."""
        done = [t for t in suite.tasks if t not in self.failed]
        if not done:
            return None
        part = restrict_tasks(suite, done)
        episodes = [e for e in self.episodes if e["task"] in done]
        return make_results(method_info(self.loaded, self.weights), suite_info(part), episodes)


class EvaluationFailed(RuntimeError):
    """Jobs of a method failed on some tasks; the results of its other tasks are kept.

    Attributes:
        method: the method.
        failed: task → error.
        partial: results of the other tasks (suite ``<name>-subset``), or None.
        written: where ``evaluate`` wrote ``partial``, or None.
    """

    def __init__(self, method: str, failed: Mapping[str, str], partial: Results | None,
                 written: Path | None = None) -> None:
        self.method, self.failed, self.partial, self.written = method, dict(failed), partial, written
        lines = [f"{method} failed on {len(self.failed)} task(s):"]
        lines += [f"  {task}: {error}" for task, error in self.failed.items()]
        if written is not None:
            lines.append(f"results of the other {len(partial.aggregates) if partial else 0} task(s) in {written}")
        super().__init__("\n".join(lines))


def training_run(weights: str | os.PathLike[str]) -> int | None:
    """The training run a weights file comes from: ``config.seed`` of its training record, the JSON beside it.

    Every ``swarmloc train`` command writes the record as the weights path with ``.json``
    (``mappo_set_gru_v2.seed2.pt`` → ``mappo_set_gru_v2.seed2.json``); the runs of the learned methods
    differ in that seed alone. Weights without a record, or a record without ``config.seed``, have no run.

    Raises:
        ValueError: the record is not a JSON object, or its ``config.seed`` is not a non-negative integer.
    """
    record = Path(weights).with_suffix(".json")
    if not record.is_file():
        return None
    try:
        raw = json.loads(record.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise ValueError(f"training record {record} of weights {weights} is not JSON: {err}") from None
    if not isinstance(raw, dict):
        raise ValueError(f"training record {record} must hold a JSON object, got {type(raw).__name__}")
    config = raw.get("config")
    seed = config.get("seed") if isinstance(config, dict) else None
    if seed is None:
        return None
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"training record {record}: config.seed must be a non-negative integer (the run seed), "
                         f"got {seed!r}")
    return seed


def method_info(loaded: LoadedMethod, weights: str | None = None) -> MethodInfo:
    """The results-file description of a loaded method: what it is, how it was made (``privileged_training``,
    the training ``run`` of its weights file) and what it declares it costs (``flops_per_channel``)."""
    digest = run = None
    if weights is not None:
        digest = hashlib.sha256(Path(weights).read_bytes()).hexdigest()
        run = training_run(weights)
    flops = getattr(loaded.method, "flops_per_channel", None)
    return MethodInfo(name=loaded.name, entry_point=loaded.entry_point, weights_sha256=digest,
                      privileged=loaded.privileged, track=loaded.track, deterministic=loaded.deterministic,
                      privileged_training=loaded.privileged_training, run=run,
                      flops_per_channel=None if flops is None else float(flops))


def suite_info(suite: Suite) -> SuiteInfo:
    """The results-file description of a suite."""
    return SuiteInfo(name=suite.name, version=suite.version, sha256=suite.sha256)


@dataclass
class Gathered:
    """What the jobs of a suite evaluation returned so far, keyed by (method, task[, seed]).

    ``add`` takes a finished job's outcome; ``failed`` holds (method, task) → error;
    ``outcome`` and ``run`` assemble a task's and a method's view in suite order.
    """

    metrics: dict[tuple[str, str, int], dict[str, float | None]] = field(default_factory=dict)
    traces: dict[tuple[str, str], Trace] = field(default_factory=dict)
    unsupported: dict[tuple[str, str], str] = field(default_factory=dict)
    failed: dict[tuple[str, str], str] = field(default_factory=dict)
    cpu_seconds: dict[str, float] = field(default_factory=dict)

    def add(self, job: Job, part: TaskOutcome) -> None:
        """Keep a finished job's metrics, trace, refusal and CPU time."""
        m = job.method
        for seed, met in zip(part.seeds, part.episodes[m]):
            self.metrics[(m, job.task, seed)] = met
        if m in part.traces:
            self.traces[(m, job.task)] = part.traces[m]
        if m in part.unsupported:
            self.unsupported[(m, job.task)] = part.unsupported[m]
        self.cpu_seconds[m] = self.cpu_seconds.get(m, 0.0) + part.cpu_seconds.get(m, 0.0)

    def outcome(self, task: str, seeds: list[int], methods: Sequence[str]) -> TaskOutcome:
        """A finished task's outcome (methods that failed there left out)."""
        out = TaskOutcome(task=task, seeds=seeds)
        for m in methods:
            if (m, task) in self.failed:
                continue
            out.episodes[m] = [self.metrics[(m, task, s)] for s in seeds]
            if (m, task) in self.traces:
                out.traces[m] = self.traces[(m, task)]
            if (m, task) in self.unsupported:
                out.unsupported[m] = self.unsupported[(m, task)]
        return out

    def run(self, m: str, loaded: LoadedMethod, suite: Suite, weights: str | None) -> MethodRun:
        """Method ``m``'s run on the suite (episodes in suite order; failed tasks left out)."""
        tasks = [t for t in suite.tasks if (m, t) not in self.failed]
        return MethodRun(
            loaded=loaded,
            episodes=[{"task": t, "seed": s, "metrics": self.metrics[(m, t, s)]} for t in tasks for s in suite.seeds(t)],
            traces=[self.traces[(m, t)] for t in tasks if (m, t) in self.traces], weights=weights,
            unsupported={t: self.unsupported[(m, t)] for t in tasks if (m, t) in self.unsupported},
            failed={t: self.failed[(m, t)] for t in suite.tasks if (m, t) in self.failed},
            cpu_seconds=self.cpu_seconds.get(m, 0.0))


def partial_path(out: str | os.PathLike[str]) -> Path:
    """Where ``evaluate`` puts the results of the tasks that did not fail: ``<stem>.partial.json``."""
    out = Path(out)
    return out.with_name(out.name.removesuffix(".json") + ".partial.json")


def write_run(out: str | os.PathLike[str], results: Results, traces: list[Trace]) -> Path:
    """Write a run's results file atomically, its traces first: a results file never lacks its traces."""
    if traces:
        write_traces(traces_path(out), traces)
    write_results(out, results)
    return Path(out)


__all__ = ["EvaluationFailed", "Gathered", "MethodRun", "TaskOutcome", "method_info", "partial_path", "suite_info",
           "training_run", "write_run"]
