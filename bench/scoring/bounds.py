"""The information bound of each episode (``bound_rmse``), computed once per (task, seed).

``episode_bounds(spec, seeds)`` returns one ``Bound`` per seed: the posterior Cramér–Rao
bound of ``swarmloc.envs.filter.bound`` reduced to the numbers a results file compares with its
metrics, on exactly the steps and UAVs that ``EpisodeRecorder`` scores:

* ``rmse``: the bound on the ``rmse`` metric (the episode's scored UAVs, per episode where
  the task scores each episode's healthy nodes, steps from ``scoring.start``);
* ``healthy_rmse``: the bound on the ``healthy_rmse`` metric where the task defines it (the
  healthy UAVs over the fault window: CascadedFault, CascadedFaultRandom), else None.

A task where the bound is not defined (a recorded flight, an anchor-free swarm) gets None
and the reason. ``suite_bounds(suite)`` does every episode of a suite.

Caching: per process, and in a JSON file per task spec under the user cache folder
(``platformdirs.user_cache_dir("swarmloc")/bounds``, or ``$SWARMLOC_CACHE/bounds``), keyed by
the SHA-256 of ``spec.model_dump_json()``, the seed, ``BOUND_VERSION`` and the label
threshold k; the files are written atomically and merged, so concurrent writers lose at most
some entries, which are then computed again.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from swarmloc.bench.common.files import write_text_atomic
from swarmloc.bench.evaluation import selection
from swarmloc.envs.filter.bound import (
    BOUND_LABEL_SIGMAS,
    BOUND_VERSION,
    BoundInputs,
    bound_rmse,
    pcrlb,
    record_inputs,
    unsupported_reason,
)
from swarmloc.envs.tasks.specs import TaskSpec
from swarmloc.envs.tasks.catalogue import get_spec

#: environment variable naming the folder for swarmloc's caches (default: the user cache folder)
CACHE_ENV = "SWARMLOC_CACHE"
#: the metrics a ``Bound`` bounds
BOUNDED_METRICS = ("rmse", "healthy_rmse")


@dataclass(frozen=True)
class Bound:
    """The information bound of one episode.

    Attributes:
        task: task ID; seed: episode seed.
        rmse: lower bound on the episode's ``rmse`` metric [m]; None where not defined.
        healthy_rmse: lower bound on its ``healthy_rmse`` metric [m]; None where the task does
            not define that metric or the bound is not defined.
        reason: why ``rmse`` is None (None when it has a value).
    """

    task: str
    seed: int
    rmse: float | None
    healthy_rmse: float | None
    reason: str | None

    def for_metric(self, metric: str) -> float | None:
        """The bound on ``metric`` (``rmse`` or ``healthy_rmse``)."""
        if metric not in BOUNDED_METRICS:
            raise ValueError(f"no bound for metric {metric!r}; bounded metrics: {', '.join(BOUNDED_METRICS)}")
        return getattr(self, metric)


# --------------------------------------------------------------------------- scored steps and UAVs


def scored_selection(spec: TaskSpec, schedule=None, b: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Steps ``(T,)`` and UAVs ``(N,)`` the ``rmse`` metric scores in episode b (``EpisodeRecorder``'s choice).

    Update k (0-based) is at time (k + 1)·dt; it is scored from ``scoring.start`` on. The
    UAVs are the task's scored nodes, and with ``scoring.nodes_from_schedule="healthy"``
    those episode b's ``schedule`` leaves healthy (``swarmloc.bench.evaluation.selection``).
    """
    return selection.scored_steps(spec), selection.scored_nodes(spec, schedule, b)


#: UAVs and steps of the ``healthy_rmse`` metric in one episode (the recorder's own rule)
healthy_selection = selection.healthy_selection


# --------------------------------------------------------------------------- computing


