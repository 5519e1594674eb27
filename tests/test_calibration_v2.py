"""``swarmloc reproduce calibration --version 2``: each admission criterion flips at its threshold, the track's
headroom verdict, dev seeds only, and the committed report is what the v2 suites freeze."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from swarmloc.bench.evaluation.suites import CALIBRATION_V2_SHA256, STANDARD_V2_TASKS, get_suite
from swarmloc.bench.reproduce import calibration_v2 as V
from swarmloc.envs.tasks.catalogue import get_spec
from swarmloc.envs.tasks.seeds import DEV_SEED_START, TEST_SEED_START
from swarmloc.envs.tasks.v2 import CATALOGUE_V2

ROOT = Path(__file__).resolve().parents[1]
N = 6


def _episodes(rmse, uniform, bound):
    return [{"rmse": r, "uniform_rmse": u, "bound_rmse": b} for r, u, b in zip(rmse, uniform, bound)]


def _numbers(*, no_peers=2.0, fault=3.0, central=1.1, gate=0.6, noncoop=2.0, random=1.5):
    """Per-seed numbers of one task whose criteria sit at the given ratios (bound 1, centralized 1.1 (the best),
    oracle 1.2, uniform 3)."""
    one = np.ones(N)
    bound, oracle, uniform = one, 1.2 * one, 3.0 * one
    # a gate whose gain is `gate` of the achievable log2(uniform / bound)
    gated = uniform / 2 ** (gate * np.log2(3.0))
    on = {"uniform": uniform, "oracle": oracle, V.CENTRAL: 1.1 * one, "chi2-soft": gated, "chi2-gate": gated,
          "non-cooperative": noncoop * oracle, "random": random * 1.1 * one}
    return {"on": on, "bound": {"on": bound, "off": bound, "no_peers": no_peers * bound},
            "off": {"uniform": uniform / fault, V.CENTRAL: central * bound},
            "episodes": {m: _episodes(v, uniform, bound) for m, v in on.items()}}


@pytest.mark.parametrize("name, key, good, bad", [
    ("peer_information", "no_peers", 1.5, 1.49), ("fault_matters", "fault", 1.5, 1.49),
    ("attainable", "central", 1.3, 1.31), ("kind_rule", "noncoop", 1.25, 1.24),
    ("not_degenerate", "random", 1.1, 1.09)])
def test_each_criterion_flips_at_its_threshold(name, key, good, bad):
    passed = V.task_criteria("swarmloc/Scale8-v2", "cooperative", _numbers(**{key: good}), True)
    failed = V.task_criteria("swarmloc/Scale8-v2", "cooperative", _numbers(**{key: bad}), True)
    assert passed[name]["pass"] is True and failed[name]["pass"] is False
    assert all(c["pass"] is not False for c in passed.values())


def test_the_gates_headroom_is_the_tasks_own_value_between_zero_and_the_maximum():
    for gate, own in ((0.5, True), (0.71, False), (-0.2, False), (0.0, True)):
        h = V.task_criteria("swarmloc/Scale8-v2", "cooperative", _numbers(gate=gate), True)["headroom"]
        assert h["task_pass"] is own and h["value"] == pytest.approx(gate, abs=1e-3)
    assert V.task_criteria("swarmloc/Scale8-v2", "cooperative", _numbers(), False)["headroom"]["task_pass"] is None


def test_the_robust_ranging_track_skips_the_peer_criteria():
    numbers = _numbers(no_peers=1.0, noncoop=1.0)
    c = V.task_criteria("swarmloc/TDOA-v2", "robust-ranging", numbers, True)
    assert c["peer_information"]["pass"] is None and c["kind_rule"]["pass"] is None
    assert V.admitted(c)


def test_headroom_is_judged_over_each_track():
    def row(track, own, others=True):
        return {"track": track, "criteria": {"headroom": {"task_pass": own, "measured": ""},
                                             "attainable": {"pass": others}}}
    rows = [row("cooperative", True), row("cooperative", False), row("cooperative", None),
            row("robust-ranging", False), row("robust-ranging", False), row("robust-ranging", True),
            row("robust-ranging", True, others=False)]
    verdicts = V.track_headroom(rows)
    # half of the judged fault tasks is enough; a task without faults is not judged and gets no verdict; a task
    # that fails another criterion does not count towards its track's headroom (but gets the track's verdict)
    assert verdicts["cooperative"] == {"pass": True, "held": 1, "judged": 2}
    assert verdicts["robust-ranging"] == {"pass": False, "held": 1, "judged": 3}
    assert [r["criteria"]["headroom"]["pass"] for r in rows] == [True, True, None, False, False, False, False]


def test_dev_seeds_only_and_v2_tasks_only():
    assert V.dev_seeds(3) == [DEV_SEED_START, DEV_SEED_START + 1, DEV_SEED_START + 2]
    with pytest.raises(ValueError, match="seeds=1"):
        V.dev_seeds(1)
    assert V.candidate_tasks() == list(CATALOGUE_V2)
    with pytest.raises(ValueError, match="not v2 tasks"):
        V.reproduce_calibration_v2(Path("x.md"), Path("x.json"), tasks=["NLOS-v1"])


def test_the_fault_free_counterpart_of_a_healthy_scored_task_scores_every_uav():
    spec = get_spec("swarmloc/CascadedFaultRandom-v2")
    over = V.fault_free(spec)
    free = get_spec(spec.task_id, **over)
    assert free.faults.imu_cascade_random is None and free.scoring.nodes_from_schedule == "all"
    assert V.fault_free(get_spec("swarmloc/Scale8-v2")) == {"faults": over["faults"]}


def test_a_short_run_writes_every_criterion_for_every_task(tmp_path):
    doc = V.reproduce_calibration_v2(tmp_path / "c.md", tmp_path / "c.json", tasks=["Scale8-v2", "TDOA-v2"],
                                     seeds=2, overrides={"duration": 2.0}, sim_to_real=False)
    saved = json.loads((tmp_path / "c.json").read_text())
    assert saved["rows_sha256"] == V.rows_sha256(saved["rows"]) == doc["rows_sha256"]
    for r in saved["rows"]:
        assert set(r["criteria"]) | set(r["not_applicable"]) == set(V.CRITERIA)
        assert r["seeds"] == [DEV_SEED_START, DEV_SEED_START + 1]
        assert all(c["pass"] is not None for c in r["criteria"].values())
        if r["track"] == "robust-ranging":
            assert set(r["not_applicable"]) == {"peer_information", "kind_rule"}
        assert r["in_headline"] == (not r["failing"])
    assert "## Track: cooperative" in (tmp_path / "c.md").read_text()


def test_the_committed_calibration_is_what_the_v2_suites_freeze():
    saved = json.loads((ROOT / "docs" / "calibration-v2.json").read_text())
    rows = saved["rows"]
    assert V.rows_sha256(rows) == saved["rows_sha256"] == CALIBRATION_V2_SHA256, \
        "docs/calibration-v2.json changed: swarmloc reproduce calibration --version 2, then freeze it in suites.py"
    assert tuple(r["task"] for r in rows if r["in_headline"]) == STANDARD_V2_TASKS
    assert sorted(r["task"] for r in rows) == sorted(CATALOGUE_V2)
    for r in rows:
        assert min(r["seeds"]) >= DEV_SEED_START, "the calibration reads dev seeds only"
        if r["in_headline"]:
            assert all(c["pass"] is True for c in r["criteria"].values())
    suite = get_suite("standard-v2")
    assert suite.tasks == list(STANDARD_V2_TASKS) and {s for _, s in suite.episodes} == set(
        range(TEST_SEED_START, TEST_SEED_START + 32))
    assert any(get_spec(t).track == "cooperative" for t in suite.tasks) or not any(
        r["in_headline"] for r in rows if r["track"] == "cooperative")
