"""Evaluation suites: frozen lists of (task ID, seed) episodes.

Seed ranges live in ``swarmloc.envs.tasks.seeds`` (training ``[0, 1_000_000)``, test from
1_000_000, dev from 2_000_000; methods never see seeds): ``standard-v0`` and ``quick`` use
test seeds 1_000_000 + i, ``dev`` uses 2_000_000 + i.

Training code must call :func:`check_training_seeds` on the seeds it draws; tuning may
use dev seeds, never test seeds. Suites:

* ``standard-v1`` — the leaderboard suite of benchmark v1: every simulated v1 task
  (:data:`STANDARD_V1_TASKS`: the recalibrated families, the randomized ``*Random-v1`` tasks
  and their ``*RandomShifted-v1`` shifted splits, TDOA-v1), 32 test seeds each. Its hash
  covers the task specs as well as the episodes.
* ``quick-v1`` / ``dev-v1`` — the same tasks, the first 4 test seeds (demos, smoke tests,
  the default of ``swarmloc demo`` and ``swarmloc evaluate``) / 8 dev seeds (tuning).
* ``standard-v0`` — the v0 leaderboard suite: the 17 tasks of v0 (:data:`STANDARD_V0_TASKS`,
  frozen), 32 test seeds each (1_000_000 … 1_000_031). Its SHA-256 is pinned in the tests.
* ``quick`` / ``dev`` — the v0 simulated tasks and TDOA-v1 (:data:`QUICK_V0_TASKS`, frozen),
  the first 4 test seeds / 8 dev seeds (2_000_000 … 2_000_007).

* ``real-v0`` — real flights replayed from imported data (:data:`REAL_V0_TASKS`: the UTIL
  Crazyflie flight ``UTILFlight-v0``), 4 test seeds each. Every seed replays the same
  recording (the seed moves only the initial prior). It runs only where the data is
  imported (``SWARMLOC_DATA``); :func:`require_data` says what is missing and how to
  import it.

* ``standard-v2`` — the leaderboard suite of benchmark v2: the v2 tasks of both tracks that passed
  every admission criterion on dev seeds (:data:`STANDARD_V2_TASKS`, from docs/calibration-v2.json),
  32 test seeds each; its hash covers the task specs and the calibration's rows
  (:data:`CALIBRATION_V2_SHA256`). Tracks are scored apart (``scoring.tracks``), with score v2.
* ``quick-v2`` / ``dev-v2`` — the same tasks, the first 4 test seeds / 8 dev seeds. The
  robust-ranging track's real flights are ``real-v1``.

* ``real-v1`` — the real flights of v1 (:data:`REAL_V1_TASKS`): ``UTILFlight-v1`` (the TWR
  flight with Vicon-frame anchors) and the eight UTIL TDOA flights (TDOA2 and TDOA3, line of
  sight and NLOS with wood, cardboard, plastic and metal obstacles), 4 test seeds each; it
  needs the imported ``util-twr`` and ``util-tdoa`` data (``swarmloc data import-util``,
  ``swarmloc data import-util-tdoa``).

Tasks that replay recorded flights (trajectory kind ``recorded``) need a data set the
repository does not ship, so the catalogue-wide suites leave them out.

The hash of a suite is :func:`swarmloc.bench.evaluation.results.suite_sha256` of its episode list
(the sorted (task, seed) pairs as compact JSON), the same value a results file records.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

from swarmloc.bench.evaluation.results import suite_sha256
from swarmloc.envs.tasks.seeds import (  # noqa: F401  (re-exported: the suites' seed ranges)
    DEV_SEED_START,
    RESERVED_SEED_START,
    TEST_SEED_START,
    TRAINING_SEED_LIMIT,
    check_training_seeds,
)
from swarmloc.envs.tasks.catalogue import CATALOGUE, canonical_task_id, get_spec
from swarmloc.envs.tasks.v1 import CATALOGUE_V1


#: the tasks of ``standard-v0`` (frozen with the suite)
STANDARD_V0_TASKS: tuple[str, ...] = (
    "swarmloc/Ideal-v0",
    "swarmloc/NLOS-v0",
    "swarmloc/NLOSStep-v0",
    "swarmloc/Scale2-v0",
    "swarmloc/Scale4-v0",
    "swarmloc/Scale6-v0",
    "swarmloc/Scale8-v0",
    "swarmloc/Scale16-v0",
    "swarmloc/Scale32-v0",
    "swarmloc/CascadedFault-v0",
    "swarmloc/CascadedFaultRandom-v0",
    "swarmloc/VisionLoss-v0",
    "swarmloc/Indoor-v0",
    "swarmloc/HybridNoise10-v0",
    "swarmloc/HybridNoise30-v0",
    "swarmloc/HybridNoise50-v0",
    "swarmloc/GradualFault-v0",
)


@dataclass(frozen=True)
class Suite:
    """A frozen list of episodes.

    Attributes:
        name: e.g. ``standard-v0``.
        version: version string (bumped whenever the episode list changes).
        episodes: ``(task ID, seed)`` pairs, grouped by task in catalogue order.
        description: one line.
    """

    name: str
    version: str
    episodes: tuple[tuple[str, int], ...]
    description: str = ""
    specs: tuple[str, ...] = ()
    sha256: str = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "sha256", suite_sha256(self.episodes, self.specs))

    @property
    def tasks(self) -> list[str]:
        """Task IDs in suite order (each once)."""
        return list(dict.fromkeys(task for task, _ in self.episodes))

    def seeds(self, task: str) -> list[int]:
        """Seeds of ``task`` in suite order."""
        return [s for t, s in self.episodes if t == task]


def _episodes(tasks: Iterable[str], start: int, count: int) -> tuple[tuple[str, int], ...]:
    return tuple((task, start + i) for task in tasks for i in range(count))


def _standard_v0() -> Suite:
    return Suite("standard-v0", "0", _episodes(STANDARD_V0_TASKS, TEST_SEED_START, 32),
                 "leaderboard suite: 17 tasks × 32 test seeds (1_000_000 … 1_000_031)")


def simulated_tasks() -> list[str]:
    """Catalogue tasks that run without external data (not recorded-flight replays)."""
    return [t for t in CATALOGUE if get_spec(t).trajectory.kind != "recorded"]


#: the tasks of ``quick`` and ``dev`` (frozen with them: the simulated tasks of the catalogue
#: before benchmark v1's tasks, which are in ``quick-v1`` and ``dev-v1``)
QUICK_V0_TASKS: tuple[str, ...] = STANDARD_V0_TASKS + ("swarmloc/AnchorFree-v0", "swarmloc/TDOA-v1")


def _quick() -> Suite:
    return Suite("quick", "0", _episodes(QUICK_V0_TASKS, TEST_SEED_START, 4),
                 "the v0 simulated tasks (and TDOA-v1) × the first 4 test seeds (smoke tests)")


def _dev() -> Suite:
    return Suite("dev", "0", _episodes(QUICK_V0_TASKS, DEV_SEED_START, 8),
                 "the v0 simulated tasks (and TDOA-v1) × 8 dev seeds (2_000_000 … 2_000_007), for tuning")


#: the tasks of ``standard-v1``: every simulated v1 task, in-distribution and shifted splits
#: (``envs/tasks/v1.py``), plus the simulated TDOA room
STANDARD_V1_TASKS: tuple[str, ...] = ("swarmloc/TDOA-v1",) + tuple(CATALOGUE_V1)


def _standard_v1() -> Suite:
    tasks = STANDARD_V1_TASKS
    return Suite("standard-v1", "1", _episodes(tasks, TEST_SEED_START, 32),
                 f"leaderboard suite v1: {len(tasks)} tasks (in-distribution and shifted splits) × 32 test seeds "
                 "(1_000_000 … 1_000_031); the hash covers the task specs", specs=_specs(tasks))


def _quick_v1() -> Suite:
    return Suite("quick-v1", "1", _episodes(STANDARD_V1_TASKS, TEST_SEED_START, 4),
                 "standard-v1's tasks × the first 4 test seeds (demo, smoke tests)", specs=_specs(STANDARD_V1_TASKS))


def _dev_v1() -> Suite:
    return Suite("dev-v1", "1", _episodes(STANDARD_V1_TASKS, DEV_SEED_START, 8),
                 "standard-v1's tasks × 8 dev seeds (2_000_000 … 2_000_007), for tuning",
                 specs=_specs(STANDARD_V1_TASKS))


def _specs(tasks: Iterable[str]) -> tuple[str, ...]:
    """The canonical JSON of each task's spec, the part of a v1 suite's hash that names the tasks."""
    return tuple(get_spec(t).model_dump_json() for t in tasks)


#: the tasks of ``real-v0`` (frozen with the suite)
REAL_V0_TASKS: tuple[str, ...] = ("swarmloc/UTILFlight-v0",)


def _real_v0() -> Suite:
    return Suite("real-v0", "0", _episodes(REAL_V0_TASKS, TEST_SEED_START, 4),
                 "real flights replayed from imported data (UTIL twr-obs-log1) × 4 test seeds; needs SWARMLOC_DATA")


#: the tasks of ``real-v1`` (frozen with the suite): the TWR flight with Vicon-frame anchors and
#: the eight UTIL TDOA flights (``tasks.UTIL_TDOA_FLIGHTS``)
REAL_V1_TASKS: tuple[str, ...] = (
    "swarmloc/UTILFlight-v1",
    "swarmloc/UTILC0425Tdoa2Los-v1",
    "swarmloc/UTILC0425Tdoa3Los-v1",
    "swarmloc/UTILC0426Tdoa2NoLabel-v1",
    "swarmloc/UTILC0426Tdoa2Wood-v1",
    "swarmloc/UTILC0426Tdoa2WoodCardPlasticMetal-v1",
    "swarmloc/UTILC0426Tdoa3NoObs-v1",
    "swarmloc/UTILC0426Tdoa3WoodCardPlasticMetal-v1",
    "swarmloc/UTILC0607Tdoa2WoodPlasticMetal-v1",
)


def _real_v1() -> Suite:
    return Suite("real-v1", "1", _episodes(REAL_V1_TASKS, TEST_SEED_START, 4),
                 "real UTIL flights (TWR with Vicon-frame anchors, 8 TDOA flights) × 4 test seeds; "
                 "needs SWARMLOC_DATA")


#: the headline of benchmark v2: the v2 tasks that pass every admission criterion of their track on dev seeds
#: (``swarmloc reproduce calibration --version 2`` → docs/calibration-v2.json, its ``in_headline`` rows, frozen
#: here before any test-seed evaluation; a test holds the two equal)
STANDARD_V2_TASKS: tuple[str, ...] = (
    "swarmloc/Scale8-v2",
    "swarmloc/Scale16-v2",
    "swarmloc/Scale32-v2",
    "swarmloc/ScaleRandom-v2",
    "swarmloc/ScaleRandomShifted-v2",
    "swarmloc/GradualFault-v2",
    "swarmloc/GradualFaultRandom-v2",
    "swarmloc/GradualFaultRandomShifted-v2",
    "swarmloc/AnchorNLOS-v2",
    "swarmloc/AnchorNLOSRandom-v2",
    "swarmloc/AnchorNLOSRandomShifted-v2",
    "swarmloc/TDOA-v2",
)
#: SHA-256 of docs/calibration-v2.json's rows (``calibration_v2.rows_sha256``), covered by the v2 suites' hashes
CALIBRATION_V2_SHA256 = "4a84d54ac827ffa670e26ff6597b66299e071519a051214b8027477f7090fb93"


def _v2_specs(tasks: Iterable[str]) -> tuple[str, ...]:
    """What a v2 suite's hash covers beside its episodes: the task specs and the calibration that admitted them."""
    return _specs(tasks) + (f"calibration-v2 rows sha256 {CALIBRATION_V2_SHA256}",)


