"""The committed standard-v1 and standard-v0 results of the shipped methods match their suites, load into a fresh
store, and (the learned ones) come from the shipped weights."""

from __future__ import annotations

import pytest

from swarmloc.bench.evaluation.results import load_results
from swarmloc.bench.evaluation.suites import get_suite
from swarmloc.bench.evaluation.shipped import RESULTS_DIRS, RUN_SEPARATOR, shipped_results
from swarmloc.leaderboard.store.shipped import WITHOUT_RESULTS, load_shipped
from swarmloc.leaderboard.store.database import SHIPPED_REFERENCE_METHODS, LeaderboardStore

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
        f"stale: regenerate with swarmloc reproduce shipped --suite {suite_name}"
    assert {(e.task, e.seed) for e in results.episodes} == set(suite.episodes)


@pytest.mark.parametrize("suite", sorted(WITHOUT_RESULTS))
def test_every_shipped_method_has_results_or_a_stated_reason(suite):
    shipped = {p.stem for p in shipped_results(RESULTS_DIRS[suite]) if RUN_SEPARATOR not in p.stem}
    methods = {m for m in SHIPPED_REFERENCE_METHODS if not m.endswith("+smooth")}
    assert shipped == methods - set(WITHOUT_RESULTS[suite])
    assert set(WITHOUT_RESULTS[suite]) <= methods


def test_both_suites_are_shipped():
    assert {p.parent for p in FILES} == set(RESULTS_DIRS.values())


def test_shipped_results_populate_a_fresh_store_once(tmp_path):
    with LeaderboardStore(f"sqlite:///{tmp_path / 'lb.db'}") as store:
        first = load_shipped(store)
        assert first.refused == ()
        # a learned method's chosen run ships again as <method>.json: present (the run is stored once)
        assert sorted(first.stored + first.present) == sorted(load_results(p).method.name for p in FILES)
        again = load_shipped(store)
        assert again.stored == () and sorted(again.present) == sorted(first.stored + first.present)
        assert store.count() == len(first.stored)


def test_a_shipped_method_whose_results_changed_replaces_its_stale_entry(tmp_path):
    """A release that changes how a reference method runs, not its name or weights (so not its hash), ships new
    results: loading them replaces the stored entry, once; a user's own entry of the same method is never replaced."""
    import dataclasses
    import shutil

    from swarmloc.bench.evaluation.results import make_results, write_results
    from swarmloc.leaderboard.errors import DuplicateSubmission, InvalidSubmission
    from swarmloc.leaderboard.submit.pipeline import submit

    shipped = tmp_path / "shipped"
    shipped.mkdir()
    source = RESULTS_DIRS["standard-v0"] / "chi2-gate.json"
    shutil.copy(source, shipped / "chi2-gate.json")
    with LeaderboardStore(f"sqlite:///{tmp_path / 'lb.db'}") as store:
        assert load_shipped(store, shipped).stored == ("chi2-gate",)
        (old,) = store.entries()
        results = load_results(source)
        episodes = [e.model_dump() for e in results.episodes]
        for episode in episodes:
            episode["metrics"]["rmse"] *= 0.5
        write_results(shipped / "chi2-gate.json", make_results(results.method, results.suite, episodes))
        loaded = load_shipped(store, shipped)
        assert loaded.stored == loaded.replaced == ("chi2-gate",)
        (new,) = store.entries()
        assert new.method_hash == old.method_hash
        assert new.task_aggregates != old.task_aggregates
        again = load_shipped(store, shipped)
        assert again.present == ("chi2-gate",) and again.replaced == () and store.count() == 1
        with pytest.raises(InvalidSubmission, match="replace_reference"):
            submit(source, metadata={"name": "chi2-gate"}, trust=False, replace_reference=True, store=store)
    with LeaderboardStore(f"sqlite:///{tmp_path / 'user.db'}") as store:  # an entry not trusted is never replaced
        store.add(dataclasses.replace(old, trusted=False))
        with pytest.raises(DuplicateSubmission):
            store.add(new, replace_reference=True)
        assert [e.task_aggregates for e in store.entries()] == [old.task_aggregates]


@pytest.mark.parametrize("method", ["mappo-set-gru", "mappo"])
def test_shipped_learned_results_come_from_the_shipped_weights(method):
    """Re-running one shipped standard-v1 episode of a learned method gives the file's numbers: the weights
    in agents/weights and the results beside them were not swapped one without the other."""
    from swarmloc.bench.evaluation.runner import run_episodes

    results = load_results(RESULTS_DIRS["standard-v1"] / f"{method}.json")
    shipped = next(e for e in results.episodes if e.task == "swarmloc/Scale2-v1")
    rerun = run_episodes(method, [(shipped.task, shipped.seed)])[0]["metrics"]
    for key in ("rmse", "max_error", "jitter"):
        assert rerun[key] == pytest.approx(getattr(shipped.metrics, key), rel=1e-6), key


def test_refresh_bounds_rewrites_the_bound_column_only(tmp_path):
    """``swarmloc reproduce shipped --bounds-only``: bound_rmse becomes the current bound of each episode; every
    other metric, the method and the provenance stay; the score's gap closed is recomputed from the new bound."""
    from swarmloc.bench.evaluation.results import make_results, write_results
    from swarmloc.bench.evaluation.shipped import refresh_bounds
    from swarmloc.bench.scoring.bounds import episode_bounds

    shipped = load_results(RESULTS_DIRS["standard-v1"] / "uniform.json")
    keep = [e for e in shipped.episodes if e.task in ("swarmloc/Ideal-v1", "swarmloc/Scale4-v1") and e.seed < 1_000_002]
    stale = [{"task": e.task, "seed": e.seed, "metrics": {**e.metrics.model_dump(), "bound_rmse": 123.0}} for e in keep]
    write_results(tmp_path / "uniform.json", make_results(shipped.method, shipped.suite, stale, shipped.provenance))
    (path,) = refresh_bounds("standard-v1", tmp_path)
    fresh = load_results(path)
    assert fresh.method == shipped.method and fresh.provenance == shipped.provenance
    for old, new in zip(keep, fresh.episodes):
        (bound,) = episode_bounds(old.task, [old.seed])
        assert new.metrics.bound_rmse == bound.rmse != 123.0
        assert new.metrics.model_dump(exclude={"bound_rmse"}) == old.metrics.model_dump(exclude={"bound_rmse"})
    assert fresh.score.tasks["swarmloc/Ideal-v1"].achievable is not None


def test_regenerating_a_training_run_needs_its_shipped_file():
    from swarmloc.bench.evaluation.shipped import regenerate

    with pytest.raises(FileNotFoundError, match=r"'uniform\.seed9' has no shipped file"):
        regenerate(["uniform.seed9"], "standard-v2")
