"""The score: how many times lower the error is than the standard CEKF's, per task and over a suite.

Per episode the **gain** over uniform trust (the standard CEKF, α = 1, on the same episode)::

    g = log2(RMSE_uniform / RMSE_method)        (g = 1: half the error; g = −1: twice)

A task's score ``G_t`` is the mean of g over its seeds; the suite score ``S`` is the mean of
``G_t`` over the tasks the method covers (tasks weigh equally, whatever their seed count),
shown as ``2^S``: "× lower error than the standard CEKF". Its 95 % CI is a stratified
bootstrap: seeds are resampled within each task, and ``S`` recomputed (rliable's
recommendation for few runs per task). A log ratio bounds what one bad task can do: a
method that diverges to 150 m where uniform has 1.5 m loses log2(100) ≈ 6.6 on that task,
not the −50 that a score normalized by the gap to an oracle gave it (benchmark v0's, retired).

Beside it, the information bound (``bound_rmse``, the posterior Cramér–Rao bound of the
episode) gives each task an **achievable** gain ``A_t = mean log2(RMSE_uniform / bound)``
and a **gap closed** ``G_t / A_t``, defined where ``A_t ≥ log2 1.25`` (a task where even
the bound is within 25 % of uniform has no gap worth a ratio). Also here: the IQM of g
(Agarwal et al. 2021, rliable; ``docs/references.md`` [rliable]); rliable's performance profiles
and probability of improvement are in :mod:`swarmloc.bench.scoring.profiles`.

A method that cannot run a task (null RMSE on any of its seeds) has no ``G_t`` there: its
coverage is k/T, and it is compared only on the tasks it covers.

**Score v2** (benchmark v2; ``docs/scoring.md``, "Score v2"): the same g and ``G_t`` on the v2
backbone, but each task *family* (:func:`~swarmloc.bench.scoring.families.task_family`) weighs the same:
``S = mean_f mean_{t ∈ f} G_t`` over the families with a covered task, and the CI is the
hierarchical bootstrap (families, then seeds within their tasks;
:func:`~swarmloc.bench.scoring.bootstrap.hierarchical_means`). Beside it the **cooperation
gain**, ``log2(RMSE_non-cooperative / RMSE)`` per episode aggregated the same way (on the same
draws), where the non-cooperative method's RMSE on the same (task, seed) is given. Which score
a suite gets is :func:`score_version`'s one decision: suites of benchmark v2 (names ending
``-v2``) score v2, every other suite (v0, v1, unversioned) score v1 unchanged; every function
below takes the version from the ``SuiteScore`` it is given, so ranks and the paired
comparison of a v2 suite resample families too.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from swarmloc.bench.scoring.bootstrap import (
    DEFAULT_CONFIDENCE,
    DEFAULT_RESAMPLES,
    DEFAULT_SEED,
    hierarchical_means,
    percentile_interval,
    resampled_means,
)
from swarmloc.bench.scoring.families import group_by_family
from swarmloc.bench.scoring.stats import iqm

#: tasks whose bound is within this ratio of uniform have no gap-closed ratio
MIN_ACHIEVABLE_GAIN = math.log2(1.25)

#: the scores this module computes (see :func:`score_version`)
SCORE_VERSIONS: tuple[int, ...] = (1, 2)

#: a suite name's benchmark version, ``standard-v2`` or a part of it, ``standard-v2-subset``
_SUITE_VERSION = re.compile(r"-v(\d+)(?:-subset)?$")


def score_version(suite: str | None) -> int:
    """The score a suite is ranked by: 2 for benchmark v2 suites, 1 for every other.

    A suite name ending ``-v<N>`` (optionally ``-subset``, a run of part of it) with N ≥ 2 is
    scored by score v2 (family-weighted, hierarchical CI); v0, v1 and unversioned suites
    (``quick``, ``dev``), and no suite at all, keep score v1 exactly. A later benchmark that
    changes the score adds its number to ``SCORE_VERSIONS`` and its rule here.

    >>> score_version("standard-v1"), score_version("standard-v2"), score_version("quick-v2-subset"), score_version(None)
    (1, 2, 2, 1)
    """
    match = _SUITE_VERSION.search(suite or "")
    return 2 if match is not None and int(match.group(1)) >= 2 else 1


def episode_gain(rmse_uniform: float | None, rmse: float | None) -> float | None:
    """``log2(RMSE_uniform / RMSE)`` of one episode; None when either is missing or not positive."""
    if rmse_uniform is None or rmse is None:
        return None
    if not (math.isfinite(rmse_uniform) and math.isfinite(rmse)) or rmse_uniform <= 0.0 or rmse <= 0.0:
        return None
    return math.log2(rmse_uniform / rmse)


@dataclass(frozen=True)
class TaskScore:
    """One method on one task.

    Attributes:
        task: task ID.
        gains: ``(n,)`` per-seed gains g, in the order the episodes came.
        mean: ``G_t``, the mean gain.
        achievable: ``A_t`` = mean log2(RMSE_uniform / bound), None where the bound is undefined.
        gap_closed: ``G_t / A_t`` where ``A_t ≥ log2 1.25``, else None.
        seeds: ``(n,)`` the episode seed of each gain (None when not given): what pairs two methods.
    """

    task: str
    gains: np.ndarray
    mean: float
    achievable: float | None
    gap_closed: float | None
    seeds: np.ndarray | None = None


@dataclass(frozen=True)
class CooperationGain:
    """Score v2's cooperation gain: ``log2(RMSE_non-cooperative / RMSE)`` per episode, aggregated as S.

    Attributes:
        S: mean over families of the mean over their tasks of the mean gain (log2 units; > 0:
            cooperating, as this method does it, beats each UAV localizing alone).
        ci_low, ci_high: its hierarchical-bootstrap 95 % CI (the draws of the score's own CI).
        tasks: task → ``TaskScore`` of the per-seed cooperation gains (no achievable gain).
    """

    S: float
    ci_low: float
    ci_high: float
    tasks: dict[str, TaskScore]


@dataclass(frozen=True)
class SuiteScore:
    """One method on a suite (on the tasks it covers).

    Attributes:
        S: score v1: mean over covered tasks of ``G_t``; score v2: mean over families of the
            mean over their covered tasks of ``G_t`` (log2 units).
        ci_low, ci_high: 95 % CI of S: stratified bootstrap (v1), hierarchical (v2).
        iqm: interquartile mean of every covered episode's g.
        gap_closed: ``Σ G_t / Σ A_t`` over the tasks with a defined gap (None if none).
        tasks: task → ``TaskScore`` for covered tasks.
        uncovered: tasks of the suite the method could not run.
        version: the score (:func:`score_version`).
        families: score v2: family → its covered tasks (what the bootstrap resamples); v1: empty.
        cooperation: score v2: the cooperation gain, where the non-cooperative RMSE of every
            covered episode was given; else None.
    """

    S: float
    ci_low: float
    ci_high: float
    iqm: float
    gap_closed: float | None
    tasks: dict[str, TaskScore]
    uncovered: tuple[str, ...]
    version: int = 1
    families: dict[str, tuple[str, ...]] = field(default_factory=dict)
    cooperation: CooperationGain | None = None

    @property
    def times(self) -> float:
        """``2^S``: how many times lower the error is than uniform's (geometric mean over tasks)."""
        return 2.0**self.S

    @property
    def times_ci(self) -> tuple[float, float]:
        """The CI of ``2^S``."""
        return 2.0**self.ci_low, 2.0**self.ci_high

    @property
    def coverage(self) -> tuple[int, int]:
        """``(k, T)``: tasks covered out of the suite's."""
        return len(self.tasks), len(self.tasks) + len(self.uncovered)


def task_score(task: str, gains: Sequence[float], achievable: Sequence[float | None] | None = None,
               seeds: Sequence[int] | None = None) -> TaskScore:
    """``G_t``, ``A_t`` and gap closed of one task from its per-seed gains and achievable gains.

    Args:
        task: task ID.
        gains: per-seed g (all defined).
        achievable: per-seed log2(RMSE_uniform / bound); ``A_t`` is None if any is None.
        seeds: the seed of each gain (kept for pairing methods).
    """
    g = np.asarray(gains, dtype=np.float64)
    if g.size == 0 or not np.isfinite(g).all():
        raise ValueError(f"task {task}: gains must be a non-empty list of finite numbers, got {gains!r}")
    mean = float(g.mean())
    a = None
    if achievable is not None and len(achievable) and all(v is not None for v in achievable):
        a = float(np.mean(np.asarray(achievable, dtype=np.float64)))
    closed = mean / a if a is not None and a >= MIN_ACHIEVABLE_GAIN else None
    seed_arr = None if seeds is None else np.asarray(seeds, dtype=np.int64)
    if seed_arr is not None and seed_arr.shape != g.shape:
        raise ValueError(f"task {task}: {seed_arr.size} seeds for {g.size} gains")
    return TaskScore(task=task, gains=g, mean=mean, achievable=a, gap_closed=closed, seeds=seed_arr)


def bootstrap_suite_ci(tasks: Sequence[np.ndarray], n_resamples: int = DEFAULT_RESAMPLES,
                       seed: int = DEFAULT_SEED, confidence: float = DEFAULT_CONFIDENCE) -> tuple[float, float]:
    """Stratified-bootstrap CI of the mean over tasks of the per-task mean.

    Each resample draws every task's seeds with replacement (within the task) and
    recomputes the mean of task means; the CI is the percentile interval
    (:mod:`swarmloc.bench.scoring.bootstrap`).

    Args:
        tasks: per task, ``(n_t,)`` values.
        n_resamples: resamples (≥ 1).
        seed: generator seed (the CI is reproducible).
        confidence: coverage in (0, 1).
    """
    if not tasks:
        raise ValueError("need at least one task")
    low, high = percentile_interval(_resampled_suite_mean(resampled_means(tasks, n_resamples, seed)), confidence)
    return float(low), float(high)


def _resampled_suite_mean(task_means: Sequence[np.ndarray]) -> np.ndarray:
    """``(..., R)``: the resampled S, the mean over tasks of their ``(..., R)`` resampled means."""
    return sum(task_means) / len(task_means)


def _families(version: int, tasks: Iterable[str]) -> dict[str, tuple[str, ...]]:
    """What the suite statistic averages over: score v2, family → tasks; score v1, nothing (tasks directly)."""
    if version not in SCORE_VERSIONS:
        raise ValueError(f"unknown score version {version!r}; allowed: {list(SCORE_VERSIONS)}")
    return {} if version == 1 else {f: tuple(ts) for f, ts in group_by_family(tasks).items()}


def suite_statistic(families: Mapping[str, Sequence[str]], task_values: Mapping[str, float | np.ndarray]) -> np.ndarray:
    """S from per-task values: their mean (no families, v1) or the mean over families of the family means (v2).

    Args:
        families: family → its tasks (score v2), or empty (score v1: tasks weigh equally).
        task_values: task → a number (``G_t``) or an array of one shape for every task (a profile
            over thresholds): the statistic is taken elementwise.

    Returns:
        The statistic, of the values' shape (0-d for numbers).
    """
    if not families:
        return np.mean(list(task_values.values()), axis=0)
    return np.mean([np.mean([task_values[t] for t in tasks], axis=0) for tasks in families.values()], axis=0)


def resampled_suite(families: Mapping[str, Sequence[str]], values: Mapping[str, np.ndarray], n_resamples: int,
                    seed: int) -> np.ndarray:
    """``(..., R)``: S of every resample of the per-task ``(..., n_t)`` values (rows of methods stay paired).

    No families (score v1): the stratified bootstrap of :func:`bootstrap_suite_ci`; families
    (score v2): the hierarchical one. Either way the draws depend on the structure only.
    """
    if not families:
        return _resampled_suite_mean(resampled_means(list(values.values()), n_resamples, seed))
    return hierarchical_means([[values[t] for t in tasks] for tasks in families.values()], n_resamples, seed)


def _episode_fields(ep: Mapping | object) -> tuple[str, int, Mapping]:
    """``(task, seed, metrics)`` of a results-file episode or its dump."""
    if isinstance(ep, Mapping):
        task, seed, m = ep["task"], ep["seed"], ep["metrics"]
    else:
        task, seed, m = ep.task, ep.seed, ep.metrics  # type: ignore[attr-defined]
    return str(task), int(seed), m if isinstance(m, Mapping) else m.model_dump()


def _cooperation_gain(rows: Mapping[str, list[tuple[int, float | None]]], families: Mapping[str, Sequence[str]],
                      n_resamples: int, seed: int) -> CooperationGain | None:
    """The cooperation gain over the covered tasks; None unless every covered episode has one."""
    if any(g is None for task_rows in rows.values() for _, g in task_rows):
        return None
    tasks = {task: task_score(task, [g for _, g in r], seeds=[s for s, _ in r]) for task, r in rows.items()}
    low, high = percentile_interval(resampled_suite(families, {t: v.gains for t, v in tasks.items()},
                                                    n_resamples, seed))
    return CooperationGain(float(suite_statistic(families, {t: v.mean for t, v in tasks.items()})), float(low),
                           float(high), tasks)


def suite_score(episodes: Iterable[Mapping], suite_tasks: Sequence[str] | None = None, *, suite: str | None = None,
                non_cooperative: Mapping[tuple[str, int], float | None] | None = None,
                n_resamples: int = DEFAULT_RESAMPLES, seed: int = DEFAULT_SEED) -> SuiteScore | None:
    """The score of one method from its per-episode metrics, score v1 or v2 as the suite says.

    Args:
        episodes: ``{"task", "seed", "metrics": {"rmse", "uniform_rmse", "bound_rmse", ...}}``
            (results-file episodes or their dumps).
        suite_tasks: every task of the suite (for coverage); default: the tasks seen.
        suite: the suite's name; it picks the score (:func:`score_version`; None: score v1).
        non_cooperative: (task, seed) → the ``non-cooperative`` method's RMSE on that episode
            (from its own results: :func:`rmse_by_episode`); score v2 computes the cooperation
            gain from it. Ignored by score v1.
        n_resamples, seed: of the bootstrap.

    Returns:
        The ``SuiteScore``, or None when the method covers no task.
    """
    version = score_version(suite)
    by_task: dict[str, list[tuple[float | None, float | None, int, float | None]]] = {}
    for ep in episodes:
        task, episode_seed, m = _episode_fields(ep)
        gain = episode_gain(m.get("uniform_rmse"), m.get("rmse"))
        bound = m.get("bound_rmse")
        cooperation = None if non_cooperative is None else episode_gain(non_cooperative.get((task, episode_seed)),
                                                                         m.get("rmse"))
        by_task.setdefault(task, []).append(
            (gain, episode_gain(m.get("uniform_rmse"), bound) if bound else None, episode_seed, cooperation))
    all_tasks = list(suite_tasks) if suite_tasks is not None else list(by_task)
    covered: dict[str, TaskScore] = {}
    for task in all_tasks:
        rows = by_task.get(task, [])
        if rows and all(g is not None for g, _, _, _ in rows):
            covered[task] = task_score(task, [r[0] for r in rows], [r[1] for r in rows], [r[2] for r in rows])
    if not covered:
        return None
    families = _families(version, covered)
    S = float(suite_statistic(families, {t: v.mean for t, v in covered.items()}))
    low, high = percentile_interval(resampled_suite(families, {t: v.gains for t, v in covered.items()},
                                                    n_resamples, seed))
    cooperation = None
    if version >= 2 and non_cooperative is not None:
        cooperation = _cooperation_gain({t: [(r[2], r[3]) for r in by_task[t]] for t in covered}, families,
                                        n_resamples, seed)
    # the gain realised over the gain achievable, summed over the tasks with a gap: a ratio of sums, so
    # that one task with a small achievable gain cannot swamp the suite (a mean of ratios would)
    gapped = [t for t in covered.values() if t.gap_closed is not None]
    closed = sum(t.mean for t in gapped) / sum(t.achievable for t in gapped) if gapped else None
    return SuiteScore(S=S, ci_low=float(low), ci_high=float(high),
                      iqm=iqm(np.concatenate([t.gains for t in covered.values()])),
                      gap_closed=closed, tasks=covered, uncovered=tuple(t for t in all_tasks if t not in covered),
                      version=version, families=families, cooperation=cooperation)


def rmse_by_episode(episodes: Iterable[Mapping]) -> dict[tuple[str, int], float | None]:
    """(task, seed) → RMSE of one method's episodes: a reference for other methods on the same episodes.

    How score v2 gets ``non-cooperative``'s per-episode RMSE: results files carry only
    uniform's (``uniform_rmse``), so a board passes the ``non-cooperative`` entry's own
    episodes through this to :func:`suite_score`.
    """
    out = {}
    for ep in episodes:
        task, episode_seed, m = _episode_fields(ep)
        out[(task, episode_seed)] = m.get("rmse")
    return out


def _paired_gains(scores: Sequence[SuiteScore], task: str) -> np.ndarray:
    """``(methods, n)``: each score's gains on ``task`` in seed order, checked to be the same episodes."""
    seeds, rows = None, []
    for score in scores:
        t = score.tasks.get(task)
        if t is None or t.seeds is None:
            raise ValueError(f"every score must cover {task} with its seeds to be paired")
        order = np.argsort(t.seeds, kind="stable")
        if seeds is not None and not np.array_equal(t.seeds[order], seeds):
            raise ValueError(f"{task}: the scores ran different seeds; only the same episodes pair")
        seeds = t.seeds[order]
        rows.append(t.gains[order])
    return np.stack(rows)


def paired_resamples(scores: Sequence[SuiteScore], n_resamples: int,
                     seed: int) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Per task the ``(methods, n)`` paired gains, and the ``(methods, n_resamples)`` resampled S.

    The scores' own bootstrap (stratified for score v1, hierarchical for v2), paired: each
    resample draws the families and a task's seeds once and applies that draw to every
    method, so two methods are compared episode by episode (same task, same seed: the same world).

    Raises:
        ValueError: the scores cover different tasks or seeds, carry no seeds, or were computed
            under different score versions.
    """
    tasks = list(dict.fromkeys(task for score in scores for task in score.tasks))  # _paired_gains: all cover each
    gains = {task: _paired_gains(scores, task) for task in tasks}
    kinds = {(score.version, tuple(score.families.items())) for score in scores}
    if len(kinds) > 1:
        raise ValueError(f"the scores were computed under different score versions "
                         f"{sorted({score.version for score in scores})}; only one suite's scores pair")
    return gains, resampled_suite(scores[0].families, gains, n_resamples, seed)


def separable_ranks(scores: Sequence[SuiteScore], n_resamples: int = DEFAULT_RESAMPLES, seed: int = DEFAULT_SEED,
                    confidence: float = DEFAULT_CONFIDENCE) -> list[int]:
    """Each method's rank as 1 + the number of others whose S is higher beyond doubt.

    "Beyond doubt": the CI of the paired difference ``S_other − S_this`` lies above 0
    (:func:`paired_resamples`: the same episodes, one shared draw of seeds, and of families
    under score v2). Two methods
    whose difference the seeds cannot resolve share a rank. Ranks are not always
    consecutive: with A ahead of B beyond doubt and C level with both, the ranks are 1, 2, 1.

    Args:
        scores: suite scores covering the same tasks with the same seeds (every method of a
            suite's ranked table does).
        n_resamples, seed: of the bootstrap.
        confidence: of the CI, in (0, 1).

    Raises:
        ValueError: the scores cover different tasks or seeds, carry no seeds, or differ in score version.
    """
    if not scores:
        return []
    _, resampled = paired_resamples(scores, n_resamples, seed)  # (methods, n_resamples): resampled S
    return ranks_beyond_doubt(resampled, confidence)


def ranks_beyond_doubt(resampled: np.ndarray, confidence: float = DEFAULT_CONFIDENCE) -> list[int]:
    """1 + the number of rows whose lead over each row is beyond doubt (its paired CI lies above 0).

    Args:
        resampled: ``(methods, R)`` the resampled statistic of each method, on paired draws.
        confidence: of the CI, in (0, 1).
    """
    ranks = []
    for i in range(len(resampled)):
        low, _ = percentile_interval(resampled - resampled[i], confidence)  # (methods,): the lower CI end of each lead
        ranks.append(1 + int(np.sum(low > 0.0)))
    return ranks


@dataclass(frozen=True)
class PairedDifference:
    """``B − A`` in gain, episode by episode, with its paired 95 % CI.

    Attributes:
        mean: the difference of the means (of S, or of ``G_t`` on one task).
        ci_low, ci_high: the paired bootstrap CI: the suite's by the scores' bootstrap (stratified
            for score v1, hierarchical for v2), a task's by resampling its seeds.
        ahead: episodes (one task) or tasks (the suite) where B's mean gain is the higher.
        count: episodes (one task) or tasks (the suite) compared.
    """

    mean: float
    ci_low: float
    ci_high: float
    ahead: int
    count: int


def paired_difference(a: SuiteScore, b: SuiteScore, n_resamples: int = DEFAULT_RESAMPLES,
                      seed: int = DEFAULT_SEED, confidence: float = DEFAULT_CONFIDENCE
                      ) -> tuple[PairedDifference, dict[str, PairedDifference]]:
    """How much B gains over A: ``S_B − S_A`` and, per task, ``G_B − G_A``, with paired CIs.

    The CIs come from the same paired bootstrap that ranks the leaderboard
    (:func:`separable_ranks`): B is ahead of A beyond doubt exactly when the suite CI is above 0.

    Args:
        a, b: suite scores of the same tasks and seeds.
        n_resamples, seed: of the bootstrap.
        confidence: of the CIs, in (0, 1).

    Returns:
        ``(suite difference, task → difference)``.

    Raises:
        ValueError: the scores cover different tasks or seeds, or carry no seeds.
    """
    per_task, suite = paired_resamples([a, b], n_resamples, seed)
    tasks = {}
    for (task, gains), resampled in zip(per_task.items(), resampled_means(list(per_task.values()), n_resamples, seed)):
        low, high = percentile_interval(resampled[1] - resampled[0], confidence)
        tasks[task] = PairedDifference(float(np.mean(gains[1] - gains[0])), float(low), float(high),
                                       int(np.sum(gains[1] > gains[0])), int(gains.shape[1]))
    low, high = percentile_interval(suite[1] - suite[0], confidence)
    means = {task: d.mean for task, d in tasks.items()}
    return (PairedDifference(float(suite_statistic(a.families, means)), float(low), float(high),
                             sum(m > 0 for m in means.values()), len(means)), tasks)