def _standard_v2() -> Suite:
    tasks = STANDARD_V2_TASKS
    return Suite("standard-v2", "2", _episodes(tasks, TEST_SEED_START, 32),
                 f"leaderboard suite v2: the {len(tasks)} headline tasks of both tracks (admitted on dev seeds, "
                 "docs/calibration-v2.md) × 32 test seeds (1_000_000 … 1_000_031); the hash covers the task specs "
                 "and the calibration", specs=_v2_specs(tasks))


def _quick_v2() -> Suite:
    return Suite("quick-v2", "2", _episodes(STANDARD_V2_TASKS, TEST_SEED_START, 4),
                 "standard-v2's tasks × the first 4 test seeds (demo, smoke tests)", specs=_v2_specs(STANDARD_V2_TASKS))


def _dev_v2() -> Suite:
    return Suite("dev-v2", "2", _episodes(STANDARD_V2_TASKS, DEV_SEED_START, 8),
                 "standard-v2's tasks × 8 dev seeds (2_000_000 … 2_000_007), for tuning",
                 specs=_v2_specs(STANDARD_V2_TASKS))


SUITES = {"standard-v0": _standard_v0, "quick": _quick, "dev": _dev, "real-v0": _real_v0,
          "standard-v1": _standard_v1, "quick-v1": _quick_v1, "dev-v1": _dev_v1, "real-v1": _real_v1,
          "standard-v2": _standard_v2, "quick-v2": _quick_v2, "dev-v2": _dev_v2}


