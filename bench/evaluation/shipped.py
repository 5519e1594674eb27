"""The shipped reference results: one results file per shipped method and suite.

``bench/results/standard-v2/<method>.json`` are the results of the shipped methods on benchmark
v2's ``standard-v2``, the default board (a learned method's training runs beside them as
``<method>.seed<k>.json``); ``bench/results/standard-v1/<method>.json`` those on the frozen,
deprecated ``standard-v1``; ``bench/results/standard-v0/<method>.json`` those of the frozen
``standard-v0``. Each is what ``swarmloc evaluate --method <method> --suite <suite>`` writes (a
run: ``--weights`` its weights); ``swarmloc reproduce shipped`` regenerates them. They travel in
the wheel as package data. The leaderboard stores them (``swarmloc.leaderboard.store.shipped``);
the calibration and label reports compare against them.
"""

from __future__ import annotations

import functools
import hashlib
from collections.abc import Sequence
from pathlib import Path

#: the suite of the default board
DEFAULT_SUITE = "standard-v2"
#: a learned method's training runs ship as ``<method>.seed<k>.json`` beside ``<method>.json``
RUN_SEPARATOR = ".seed"
#: the shipped results of each suite, default board first
RESULTS_DIRS: dict[str, Path] = {
    suite: Path(__file__).resolve().parents[1] / "results" / suite for suite in (DEFAULT_SUITE, "standard-v1", "standard-v0")
}


def shipped_results(results_dir: Path | None = None) -> list[Path]:
    """The shipped results files of one folder in name order (default: every suite's, ``RESULTS_DIRS`` order)."""
    if results_dir is not None:
        return sorted(results_dir.glob("*.json"))
    return [path for folder in RESULTS_DIRS.values() for path in sorted(folder.glob("*.json"))]


def shipped_weights(sha256: str) -> Path | None:
    """The shipped weights file (``agents/weights``, records aside) whose SHA-256 is ``sha256``, or None.

    A shipped results file evaluated with ``--weights`` (a learned method's training runs,
    ``<method>.seed<k>.json``) names its weights by hash only; the leaderboard stores it with this file,
    as any submission with weights.
    """
    from swarmloc.agents.registry import WEIGHTS_DIR  # local: the registry, only when weights are looked up

    files = tuple(sorted((p, p.stat().st_size, p.stat().st_mtime_ns) for p in WEIGHTS_DIR.rglob("*")
                         if p.is_file() and p.suffix != ".json"))
    return _weights_by_hash(files).get(sha256)


@functools.lru_cache(maxsize=4)
def _weights_by_hash(files: tuple[tuple[Path, int, int], ...]) -> dict[str, Path]:
    """SHA-256 → path of the weights files (keyed by path, size and modification time: a changed file is re-read)."""
    return {hashlib.sha256(path.read_bytes()).hexdigest(): path for path, _, _ in files}


def regenerate(methods: Sequence[str], suite_name: str = DEFAULT_SUITE, workers: int = 2) -> list[Path]:
    """Re-evaluate ``methods`` on a suite into its shipped results folder (traces are not kept).

    All methods run in one evaluation, so the references every episode needs (uniform, the
    information bound) are computed once per worker, not once per method. A name
    ``<method>.seed<k>`` is a learned method's training run: its shipped file is re-evaluated with
    the weights it names (by SHA-256, ``shipped_weights``), in an evaluation of its own.

    Args:
        methods: method names or training runs (default of the command: every shipped file of the suite).
        suite_name: a suite of ``RESULTS_DIRS``.
        workers: worker processes.

    Returns:
        The files written.

    Raises:
        KeyError: the suite has no shipped results.
        FileNotFoundError: a training run has no shipped file, or its weights are not shipped.
        RuntimeError: a job failed (nothing is written).
    """
    from swarmloc.bench.evaluation.results import read_results_file, write_results
    from swarmloc.bench.evaluation.runner import evaluate_methods
    from swarmloc.bench.evaluation.suites import get_suite

    if suite_name not in RESULTS_DIRS:
        raise KeyError(f"suite {suite_name!r} has no shipped results; allowed: {', '.join(RESULTS_DIRS)}")
    results_dir = RESULTS_DIRS[suite_name]
    results_dir.mkdir(parents=True, exist_ok=True)
    suite = get_suite(suite_name)
    # (file stem, method, weights or None) of every evaluation: the plain methods together, each run alone
    plain = [name for name in methods if RUN_SEPARATOR not in name]
    evaluations: list[list[tuple[str, str, Path | None]]] = [[(name, name, None) for name in plain]] if plain else []
    for stem in (name for name in methods if RUN_SEPARATOR in name):
        file = results_dir / f"{stem}.json"
        if not file.is_file():
            raise FileNotFoundError(f"training run {stem!r} has no shipped file {file}; write it with "
                                    f"swarmloc evaluate --weights <its weights>")
        sha = read_results_file(file).results.method.weights_sha256
        weights_file = shipped_weights(sha) if sha else None
        if weights_file is None:
            raise FileNotFoundError(f"the weights of {file.name} (sha256 {sha}) are not among the shipped weights")
        evaluations.append([(stem, stem.split(RUN_SEPARATOR)[0], weights_file)])
    outputs = []
    for evaluation in evaluations:
        weights = {method: str(path) for _, method, path in evaluation if path is not None}
        runs = evaluate_methods([method for _, method, _ in evaluation], suite, workers=workers, trace=False,
                                weights=weights or None)
        failed = {name: run.failed for name, run in runs.items() if run.failed}
        if failed:
            raise RuntimeError(f"not regenerated, some jobs failed: {failed}")
        outputs += [(stem, runs[method]) for stem, method, _ in evaluation]
    return [write_results(results_dir / f"{stem}.json", run.results(suite)) for stem, run in outputs]


def refresh_bounds(suite_name: str = DEFAULT_SUITE, results_dir: Path | None = None) -> list[Path]:
    """Recompute ``bound_rmse`` in a suite's shipped results files with the current information bound.

    The bound depends on the episode only (task spec and seed), never on the method, so a new
    bound (``envs.filter.bound.BOUND_VERSION``) changes one column of every file and nothing
    else: every other metric, the method and the provenance stay as evaluated; the aggregates
    and the score block (whose gap closed reads the bound) are recomputed from the episodes.

    Args:
        suite_name: a suite of ``RESULTS_DIRS``.
        results_dir: the files to refresh (default: the suite's shipped folder).

    Returns:
        The files rewritten (atomically, one by one).

    Raises:
        KeyError: the suite has no shipped results.
    """
    from swarmloc.bench.evaluation.results import load_results, make_results, write_results
    from swarmloc.bench.scoring.bounds import episode_bounds

    if suite_name not in RESULTS_DIRS:
        raise KeyError(f"suite {suite_name!r} has no shipped results; allowed: {', '.join(RESULTS_DIRS)}")
    written = []
    for path in shipped_results(results_dir or RESULTS_DIRS[suite_name]):
        results = load_results(path)
        by_task: dict[str, list[int]] = {}
        for e in results.episodes:
            by_task.setdefault(e.task, []).append(e.seed)
        bound = {(task, b.seed): b.rmse for task, seeds in by_task.items() for b in episode_bounds(task, seeds)}
        episodes = []
        for e in results.episodes:
            metrics = e.metrics.model_dump()
            if metrics["rmse"] is not None:
                metrics["bound_rmse"] = bound[(e.task, e.seed)]
            episodes.append({"task": e.task, "seed": e.seed, "metrics": metrics})
        written.append(write_results(path, make_results(results.method, results.suite, episodes, results.provenance)))
    return written
