"""The committed standard-v1 and standard-v0 results of the shipped methods match their suites and load into a fresh
store."""

from __future__ import annotations

import pytest

from swarmloc.bench.evaluation.results import load_results
from swarmloc.bench.evaluation.suites import get_suite
from swarmloc.leaderboard.shipped import RESULTS_DIRS, WITHOUT_V1_RESULTS, load_shipped, shipped_results
from swarmloc.leaderboard.store import SHIPPED_REFERENCE_METHODS, LeaderboardStore

FILES = shipped_results()


def test_reference_methods_are_shipped():
    names = {path.stem for path in FILES}
    assert {"uniform", "oracle", "chi2-gate"} <= names


@pytest.mark.parametrize("path", FILES, ids=[f"{p.parent.name}/{p.stem}" for p in FILES])
def test_shipped_file_matches_the_current_suite(path):
    results = load_results(path)
    suite_name = next(name for name, folder in RESULTS_DIRS.items() if folder == path.parent)
    assert results.suite.name == suite_name
    suite = get_suite(suite_name)
    assert results.suite.sha256 == suite.sha256, \
        f"stale: regenerate with python -m swarmloc.leaderboard.shipped --suite {suite_name} --regenerate"
    assert {(e.task, e.seed) for e in results.episodes} == set(suite.episodes)


def test_every_shipped_method_has_standard_v1_results_or_a_stated_reason():
    on_v1 = {p.stem for p in shipped_results(RESULTS_DIRS["standard-v1"])}
    methods = {m for m in SHIPPED_REFERENCE_METHODS if not m.endswith("+smooth")}
    assert on_v1 == methods - set(WITHOUT_V1_RESULTS)
    assert set(WITHOUT_V1_RESULTS) <= methods


def test_both_suites_are_shipped():
    assert {p.parent for p in FILES} == set(RESULTS_DIRS.values())


def test_shipped_results_populate_a_fresh_store_once(tmp_path):
    with LeaderboardStore(f"sqlite:///{tmp_path / 'lb.db'}") as store:
        first = load_shipped(store)
        assert first.refused == ()
        assert sorted(first.stored) == sorted(load_results(p).method.name for p in FILES)
        again = load_shipped(store)
        assert again.stored == () and sorted(again.present) == sorted(first.stored)
        assert store.count() == len(FILES)
