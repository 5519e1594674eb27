"""Sim-to-real rank agreement: does the robust-ranging track rank the classical methods as the real flights do?

Benchmark v2's robust-ranging track (one UAV against faulty anchor ranging, ``envs/tasks/v2.py``)
stands beside the real UTIL flights (suite ``real-v1``). If the simulated track is a faithful
proxy, it orders the shipped classical methods as the flights do. This module measures that
order on both sides and their agreement:

* each side's **score** of a method is score v2's gain ``g = log2(RMSE_uniform / RMSE)`` per
  episode, averaged over a task's seeds, then over the tasks, **each task weighing the same**
  (a flight is a task); its **ranking** orders the methods by that score, best first;
* the agreement is **Kendall's τ-b** between the two score vectors (ties counted as in
  ``scipy.stats.kendalltau``): +1 the same order, −1 the reverse;
* its **confidence interval** is a percentile bootstrap: each resample draws, on each side
  independently, the tasks with replacement and each drawn task's seeds with replacement
  (``bootstrap.hierarchical_means`` with one task per family), recomputes both sides' scores
  and τ. The two sides' draws come from seeds ``seed`` and ``seed + 1``, so the interval is
  reproducible.

The sim side reads **dev seeds only** (2_000_000 …): the comparison informs the benchmark's
design and must not touch the test seeds of the simulated tasks. The real side is the suite's
own episodes: every seed of a flight replays the same recording (the seed moves only the initial
prior), so the real side's uncertainty is mostly which flights were flown.

Use from a report (``calibration_v2``)::

    doc = measure_sim_to_real()                 # defaults: DEFAULT_METHODS, the robust-ranging
                                                # v2 tasks × 8 dev seeds, real-v1's flights × seeds
    lines = render_sim_to_real(doc)             # a Markdown section (a "##" heading and its body)

``rank_agreement`` is the pure part (synthetic numbers in the tests); ``measure_sim_to_real``
runs the methods through ``evaluate_task`` and hands their per-episode RMSE to it.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Mapping, Sequence
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from swarmloc.bench.evaluation.suites import DEV_SEED_START, RESERVED_SEED_START, get_suite
from swarmloc.bench.reports.markdown import markdown_table
from swarmloc.bench.scoring.bootstrap import (
    DEFAULT_CONFIDENCE,
    DEFAULT_RESAMPLES,
    DEFAULT_SEED,
    hierarchical_means,
    percentile_interval,
)
from swarmloc.bench.scoring.families import task_label
from swarmloc.bench.scoring.score import episode_gain
from swarmloc.envs.tasks.catalogue import canonical_task_id, get_spec
from swarmloc.envs.tasks.v2 import CATALOGUE_V2

#: the shipped classical methods compared: every registered method that is classical (no learned
#: weights), not privileged, deterministic and runs on every single-UAV task of both sides. Left out:
#: ``non-cooperative`` (on one UAV it is ``uniform`` exactly: no peer channel to skip), ``dead-reckoning``
#: (IMU only: no ranging to be robust about, last on both sides by construction, so it would add
#: concordant pairs that say nothing about the track), the particle filters (they do not model TDOA,
#: 8 of the 9 flights and TDOA-v2), the IMM and federated filters (they need GPS) and the CI-EKF (peers).
DEFAULT_METHODS: tuple[str, ...] = ("uniform", "fixed", "huber", "chi2-gate", "chi2-soft", "federated-coef",
                                    "cusum", "raim", "random")
#: the score's reference (gain 0 by definition); it must be among the methods
REFERENCE = "uniform"
#: the real side: this suite's flights and seeds
REAL_SUITE = "real-v1"
#: dev seeds per simulated task (2_000_000 …)
DEFAULT_SIM_SEEDS = 8

#: per task, per method, one value per seed (the same seeds for every method of a task)
EpisodeTable = Mapping[str, Mapping[str, ArrayLike]]


# --------------------------------------------------------------------------- defaults


def robust_ranging_tasks() -> list[str]:
    """The simulated tasks of the robust-ranging track (``spec.track``), in ``CATALOGUE_V2`` order."""
    return [t for t in CATALOGUE_V2 if get_spec(t).track == "robust-ranging"]


def sim_dev_seeds(n: int = DEFAULT_SIM_SEEDS) -> list[int]:
    """The first ``n`` dev seeds, 2_000_000 …; at least 2 (a bootstrap over one seed resamples nothing)."""
    if not 2 <= n <= RESERVED_SEED_START - DEV_SEED_START:
        raise ValueError(f"n={n}: need between 2 and {RESERVED_SEED_START - DEV_SEED_START} dev seeds")
    return list(range(DEV_SEED_START, DEV_SEED_START + n))


def real_episodes() -> tuple[list[str], list[int]]:
    """The flights of ``REAL_SUITE`` and their seeds (every flight has the same ones)."""
    suite = get_suite(REAL_SUITE)
    seeds = {tuple(suite.seeds(t)) for t in suite.tasks}
    if len(seeds) != 1:
        raise ValueError(f"suite {REAL_SUITE!r} gives its flights different seeds {sorted(seeds)}; expected one list")
    return suite.tasks, list(seeds.pop())


# --------------------------------------------------------------------------- the pure part


def kendall_tau_b(x: ArrayLike, y: ArrayLike) -> NDArray[np.float64]:
    """Kendall's τ-b of ``x`` and ``y`` along the last axis (NaN where either side is all ties).

    τ-b = Σ_{i<j} sgn(x_i − x_j) sgn(y_i − y_j) / √(n_x n_y), where n_x (n_y) counts the pairs not
    tied in x (y): ``scipy.stats.kendalltau``'s default, here vectorised over resamples.

    Args:
        x, y: ``(..., M)`` scores of M methods (the same leading shape).

    Returns:
        ``(...)`` τ-b.
    """
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    if x.shape != y.shape or x.shape[-1] < 2:
        raise ValueError(f"x {x.shape} and y {y.shape}: need the same shape with at least 2 methods on the last axis")
    i, j = np.triu_indices(x.shape[-1], k=1)
    a, b = np.sign(x[..., i] - x[..., j]), np.sign(y[..., i] - y[..., j])
    den = np.sqrt(np.sum(a != 0, axis=-1) * np.sum(b != 0, axis=-1))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, np.sum(a * b, axis=-1) / np.where(den > 0, den, 1.0), np.nan)


def _gain_table(side: str, table: EpisodeTable, methods: Sequence[str], values: str,
                reference: str) -> dict[str, NDArray[np.float64]]:
    """task → ``(M, S_t)`` per-episode gains of ``methods`` (rows in that order), checked."""
    if not table:
        raise ValueError(f"{side}: no task")
    out = {}
    for task, per_method in table.items():
        missing = [m for m in methods if m not in per_method]
        if missing:
            raise ValueError(f"{side} task {task!r} has no values for method(s) {missing}; every task needs "
                             f"every method of {list(methods)}")
        rows = {m: np.asarray(per_method[m], dtype=np.float64) for m in per_method}
        lengths = {m: r.shape for m, r in rows.items()}
        if len(set(lengths.values())) != 1 or any(len(n) != 1 or n[0] < 1 for n in lengths.values()):
            raise ValueError(f"{side} task {task!r}: every method needs one value per seed, the same seeds; got "
                             f"shapes {lengths}")
        if values == "rmse":
            ref = rows[reference]
            gains = [[episode_gain(float(u), float(r)) for u, r in zip(ref, rows[m])] for m in methods]
            bad = [(m, k) for m, g in zip(methods, gains) for k, v in enumerate(g) if v is None or not np.isfinite(v)]
            if bad or not np.all(np.isfinite(ref)):
                raise ValueError(f"{side} task {task!r}: RMSE must be positive and finite for {reference!r} and "
                                 f"every method; not at (method, seed index) {bad[:5]}")
            out[task] = np.array(gains, dtype=np.float64)
        else:
            g = np.stack([rows[m] for m in methods])
            if not np.all(np.isfinite(g)):
                raise ValueError(f"{side} task {task!r}: gains must be finite; got {g}")
            out[task] = g
    return out


def _ranking(methods: Sequence[str], scores: NDArray[np.float64]) -> list[str]:
    """Best first; ties keep the order of ``methods``."""
    return [methods[k] for k in sorted(range(len(methods)), key=lambda k: -scores[k])]


def rank_agreement(sim: EpisodeTable, real: EpisodeTable, *, methods: Sequence[str] | None = None,
                   values: Literal["rmse", "gain"] = "rmse", reference: str = REFERENCE,
                   n_resamples: int = DEFAULT_RESAMPLES, confidence: float = DEFAULT_CONFIDENCE,
                   seed: int = DEFAULT_SEED) -> dict[str, Any]:
    """Both sides' rankings of the methods and Kendall's τ between them, with a bootstrap CI.

    A side's score of a method is the mean over tasks (each the same weight) of the mean over
    the task's seeds of its per-episode gain ``log2(RMSE_reference / RMSE)``. Each bootstrap
    resample draws, on each side independently, the tasks with replacement and each drawn
    task's seeds with replacement (paired across methods), then recomputes τ-b of the two score
    vectors; the interval is the percentile one. Resamples where one side ties every method
    (τ undefined) are left out and counted.

    Args:
        sim, real: task → method → ``(S_t,)`` per-seed values, the same seeds for every method of
            a task (the sides may differ in tasks and seeds, not in methods).
        methods: the methods compared, at least 2 (default: those of ``sim``'s first task, in that order).
        values: ``"rmse"``: per-episode RMSE (``reference`` must be among the methods of every task);
            ``"gain"``: per-episode gains over the reference already.
        reference: the method whose RMSE the gain divides (``values="rmse"``).
        n_resamples, confidence, seed: the bootstrap's (the real side draws with ``seed + 1``).

    Returns:
        ``{"methods", "sim": {"scores": method → score, "ranking": best first, "tasks", "seeds"
        (per task)}, "real": the same, "tau", "ci": [low, high], "confidence", "n_resamples",
        "seed", "undefined_resamples"}``, JSON-able.

    Raises:
        ValueError: a bad ``values``, fewer than 2 methods, a method missing on a task, unequal
            seed counts within a task, a non-positive or missing RMSE, or τ undefined on the data.
    """
    if values not in ("rmse", "gain"):
        raise ValueError(f"values={values!r}; allowed: 'rmse', 'gain'")
    if not sim or not real:
        raise ValueError(f"need tasks on both sides; got {len(sim)} simulated and {len(real)} real")
    chosen = list(methods) if methods is not None else list(next(iter(sim.values())))
    if len(chosen) < 2 or len(set(chosen)) != len(chosen):
        raise ValueError(f"methods={chosen}: need at least 2 distinct methods to rank")
    if values == "rmse":
        for side, table in (("sim", sim), ("real", real)):
            lacking = [t for t, per in table.items() if reference not in per]
            if lacking:
                raise ValueError(f"{side} task(s) {lacking} lack the reference {reference!r}; the gain needs its RMSE")
    sides = {"sim": _gain_table("sim", sim, chosen, values, reference),
             "real": _gain_table("real", real, chosen, values, reference)}
    point = {s: np.mean([g.mean(axis=-1) for g in t.values()], axis=0) for s, t in sides.items()}
    tau = float(kendall_tau_b(point["sim"], point["real"]))
    if not np.isfinite(tau):
        raise ValueError(f"τ is undefined: one side ties every method (sim {point['sim']}, real {point['real']})")
    # one task per family: tasks drawn with replacement, then each drawn task's seeds (bootstrap.py)
    resampled = {s: hierarchical_means([[g] for g in t.values()], n_resamples, seed + k)
                 for k, (s, t) in enumerate(sides.items())}
    taus = kendall_tau_b(resampled["sim"].T, resampled["real"].T)
    defined = taus[np.isfinite(taus)]
    low, high = percentile_interval(defined, confidence)
    out: dict[str, Any] = {"methods": chosen}
    for s, table in (("sim", sim), ("real", real)):
        out[s] = {"scores": {m: round(float(v), 4) for m, v in zip(chosen, point[s])},
                  "ranking": _ranking(chosen, point[s]), "tasks": list(table),
                  "seeds": {t: int(g.shape[-1]) for t, g in sides[s].items()}}
    out.update(tau=round(tau, 4), ci=[round(float(low), 4), round(float(high), 4)], confidence=confidence,
               n_resamples=n_resamples, seed=seed, undefined_resamples=int(taus.size - defined.size))
    return out


# --------------------------------------------------------------------------- running


def _check_seeds(sim_seeds: Sequence[int], real_seeds: Sequence[int]) -> None:
    outside = [int(s) for s in sim_seeds if not DEV_SEED_START <= int(s) < RESERVED_SEED_START]
    if outside:
        raise ValueError(f"sim_seeds {outside} are not dev seeds: the sim side reads [{DEV_SEED_START}, "
                         f"{RESERVED_SEED_START}) only")
    for name, seeds in (("sim_seeds", sim_seeds), ("real_seeds", real_seeds)):
        if len(seeds) < 1:
            raise ValueError(f"{name} is empty; give at least one seed")


def _rmse_table(methods: Sequence[str], tasks: Sequence[str], seeds: Sequence[int], recorded: bool,
                overrides: Mapping[str, Any], progress: bool) -> dict[str, dict[str, list[float]]]:
    """task → method → per-seed RMSE, through ``evaluate_task``; a method that cannot run a task is an error."""
    from swarmloc.bench.evaluation.runner import evaluate_task
    from swarmloc.envs.world.worlds import data_missing

    out: dict[str, dict[str, list[float]]] = {}
    for task in tasks:
        spec = get_spec(task, **overrides)
        if (spec.trajectory.kind == "recorded") != recorded:
            raise ValueError(f"task {task!r} is {'not ' if recorded else ''}a recorded flight; the "
                             f"{'real' if recorded else 'sim'} side takes {'recorded' if recorded else 'simulated'} "
                             "tasks only")
        if recorded and (why := data_missing(spec)) is not None:
            raise FileNotFoundError(f"the real side needs {task}'s data, which is not here:\n{why}")
        started = time.perf_counter()
        outcome = evaluate_task(list(methods), spec, seeds)
        if outcome.unsupported:
            raise ValueError(f"method(s) cannot run {task}: {outcome.unsupported}; choose methods that run "
                             "every task of both sides")
        out[task] = {m: [float(e["rmse"]) for e in outcome.episodes[m]] for m in methods}
        if progress:
            print(f"sim_to_real: {task} × {len(seeds)} seeds, {len(methods)} methods: "
                  f"{time.perf_counter() - started:.0f} s", file=sys.stderr, flush=True)
    return out


def measure_sim_to_real(methods: Sequence[str] = DEFAULT_METHODS, sim_tasks: Sequence[str] | None = None,
                        sim_seeds: Sequence[int] | None = None, real_tasks: Sequence[str] | None = None,
                        real_seeds: Sequence[int] | None = None, *, overrides: Mapping[str, Any] | None = None,
                        n_resamples: int = DEFAULT_RESAMPLES, seed: int = DEFAULT_SEED,
                        progress: bool = False) -> dict[str, Any]:
    """Run ``methods`` on the simulated robust-ranging tasks and on the real flights, and compare their rankings.

    Every (task, seed) episode runs through ``evaluate_task`` (deterministic), then
    ``rank_agreement`` on the per-episode RMSE.

    Args:
        methods: registered names, ``REFERENCE`` among them (default ``DEFAULT_METHODS``: why these).
        sim_tasks: simulated task IDs (default: ``robust_ranging_tasks()``).
        sim_seeds: dev seeds only (default: ``sim_dev_seeds()``, 2_000_000 … 2_000_007).
        real_tasks: recorded-flight task IDs (default: ``REAL_SUITE``'s flights); their data must be
            imported (``SWARMLOC_DATA``).
        real_seeds: default ``REAL_SUITE``'s seeds (4 test seeds, each replaying the same recording).
        overrides: spec overrides for every task of both sides (``{"duration": 2.0}`` in a smoke test;
            the numbers are then not the measurement).
        n_resamples, seed: the bootstrap's.
        progress: one line per task on stderr.

    Returns:
        ``rank_agreement``'s dict plus ``"rmse": {"sim"|"real": task → method → per-seed RMSE}``,
        ``"seed_lists": {"sim", "real"}``, ``"overrides"`` and ``"seconds"``; JSON-able, what
        ``render_sim_to_real`` reads.

    Raises:
        ValueError: a non-dev sim seed, a recorded task on the sim side or a simulated one on the real
            side, an unknown task, a method that cannot run a task, or ``rank_agreement``'s errors.
        FileNotFoundError: the real flights' data is not here (the message says how to import it).
    """
    if REFERENCE not in methods:
        raise ValueError(f"methods={list(methods)} lack the reference {REFERENCE!r}; the gain needs its RMSE")
    default_tasks, default_seeds = real_episodes() if real_tasks is None or real_seeds is None else ([], [])
    sim_t = [canonical_task_id(t) for t in sim_tasks] if sim_tasks is not None else robust_ranging_tasks()
    sim_s = [int(s) for s in sim_seeds] if sim_seeds is not None else sim_dev_seeds()
    real_t = [canonical_task_id(t) for t in real_tasks] if real_tasks is not None else default_tasks
    real_s = [int(s) for s in real_seeds] if real_seeds is not None else default_seeds
    _check_seeds(sim_s, real_s)
    over = dict(overrides or {})
    started = time.perf_counter()
    rmse = {"sim": _rmse_table(methods, sim_t, sim_s, False, over, progress),
            "real": _rmse_table(methods, real_t, real_s, True, over, progress)}
    doc = rank_agreement(rmse["sim"], rmse["real"], methods=methods, n_resamples=n_resamples, seed=seed)
    doc.update(seed_lists={"sim": sim_s, "real": real_s}, overrides=over, rmse=rmse,
               seconds=round(time.perf_counter() - started, 1))
    return doc


# --------------------------------------------------------------------------- report


def render_sim_to_real(doc: Mapping[str, Any]) -> list[str]:
    """The Markdown section of ``measure_sim_to_real``'s dict: a ``##`` heading, τ with its CI, the two rankings.

    Args:
        doc: ``measure_sim_to_real``'s (or ``rank_agreement``'s) dict.

    Returns:
        The section's lines (join with ``"\\n"``).
    """
    sim, real = doc["sim"], doc["real"]
    rank = {s: {m: k + 1 for k, m in enumerate(doc[s]["ranking"])} for s in ("sim", "real")}
    rows = [[f"`{m}`", str(rank["sim"][m]), f"{sim['scores'][m]:+.3f}", str(rank["real"][m]),
             f"{real['scores'][m]:+.3f}"] for m in doc["sim"]["ranking"]]
    low, high = doc["ci"]
    seeds = doc.get("seed_lists", {})

    def episodes(side: str, note: str) -> str:
        tasks = ", ".join(f"`{task_label(t)}`" for t in doc[side]["tasks"])
        got = seeds.get(side)
        per = f"seeds {got[0]} … {got[-1]} ({len(got)} each; {note})" if got else \
            f"{'/'.join(map(str, sorted(set(doc[side]['seeds'].values()))))} seeds each ({note})"
        return f"{len(doc[side]['tasks'])} task(s) ({tasks}), {per}"

    undefined = doc["undefined_resamples"]
    tau = (f"Kendall τ-b between the two rankings: **{doc['tau']:+.2f}** ({doc['confidence']:.0%} bootstrap CI "
           f"[{low:+.2f}, {high:+.2f}]; {doc['n_resamples']} resamples of tasks and seeds on both sides, seed "
           f"{doc['seed']}" + (f"; {undefined} with τ undefined left out" if undefined else "") + ").")
    score = ("Score: mean log2(RMSE_uniform / RMSE) over a task's seeds, then over the tasks (each the same weight); "
             "rank 1 is best.")
    lines = ["## Sim-to-real rank agreement (robust-ranging track)", "", tau, "", score, "",
             f"- simulated: {episodes('sim', 'dev seeds only')};",
             f"- real: {episodes('real', 'every seed replays the same recording')}.", ""]
    if doc.get("overrides"):
        lines += [f"Shortened or changed episodes ({doc['overrides']}): not the measurement.", ""]
    lines += markdown_table(["method", "sim rank", "sim score", "real rank", "real score"], rows, "lrrrr")
    return lines + [""]
