"""``swarmloc reproduce consistency``: the NEES it reports, its rows, its verdict and its report."""

from __future__ import annotations

import json

import numpy as np
import pytest

from swarmloc.bench.evaluation.episode import StepRecord
from swarmloc.bench.reproduce.consistency import (
    FAMILY_TASKS,
    NeesObserver,
    reproduce_consistency,
    verdict,
)
from swarmloc.envs.tasks.catalogue import get_spec


def _record(estimate, truth, cov):
    r = StepRecord()
    r.estimate, r.truth, r.covariance = np.asarray(estimate, float), np.asarray(truth, float), cov
    return r


def test_nees_is_the_mahalanobis_square_of_the_position_error():
    """e = (1, 2, 0) against diag(4, 1, 9): 1/4 + 4 = 4.25; e = 0: 0 (B = 1, N = 2, one update)."""
    obs = NeesObserver()
    obs.begin(None)
    cov = np.stack([np.diag([4.0, 1.0, 9.0])] * 2)[None]
    obs.observe(_record([[[1.0, 2.0, 0.0], [0.0, 0.0, 0.0]]], np.zeros((1, 2, 3)), cov))
    assert obs.summary() == pytest.approx((4.25 / 2, 4.25 / 2))


def test_nees_of_errors_drawn_from_the_covariance_is_three():
    """Errors drawn from the covariance a filter reports: mean NEES 3 (χ² with 3 dof), median 2.366."""
    rng = np.random.default_rng(0)
    A = rng.normal(size=(64, 5, 3, 3))
    cov = A @ np.swapaxes(A, -1, -2) + 0.1 * np.eye(3)
    obs = NeesObserver()
    obs.begin(None)
    for _ in range(50):
        e = np.einsum("bnij,bnj->bni", np.linalg.cholesky(cov), rng.normal(size=(64, 5, 3)))
        obs.observe(_record(e, np.zeros_like(e), cov))
    mean, median = obs.summary()
    assert mean == pytest.approx(3.0, abs=0.1) and median == pytest.approx(2.366, abs=0.1)


def test_a_method_without_a_covariance_is_refused():
    obs = NeesObserver()
    obs.begin(None)
    with pytest.raises(ValueError, match="covariance"):
        obs.observe(_record(np.zeros((1, 1, 3)), np.zeros((1, 1, 3)), None))


def test_family_tasks_have_absolute_references_and_are_registered():
    for task in FAMILY_TASKS:
        spec = get_spec(task)
        assert spec.version == 1
    assert not any("AnchorFree" in t for t in FAMILY_TASKS)  # a gauge: NEES of absolute positions means nothing


def test_verdict_names_the_inconsistent_tasks_and_where_dropping_peers_wins():
    def row(task, method, rmse, nees=None, update="split_ci", faults="off"):
        return {"task": task, "peer_update": update, "faults": faults, "method": method, "nees_mean": nees,
                "nees_median": nees, "rmse": rmse, "default": update == "split_ci"}

    rows = [row("A", "uniform", 1.0, 3.0), row("A", "non-cooperative", 0.99),  # within 2 %: not better
            row("B", "uniform", 1.0, 6.0), row("B", "non-cooperative", 0.90),  # both fail
            row("C", "uniform", 1.0, 1.2, faults="on"), row("C", "non-cooperative", 0.5, faults="on"),  # faults on
            row("D", "uniform", 1.0, 90.0, update="point"), row("D", "non-cooperative", 0.5, update="point")]
    assert verdict(rows) == {"tasks": 2, "nees_outside": ["B"], "non_cooperative_better": ["B"]}


def test_report_rows_and_the_peerless_policy_is_unchanged(tmp_path):
    path = reproduce_consistency(tmp_path, seeds=2, tasks=["Scale2-v1"], duration=8.0, scale=False)
    assert path.name == "consistency.md"
    text = path.read_text()
    assert "| Scale2-v1 |" in text and "## Faults removed" in text and "## Faults on" in text
    rows = json.loads(path.with_suffix(".json").read_text())["rows"]
    assert len(rows) == 2 * 3 * 2  # faults on/off × three updates × two methods
    assert {tuple(sorted(r)) for r in rows} == {tuple(sorted(
        ["task", "peer_update", "faults", "method", "nees_mean", "nees_median", "rmse", "default"]))}
    assert [r["default"] for r in rows] == [r["peer_update"] == "split_ci" for r in rows]
    for faults in ("on", "off"):
        nc = {r["peer_update"]: r["rmse"] for r in rows if r["faults"] == faults and r["method"] == "non-cooperative"}
        # non-cooperative fuses no peer channel: the peer update cannot change it, bit for bit
        assert nc["point"] == nc["ci"] == nc["split_ci"]
        uni = [r for r in rows if r["faults"] == faults and r["method"] == "uniform"]
        assert all(r["nees_mean"] > 0 and r["nees_median"] > 0 for r in uni)