def missing_data(suite: Suite) -> dict[str, str]:
    """Tasks of ``suite`` whose external data is absent here, with the reason (empty: it runs here).

    Args:
        suite: the suite.

    Returns:
        task ID → message naming where the data comes from and the command that imports it.
    """
    from swarmloc.envs.world.worlds import data_missing

    found = {}
    for task in suite.tasks:
        why = data_missing(get_spec(task))
        if why is not None:
            found[task] = why
    return found


def require_data(suite: Suite) -> None:
    """Refuse to run a suite whose external data is absent here.

    Raises:
        FileNotFoundError: naming the suite, the tasks, where the data comes from and how to
            import it.
    """
    missing = missing_data(suite)
    if missing:
        first = next(iter(missing.values()))
        raise FileNotFoundError(f"suite {suite.name!r} needs data that is not here (task(s) "
                                f"{', '.join(missing)}):\n{first}")


def suite_names() -> list[str]:
    """Names accepted by :func:`get_suite`."""
    return list(SUITES)


def get_suite(name: str) -> Suite:
    """The suite called ``name``.

    Raises:
        KeyError: unknown name (the message lists the known suites).
    """
    if name not in SUITES:
        raise KeyError(f"unknown suite {name!r}; known suites: {', '.join(SUITES)}")
    return SUITES[name]()


