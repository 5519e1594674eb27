"""Suites: frozen episode lists, seed ranges, training-seed guard, task restriction."""

from __future__ import annotations

import pytest

from swarmloc.bench.evaluation.results import suite_sha256
from swarmloc.bench.evaluation.suites import (
    STANDARD_V0_TASKS,
    check_training_seeds,
    get_suite,
    restrict_tasks,
    suite_names,
)
from swarmloc.envs.tasks.catalogue import CATALOGUE

#: the published hash of standard-v0; changing the suite needs a new version
STANDARD_V0_SHA256 = "457474c96a5eb6f38151eb0f20d4af8348304e6e289ea000c4873a3f544cfb7f"


def test_standard_v0_is_frozen():
    suite = get_suite("standard-v0")
    assert suite.name == "standard-v0" and suite.version == "0"
    assert suite.tasks == list(STANDARD_V0_TASKS)
    assert len(STANDARD_V0_TASKS) == 17 and set(STANDARD_V0_TASKS) <= set(CATALOGUE)
    for task in suite.tasks:
        assert suite.seeds(task) == list(range(1_000_000, 1_000_032))
    assert suite.sha256 == STANDARD_V0_SHA256 == suite_sha256(suite.episodes)


def test_quick_and_dev_seed_ranges():
    quick, dev, standard = get_suite("quick"), get_suite("dev"), get_suite("standard-v0")
    assert set(standard.tasks) <= set(quick.tasks) <= set(CATALOGUE)
    assert all(s in range(1_000_000, 1_000_004) for _, s in quick.episodes)
    on_standard = {(t, s) for t, s in quick.episodes if t in standard.tasks}
    assert on_standard <= set(standard.episodes)
    assert all(2_000_000 <= s < 3_000_000 for _, s in dev.episodes)
    assert not {s for _, s in dev.episodes} & {s for _, s in standard.episodes}


def test_unknown_suite_lists_names():
    with pytest.raises(KeyError, match="known suites: standard-v0, quick, dev"):
        get_suite("standard")
    assert suite_names() == ["standard-v0", "quick", "dev", "real-v0", "standard-v1", "quick-v1", "dev-v1", "real-v1",
                             "standard-v2", "quick-v2", "dev-v2"]


def test_check_training_seeds():
    check_training_seeds([0, 1, 999_999])
    with pytest.raises(ValueError, match=r"test seed\(s\).*1000000.*\[0, 1000000\)"):
        check_training_seeds([5, 1_000_000])
    with pytest.raises(ValueError, match="dev seed"):
        check_training_seeds([2_000_003])
    with pytest.raises(ValueError, match="out-of-range"):
        check_training_seeds([-1])
    for _, seed in get_suite("quick").episodes:
        with pytest.raises(ValueError):
            check_training_seeds([seed])


def test_restrict_tasks():
    quick = get_suite("quick")
    sub = restrict_tasks(quick, "Ideal-v0, swarmloc/NLOS-v0")
    assert sub.tasks == ["swarmloc/Ideal-v0", "swarmloc/NLOS-v0"]
    assert sub.name == "quick-subset" and sub.sha256 != quick.sha256
    assert len(sub.episodes) == 8
    with pytest.raises(ValueError, match="not in suite 'quick'; choose from"):
        restrict_tasks(quick, ["Nope-v0"])
    with pytest.raises(ValueError, match="selects no task"):
        restrict_tasks(quick, " , ")


def test_suite_satisfies_leaderboard_lookup():
    from swarmloc.leaderboard.store.schema import default_suite_lookup

    suite = default_suite_lookup("standard-v0")
    assert (suite.name, suite.version, suite.sha256) == ("standard-v0", "0", STANDARD_V0_SHA256)
    assert len(suite.episodes) == 17 * 32


def test_standard_v1_holds_every_simulated_v1_task_and_its_hash_covers_the_specs():
    from swarmloc.bench.scoring.families import task_split
    from swarmloc.bench.evaluation.suites import STANDARD_V1_TASKS, Suite, simulated_tasks
    from swarmloc.envs.tasks.catalogue import get_spec

    suite = get_suite("standard-v1")
    assert (suite.name, suite.version) == ("standard-v1", "1")
    assert suite.tasks == list(STANDARD_V1_TASKS)
    assert set(suite.tasks) == {t for t in simulated_tasks() if t.endswith("-v1")}
    for task in suite.tasks:
        assert suite.seeds(task) == list(range(1_000_000, 1_000_032))
    specs = tuple(get_spec(t).model_dump_json() for t in suite.tasks)
    assert suite.sha256 == suite_sha256(suite.episodes, specs) != suite_sha256(suite.episodes)
    # one task changed (its NLOS onset rate), same episodes: another hash
    changed = (get_spec(suite.tasks[2], faults={"nlos_gauss_markov": {"onset_rate": 0.09}}).model_dump_json(),)
    assert Suite("x", "1", suite.episodes, specs=specs[:2] + changed + specs[3:]).sha256 != suite.sha256
    # every shifted split has its in-distribution split beside it
    for task in suite.tasks:
        if task_split(task) == "shifted":
            assert task.replace("RandomShifted-", "Random-") in suite.tasks


def test_quick_v1_and_dev_v1():
    standard, quick, dev = get_suite("standard-v1"), get_suite("quick-v1"), get_suite("dev-v1")
    assert quick.tasks == dev.tasks == standard.tasks
    assert set(quick.episodes) <= set(standard.episodes) and len(quick.episodes) == 4 * len(standard.tasks)
    assert all(2_000_000 <= s < 2_000_008 for _, s in dev.episodes)
    sub = restrict_tasks(standard, "NLOS-v1")
    assert sub.specs and sub.sha256 != restrict_tasks(get_suite("dev-v1"), "NLOS-v1").sha256
