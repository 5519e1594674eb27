"""Sim-to-real rank agreement (``bench/reproduce/sim_to_real.py``): synthetic numbers with known answers.

The rankings and τ of known tables (identical, reversed, ties), the bootstrap's interval (degenerate
where no resample can change an order, containing the estimate, reproducible), tasks weighing the
same whatever their seed counts, the τ-b kernel against scipy, the errors; one smoke run on two
shortened episodes of real data where the UTIL data is imported.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import kendalltau

from swarmloc.bench.evaluation.suites import get_suite, missing_data
from swarmloc.bench.reproduce.sim_to_real import (
    DEFAULT_METHODS,
    REFERENCE,
    kendall_tau_b,
    measure_sim_to_real,
    rank_agreement,
    render_sim_to_real,
    robust_ranging_tasks,
    sim_dev_seeds,
)

METHODS = ("uniform", "a", "b", "c", "d")


def table(gains: dict[str, float], tasks: int, seeds: int, noise: float = 0.0, seed: int = 0,
          uniform: float = 0.5) -> dict[str, dict[str, np.ndarray]]:
    """task → method → per-seed RMSE whose gain over uniform is ``gains[m]`` (plus Gaussian ``noise`` in log2)."""
    rng = np.random.default_rng(seed)
    out = {}
    for t in range(tasks):
        u = uniform * (1.0 + 0.1 * rng.random(seeds))
        out[f"task{t}"] = {"uniform": u, **{m: u * 2.0 ** -(g + noise * rng.standard_normal(seeds))
                                            for m, g in gains.items()}}
    return out


SPREAD = {"a": 1.0, "b": 0.5, "c": -0.5, "d": -1.0}  # separated by far more than any noise used below


def test_identical_rankings_give_tau_one_with_a_degenerate_interval():
    out = rank_agreement(table(SPREAD, 4, 8, noise=0.01), table(SPREAD, 9, 4, noise=0.01, seed=1), methods=METHODS)
    assert out["sim"]["ranking"] == out["real"]["ranking"] == ["a", "b", "uniform", "c", "d"]
    assert out["tau"] == 1.0 and out["ci"] == [1.0, 1.0]
    assert out["sim"]["scores"]["uniform"] == 0.0 and out["sim"]["scores"]["a"] == pytest.approx(1.0, abs=0.02)
    assert out["undefined_resamples"] == 0


def test_reversed_rankings_give_minus_one():
    reverse = {m: -g for m, g in SPREAD.items()}
    out = rank_agreement(table(SPREAD, 4, 8, noise=0.01), table(reverse, 9, 4, noise=0.01), methods=METHODS)
    assert out["real"]["ranking"] == out["sim"]["ranking"][::-1]
    assert out["tau"] == -1.0 and out["ci"] == [-1.0, -1.0]


def test_the_interval_contains_the_estimate_and_is_reproducible():
    close = {"a": 0.1, "b": 0.05, "c": -0.05, "d": 0.02}  # noisy enough that resamples reorder them
    sim, real = table(close, 4, 8, noise=0.3, seed=2), table(close, 9, 4, noise=0.3, seed=3)
    out = rank_agreement(sim, real, n_resamples=500)
    low, high = out["ci"]
    assert -1.0 <= low < high <= 1.0
    assert low <= out["tau"] <= high
    assert rank_agreement(sim, real, n_resamples=500) == out


def test_tau_matches_scipy_on_the_scores():
    close = {"a": 0.1, "b": 0.05, "c": -0.05, "d": 0.02}
    out = rank_agreement(table(close, 3, 6, noise=0.3, seed=4), table(close, 5, 4, noise=0.3, seed=5))
    x = [out["sim"]["scores"][m] for m in out["methods"]]
    y = [out["real"]["scores"][m] for m in out["methods"]]
    assert out["tau"] == pytest.approx(kendalltau(x, y).statistic, abs=1e-4)


def test_tasks_weigh_the_same_whatever_their_seed_count():
    sim = {"few": {"uniform": [1.0], "a": [0.5], "b": [0.25]},
           "many": {"uniform": [1.0] * 9, "a": [2.0] * 9, "b": [0.25] * 9}}
    real = {"f": {"uniform": [1.0, 1.0], "a": [0.5, 0.5], "b": [0.25, 0.25]}}
    out = rank_agreement(sim, real)
    assert out["sim"]["scores"]["a"] == 0.0  # (+1 − 1) / 2, not (1·1 − 9·1) / 10
    assert out["sim"]["seeds"] == {"few": 1, "many": 9}


def test_gains_in_give_what_rmse_in_gives():
    sim, real = table(SPREAD, 2, 4, noise=0.2, seed=6), table(SPREAD, 3, 4, noise=0.2, seed=7)
    as_gain = {side: {t: {m: np.log2(per["uniform"] / r) for m, r in per.items()} for t, per in tab.items()}
               for side, tab in (("sim", sim), ("real", real))}
    a = rank_agreement(sim, real, n_resamples=200)
    b = rank_agreement(as_gain["sim"], as_gain["real"], values="gain", n_resamples=200)
    assert a == b


def test_kendall_tau_b_equals_scipy_with_ties():
    rng = np.random.default_rng(8)
    x, y = rng.integers(0, 3, (50, 6)).astype(float), rng.integers(0, 3, (50, 6)).astype(float)
    ours = kendall_tau_b(x, y)
    for k in range(50):
        theirs = kendalltau(x[k], y[k]).statistic
        assert (math.isnan(ours[k]) and math.isnan(theirs)) or ours[k] == pytest.approx(theirs, abs=1e-12)
    assert math.isnan(float(kendall_tau_b([1.0, 1.0, 1.0], [1.0, 2.0, 3.0])))


@pytest.mark.parametrize("change, message", [
    (lambda s: s["task0"].pop("b"), r"no values for method\(s\) \['b'\]"),
    (lambda s: s["task0"].update(a=np.ones(3)), "one value per seed, the same seeds"),
    (lambda s: s["task0"].update(a=np.zeros(4)), "RMSE must be positive and finite"),
    (lambda s: s["task1"].pop("uniform"), r"lack the reference 'uniform'"),
])
def test_bad_tables_are_refused_by_name(change, message):
    sim = table(SPREAD, 2, 4)
    change(sim)
    with pytest.raises(ValueError, match=message):
        rank_agreement(sim, table(SPREAD, 2, 4), methods=METHODS)


def test_bad_arguments_are_refused_by_name():
    sim = table(SPREAD, 2, 4)
    with pytest.raises(ValueError, match="values='ranks'; allowed"):
        rank_agreement(sim, sim, values="ranks")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="at least 2 distinct methods"):
        rank_agreement(sim, sim, methods=["a"])
    with pytest.raises(ValueError, match="ties every method"):
        rank_agreement({"t": {"uniform": [1.0], "a": [1.0]}}, {"t": {"uniform": [1.0], "a": [2.0]}})
    with pytest.raises(ValueError, match=r"sim_seeds \[1000000\] are not dev seeds"):
        measure_sim_to_real(sim_seeds=[1_000_000], real_tasks=[], real_seeds=[1_000_000])
    with pytest.raises(ValueError, match="lack the reference 'uniform'"):
        measure_sim_to_real(methods=("huber", "raim"))
    with pytest.raises(ValueError, match="need between 2 and"):
        sim_dev_seeds(1)


def test_defaults_are_the_robust_ranging_track_and_shipped_classical_methods():
    from swarmloc.agents.registry import REGISTRY

    assert robust_ranging_tasks() == ["swarmloc/AnchorNLOS-v2", "swarmloc/AnchorNLOSRandom-v2",
                                      "swarmloc/AnchorNLOSRandomShifted-v2", "swarmloc/TDOA-v2"]
    assert REFERENCE in DEFAULT_METHODS
    assert all(not REGISTRY[m].privileged and REGISTRY[m].deterministic for m in DEFAULT_METHODS)


def test_the_section_names_tau_its_interval_and_both_rankings():
    out = rank_agreement(table(SPREAD, 4, 8, noise=0.01), table(SPREAD, 9, 4, noise=0.01), methods=METHODS)
    text = "\n".join(render_sim_to_real(out))
    for part in ("## Sim-to-real rank agreement", "**+1.00**", "CI [+1.00, +1.00]", "| `a` | 1 | +", "| `d` | 5 | -",
                 "| method | sim rank | sim score | real rank | real score |"):
        assert part in text, part


MISSING = missing_data(get_suite("real-v1"))


@pytest.mark.slow  # the kernels' first compilation in a fresh process: about a minute on 2 cores
@pytest.mark.skipif(bool(MISSING), reason="the UTIL flights are not imported here (SWARMLOC_DATA; "
                                          "swarmloc data import-util / import-util-tdoa)")
def test_smoke_on_shortened_real_and_simulated_episodes():
    doc = measure_sim_to_real(("uniform", "chi2-gate", "random"), ["AnchorNLOS-v2"], sim_dev_seeds(2),
                              ["UTILC0426Tdoa2NoLabel-v1"], [1_000_000], overrides={"duration": 2.0},
                              n_resamples=100)
    assert doc["sim"]["tasks"] == ["swarmloc/AnchorNLOS-v2"]
    assert doc["real"]["seeds"] == {"swarmloc/UTILC0426Tdoa2NoLabel-v1": 1}
    assert -1.0 <= doc["ci"][0] <= doc["ci"][1] <= 1.0
    assert len(doc["rmse"]["sim"]["swarmloc/AnchorNLOS-v2"]["random"]) == 2
    assert "not the measurement" in "\n".join(render_sim_to_real(doc))