def compute_bounds(spec: TaskSpec, seeds: Sequence[int], label_sigmas: float = BOUND_LABEL_SIGMAS) -> list[Bound]:
    """The bounds of some episodes of one task, computed now (no cache): the world is simulated here.

    Args:
        spec: the task.
        seeds: episode seeds.
        label_sigmas: k: a channel-step with an injected error above k·σ is left out.

    Returns:
        One ``Bound`` per seed, in order.
    """
    seeds = [int(s) for s in seeds]
    why = unsupported_reason(spec)
    if why is not None:
        return [Bound(spec.task_id, s, None, None, why) for s in seeds]
    inputs, world = record_inputs(spec, seeds, label_sigmas)
    return bounds_from_inputs(spec, seeds, inputs, getattr(world, "schedule", None))


def bounds_from_inputs(spec: TaskSpec, seeds: Sequence[int], inputs: BoundInputs, schedule) -> list[Bound]:
    """The bounds of episodes whose inputs were recorded elsewhere (``envs.bound.BoundRecorder``).

    Args:
        spec: the task; seeds: ``(B,)`` the episodes' seeds.
        inputs: their ``BoundInputs`` (B episodes, in the order of ``seeds``).
        schedule: the world's ``FaultSchedule`` of those episodes (``world.schedule``; None for
            a world without one), which the ``healthy_rmse`` selection and a per-episode scored set
            (``scoring.nodes_from_schedule``) need.

    Returns:
        One ``Bound`` per seed.
    """
    seeds = [int(s) for s in seeds]
    why = unsupported_reason(spec)
    if why is not None:
        return [Bound(spec.task_id, s, None, None, why) for s in seeds]
    out = pcrlb(inputs)
    bounds = []
    for b, seed in enumerate(seeds):
        k = int(out.failed_at[b])
        if k >= 0:
            reason = (f"the information matrix of {spec.task_id} seed {seed} is not positive definite numerically "
                      f"at step {k + 1} (t = {(k + 1) * spec.dt:g} s): no finite bound")
            bounds.append(Bound(spec.task_id, seed, None, None, reason))
            continue
        pos_var = out.pos_var[:, b]
        steps, nodes = scored_selection(spec, schedule, b)
        healthy = healthy_selection(spec, schedule, b)
        healthy_value = None
        if healthy is not None and healthy[0].any() and healthy[1].any():
            healthy_value = bound_rmse(pos_var, healthy[1], healthy[0])
        value = bound_rmse(pos_var, steps, nodes)
        if not np.isfinite(value):
            bounds.append(Bound(spec.task_id, seed, None, None, f"{spec.task_id} scores no step or UAV"))
            continue
        bounds.append(Bound(spec.task_id, seed, value, healthy_value, None))
    return bounds


# --------------------------------------------------------------------------- caching

_MEMORY: dict[tuple[str, int, int, float], Bound] = {}


def cache_folder() -> Path:
    """Folder of the persistent bound cache (``$SWARMLOC_CACHE/bounds`` or the user cache folder)."""
    root = os.environ.get(CACHE_ENV)
    if not root:
        from platformdirs import user_cache_dir

        root = user_cache_dir("swarmloc")
    return Path(root) / "bounds"


def spec_sha256(spec: TaskSpec) -> str:
    """SHA-256 (hex) of ``spec.model_dump_json()``: the task part of the cache key."""
    return hashlib.sha256(spec.model_dump_json().encode()).hexdigest()


def _cache_file(spec_key: str, label_sigmas: float) -> Path:
    return cache_folder() / f"v{BOUND_VERSION}-k{float(label_sigmas)!r}" / f"{spec_key}.json"


