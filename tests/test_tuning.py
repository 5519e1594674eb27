"""Tuning the classical methods: search spaces, the cusum-chi2 composite, the tuner, the shipped records and their docs."""

from __future__ import annotations

import json
from dataclasses import asdict

import numpy as np
import pytest
from trust_helpers import trust_input, trust_layout

from swarmloc.agents.registry import REGISTRY, load_method
from swarmloc.agents.trust.classical import Chi2SoftTrust
from swarmloc.agents.trust.composite import CusumChi2Trust
from swarmloc.agents.trust.integrity import CusumTrust
from swarmloc.agents.trust.search_space import Param
from swarmloc.agents.trust.tuned import TUNABLE, default_params, read_params, record_path, search_space
from swarmloc.envs.tasks.channels import ANCHOR, LANDMARK, PEER, PEER_REL

# --------------------------------------------------------------------------- search spaces


def test_a_param_maps_its_scale_onto_the_sampled_variable():
    tail = Param("confidence", 0.8, 0.9999, "log-tail")
    assert (tail.search_name, tail.log) == ("1-confidence", True)
    assert tail.search_bounds == pytest.approx((1e-4, 0.2))
    assert tail.from_search(tail.to_search(0.95)) == pytest.approx(0.95)
    assert Param("k", 0.5, 4.0, "log").search_bounds == (0.5, 4.0)
    with pytest.raises(ValueError, match="scale must be one of"):
        Param("k", 0.5, 4.0, "cubic")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="low < high"):
        Param("k", 4.0, 0.5)
    with pytest.raises(ValueError, match="log scale needs low > 0"):
        Param("k", 0.0, 1.0, "log")
    with pytest.raises(ValueError, match="log-tail scale needs high < 1"):
        Param("c", 0.5, 1.0, "log-tail")


@pytest.mark.parametrize("method", list(TUNABLE))
def test_every_tunable_method_is_registered_with_its_tuned_twin_and_its_default_lies_in_its_space(method):
    assert REGISTRY[method].track == REGISTRY[f"{method}-tuned"].track == "A"
    space = search_space(method)
    assert [p.name for p in space] == list(default_params(method))
    assert all(p.contains(default_params(method)[p.name]) for p in space)


def test_an_untunable_method_is_refused_by_name():
    with pytest.raises(ValueError, match="'uniform' is not tunable; tunable: huber, chi2-gate"):
        search_space("uniform")


# --------------------------------------------------------------------------- the composite


def test_cusum_chi2_equals_cusum_on_absolute_channels_and_chi2_soft_on_peers():
    """Same NIS stream into the composite and both parents: a biased anchor and a biased peer, 300 steps."""
    kinds = [ANCHOR, ANCHOR, ANCHOR, LANDMARK, PEER, PEER, PEER, PEER_REL]
    layout = trust_layout(kinds)
    peer = np.isin(kinds, (PEER, PEER_REL))
    dof = np.where(np.isin(kinds, (LANDMARK, PEER_REL)), 3, 1)
    params = {"design_ratio": 3.0, "arl": 500.0, "alpha_reject": 0.02, "confidence": 0.99, "softness": 0.7}
    composite = CusumChi2Trust(**params)
    cusum = CusumTrust(params["design_ratio"], params["arl"], params["alpha_reject"])
    soft = Chi2SoftTrust(params["confidence"], params["softness"])
    keys = np.arange(3)
    for policy in (composite, cusum, soft):
        policy.reset(3, layout, keys)
    rng = np.random.default_rng(3)
    seen_alarm = seen_soft = False
    for step in range(300):
        nis = rng.chisquare(dof, size=(3, 1, len(kinds)))
        if 100 <= step < 200:
            nis[:, 0, 1] *= 6.0  # a biased anchor: CUSUM alarms
            nis[:, 0, 5] *= 6.0  # a biased peer: the soft gate down-weights
        inp = trust_input(nis, step=step)
        alpha, a_cusum, a_soft = composite.act(inp), cusum.act(inp), soft.act(inp)
        np.testing.assert_array_equal(alpha[..., ~peer], a_cusum[..., ~peer])
        np.testing.assert_array_equal(alpha[..., peer], a_soft[..., peer])
        seen_alarm |= bool((a_cusum[..., ~peer] < 1).any())
        seen_soft |= bool((a_soft[..., peer] < 1).any())
    assert seen_alarm and seen_soft  # both parents acted, so the equalities above were not all ones
    assert (composite.design_ratio, composite.softness) == (3.0, 0.7)
    assert load_method("cusum-chi2").method.confidence == 0.95


# --------------------------------------------------------------------------- the tuner


@pytest.fixture(scope="module")
def tiny_runs():
    """chi2-gate, 3 trials twice on AnchorNLOS-v2, 2 dev seeds, 10 s episodes (100 steps)."""
    pytest.importorskip("optuna")
    from swarmloc.bench.evaluation.suites import Suite
    from swarmloc.bench.tuning.search import tune

    suite = Suite("dev-v2-subset", "test", (("swarmloc/AnchorNLOS-v2", 2_000_000), ("swarmloc/AnchorNLOS-v2", 2_000_001)))
    return [tune("chi2-gate", 3, 7, suite=suite, overrides={"duration": 10.0}) for _ in range(2)]