def restrict_tasks(suite: Suite, tasks: Sequence[str] | str) -> Suite:
    """The part of ``suite`` on some of its tasks (``--tasks``).

    The result is a different suite (name ``<name>-subset``, its own hash), so a results
    file of a restricted run is never mistaken for a full one.

    Args:
        suite: the suite.
        tasks: task IDs (the ``swarmloc/`` prefix may be omitted), or one comma-separated string.

    Returns:
        The restricted suite, in the suite's task order.

    Raises:
        ValueError: empty selection or a task the suite does not hold (the message lists them).
    """
    if isinstance(tasks, str):
        tasks = [t for t in tasks.split(",")]
    names = [t.strip() for t in tasks if t.strip()]
    if not names:
        raise ValueError(f"--tasks selects no task; choose from: {', '.join(suite.tasks)}")
    ids = {t: canonical_task_id(t) for t in names if t in CATALOGUE or f"swarmloc/{t}" in CATALOGUE}
    wanted = [ids.get(t, t) for t in names]
    unknown = [t for t in wanted if t not in suite.tasks]
    if unknown:
        raise ValueError(f"task(s) {unknown} not in suite {suite.name!r}; choose from: {', '.join(suite.tasks)}")
    keep = set(wanted)
    episodes = tuple((t, s) for t, s in suite.episodes if t in keep)
    return Suite(f"{suite.name}-subset", suite.version, episodes,
                 f"{suite.name} restricted to {len(keep)} task(s)",
                 specs=_specs([t for t in suite.tasks if t in keep]) if suite.specs else ())