def _read_cache(path: Path) -> dict[str, dict]:
    """The cached bounds of one file (seed text → fields); empty when absent or unreadable."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        return dict(data["bounds"]) if data.get("bound_version") == BOUND_VERSION else {}
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return {}


def _write_cache(path: Path, spec: TaskSpec, label_sigmas: float, new: list[Bound]) -> None:
    """Merge ``new`` into the cache file (atomically); a cache that cannot be written is skipped."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        entries = _read_cache(path)
        for bound in new:
            entries[str(bound.seed)] = {k: v for k, v in asdict(bound).items() if k not in ("task", "seed")}
        data = {"bound_version": BOUND_VERSION, "label_sigmas": float(label_sigmas), "task": spec.task_id,
                "spec_sha256": spec_sha256(spec), "bounds": entries}
        write_text_atomic(path, json.dumps(data, sort_keys=True))
    except OSError:
        pass


def episode_bounds(spec: TaskSpec | str, seeds: Sequence[int], *, label_sigmas: float = BOUND_LABEL_SIGMAS,
                   persistent: bool = True) -> list[Bound]:
    """The bounds of some episodes of one task, from the caches where they are, else computed.

    Args:
        spec: the task (or its ID).
        seeds: episode seeds.
        label_sigmas: k of the bound's labels (``envs.bound.BOUND_LABEL_SIGMAS``).
        persistent: also read and write the cache file (the per-process cache is always used).

    Returns:
        One ``Bound`` per seed, in order.
    """
    spec = get_spec(spec) if isinstance(spec, str) else spec
    key = spec_sha256(spec)
    seeds = [int(s) for s in seeds]
    path = _cache_file(key, label_sigmas)
    stored = _read_cache(path) if persistent else {}
    found: dict[int, Bound] = {}
    for seed in seeds:
        mem = _MEMORY.get((key, seed, BOUND_VERSION, float(label_sigmas)))
        if mem is not None:
            found[seed] = mem
        elif str(seed) in stored:
            e = stored[str(seed)]
            found[seed] = Bound(spec.task_id, seed, e.get("rmse"), e.get("healthy_rmse"), e.get("reason"))
    missing = list(dict.fromkeys(s for s in seeds if s not in found))
    if missing:
        computed = compute_bounds(spec, missing, label_sigmas)
        found.update({b.seed: b for b in computed})
        if persistent:
            _write_cache(path, spec, label_sigmas, computed)
    for seed, bound in found.items():
        _MEMORY[(key, seed, BOUND_VERSION, float(label_sigmas))] = bound
    return [found[s] for s in seeds]


def remember_bounds(spec: TaskSpec, bounds: Sequence[Bound], *, label_sigmas: float = BOUND_LABEL_SIGMAS,
                    persistent: bool = True) -> None:
    """Put bounds computed elsewhere (``bounds_from_inputs``) into the caches ``episode_bounds`` reads.

    Args:
        spec: the task they belong to; bounds: its episodes' bounds.
        label_sigmas: the k they were computed with.
        persistent: also merge them into the cache file.
    """
    key = spec_sha256(spec)
    for bound in bounds:
        _MEMORY[(key, bound.seed, BOUND_VERSION, float(label_sigmas))] = bound
    if persistent and bounds:
        _write_cache(_cache_file(key, label_sigmas), spec, label_sigmas, list(bounds))


def suite_bounds(suite, *, label_sigmas: float = BOUND_LABEL_SIGMAS,
                 persistent: bool = True) -> dict[tuple[str, int], Bound]:
    """The bound of every episode of a suite (one batch per task).

    Args:
        suite: a ``swarmloc.bench.evaluation.suites.Suite``.
        label_sigmas, persistent: as in ``episode_bounds``.

    Returns:
        ``(task ID, seed) → Bound`` for every episode of the suite.
    """
    out: dict[tuple[str, int], Bound] = {}
    for task in suite.tasks:
        for bound in episode_bounds(get_spec(task), suite.seeds(task), label_sigmas=label_sigmas,
                                    persistent=persistent):
            out[(task, bound.seed)] = bound
    return out


def clear_memory_cache() -> None:
    """Forget the bounds cached in this process (the cache files stay)."""
    _MEMORY.clear()