def test_a_tuning_run_is_deterministic_for_its_seed(tiny_runs):
    first, second = tiny_runs
    assert [t["params"] for t in first["trials"]] == [t["params"] for t in second["trials"]]
    assert [t["objective"] for t in first["trials"]] == [t["objective"] for t in second["trials"]]
    assert first["params"] == second["params"]


def test_a_tuning_run_writes_a_record_the_tuned_factory_reads(tiny_runs, tmp_path):
    from swarmloc.bench.tuning.search import write_record

    record = tiny_runs[0]
    path = write_record(record, tmp_path / "chi2-gate.json")
    data = json.loads(path.read_text())
    assert data["method"] == "chi2-gate"
    assert data["space"] == [asdict(p) for p in search_space("chi2-gate")]
    assert data["budget"] == {"trials": 3, "sampler": "optuna.samplers.TPESampler", "seed": 7,
                              "first_trial": "the registered default (enqueued)"}
    assert len(data["trials"]) == 3 and data["trials"][0]["params"] == default_params("chi2-gate")
    assert data["default"]["trial"] == 0
    best = max(data["trials"], key=lambda t: t["objective"])
    assert data["chosen"]["objective"] == best["objective"] and data["params"] == data["chosen"]["params"]
    assert list(data["chosen"]["tracks"]) == ["robust-ranging"]  # the one task's track
    assert data["command"] == "swarmloc tune chi2-gate --trials 3 --seed 7 --workers 1"
    assert data["optuna_version"] and data["suite"]["episodes"] == 2 and data["overrides"] == {"duration": 10.0}
    policy = load_method("chi2-gate-tuned", weights=path).method
    assert (policy.confidence, policy.alpha_reject) == (data["params"]["confidence"], data["params"]["alpha_reject"])
    assert read_params("chi2-gate", path) == data["params"]
    with pytest.raises(ValueError, match="holds parameters of 'chi2-gate', not of 'huber'"):
        load_method("huber-tuned", weights=path)


def test_bad_input_is_refused_by_name(capsys):
    from swarmloc.bench.tuning.search import check_budget
    from swarmloc.cli import main

    with pytest.raises(ValueError, match="trials must be an integer >= 1, got 0"):
        check_budget(0, 0)
    with pytest.raises(ValueError, match="seed must be an integer >= 0, got -1"):
        check_budget(3, -1)
    assert main(["tune", "uniform"]) == 2
    assert "'uniform' is not tunable; tunable: huber" in " ".join(capsys.readouterr().err.split())
    assert main(["tune", "huber", "--trials", "0"]) == 2
    assert "trials must be an integer >= 1, got 0" in capsys.readouterr().err


def test_a_missing_record_names_the_command_that_writes_it(tmp_path):
    with pytest.raises(FileNotFoundError, match="swarmloc tune huber"):
        load_method("huber-tuned", weights=tmp_path / "absent.json")


# --------------------------------------------------------------------------- the shipped records


@pytest.mark.parametrize("method", list(TUNABLE))
def test_the_tuned_factory_builds_the_policy_with_the_shipped_record_s_values(method):
    record = json.loads(record_path(method).read_text())
    policy = load_method(f"{method}-tuned").method
    assert type(policy) is TUNABLE[method]
    assert {name: getattr(policy, name) for name in record["params"]} == record["params"]
    assert record["space"] == [asdict(p) for p in search_space(method)]  # the space the code declares
    assert all(p.contains(record["params"][p.name]) for p in search_space(method))
    assert record["params"] == max(record["trials"], key=lambda t: t["objective"])["params"]
    assert record["suite"]["name"] == "dev-v2" and record["overrides"] is None
    assert list(record["chosen"]["tracks"]) == ["cooperative", "robust-ranging"]


def test_every_shipped_record_has_the_same_budget():
    from swarmloc.bench.tuning import BUDGET_SEED, BUDGET_TRIALS

    budgets = {m: json.loads(record_path(m).read_text())["budget"] for m in TUNABLE}
    assert all(b["trials"] == BUDGET_TRIALS and b["seed"] == BUDGET_SEED for b in budgets.values()), budgets
    assert all(len(json.loads(record_path(m).read_text())["trials"]) == BUDGET_TRIALS for m in TUNABLE)


def test_the_docs_tables_match_the_shipped_records():
    from swarmloc.cli import main

    assert main(["docs", "tuning", "--check"]) == 0, "run: swarmloc docs tuning"


def test_a_tuned_value_at_an_end_of_its_range_is_marked():
    from swarmloc.bench.tuning.table import _tuned

    k, confidence = Param("k", 0.5, 4.0, "log"), Param("confidence", 0.8, 0.9999, "log-tail")
    assert (k.position(0.5), k.position(4.0), k.position(np.sqrt(2.0))) == pytest.approx((0.0, 1.0, 0.5))
    assert (confidence.position(0.8), confidence.position(0.9999)) == pytest.approx((0.0, 1.0))
    assert (_tuned(k, 0.5001), _tuned(k, 3.99), _tuned(k, 1.3)) == ("0.5001 (low end)", "3.99 (high end)", "1.3")
    assert _tuned(confidence, 0.8002) == "0.8002 (low end)"
