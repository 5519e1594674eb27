"""The information bound is a floor for the privileged estimators on randomized spec variants (issue 46 item 4).

Over 240 variants of three v1 task families (N, anchor layout and range, peer kind, topology
and range, Gauss–Markov NLOS and an IMU fault on or off, the accelerometer bias of the
family), short episodes of 4 seeds each: neither ``oracle`` (the CEKF with the error-labelled
channels cut) nor ``centralized-oracle`` (one EKF over the joint state, the same channels left
out) may fall below ``bound_rmse`` beyond its confidence interval.

The bound bounds the expected mean-square error of an episode, E[MSE] ≥ bound², not the RMSE
of a few seeds (by Jensen E[RMSE] ≤ √E[MSE], so a mean RMSE under the bound on short episodes
is no violation). Per variant and method the statistic is x_s = MSE_s / bound_s² over the
seeds; a variant fails when even the one-sided 99.9 % upper t limit of mean(x) is below 1,
and the pooled test fails when the mean of x over all variants is more than 3 standard errors
below 1 (a systematic violation of a few per cent, which no single short variant resolves).
"""

from __future__ import annotations

import time

import numpy as np
import pytest
from scipy import stats

from swarmloc.bench import evaluate_task
from swarmloc.envs import get_spec

N_VARIANTS = 240
SEEDS = [11, 12, 13, 14]
DURATION = 6.0
METHODS = ("oracle", "centralized-oracle")
BASES = ("swarmloc/NLOS-v1", "swarmloc/Scale8-v1", "swarmloc/Indoor-v1")


def variant(rng: np.random.Generator):
    """One randomized spec: a base family with its swarm size, anchors, peers and faults redrawn."""
    base_id = BASES[rng.integers(len(BASES))]
    base = get_spec(base_id)
    n = int(rng.integers(2, 9))
    # anchor layout: 3–8 anchors in the base's area (its anchors' box, or the landmarks' where it has none),
    # heights 0–6 m; their reach from 6 m to unlimited
    ref = np.array(base.anchors or base.landmarks, dtype=float)
    lo, hi = ref[:, :2].min(0) - 3.0, ref[:, :2].max(0) + 3.0
    n_a = int(rng.integers(3, 9))
    anchors = np.column_stack([rng.uniform(lo, hi, size=(n_a, 2)), rng.uniform(0.0, 6.0, n_a)])
    peers = {"kind": str(rng.choice(["none", "range", "range", "relative_position"])),
             "topology": str(rng.choice(["all", "chain", "leader"])),
             "max_range": float(rng.choice([3.0, 6.0, 12.0, 1e6]))}
    sensors = {"anchor_max_range": float(rng.choice([6.0, 10.0, 14.0, 25.0, 1e6])), "peers": peers}
    faults: dict = {}
    if rng.uniform() < 0.5:  # the family's Gauss–Markov NLOS (Indoor has none: take NLOS-v1's)
        faults["nlos_gauss_markov"] = get_spec("swarmloc/NLOS-v1").faults.nlos_gauss_markov.model_dump()
    else:
        faults["nlos_gauss_markov"] = None
    if rng.uniform() < 0.5:  # an IMU fault on the last UAV from 1 to 4 s
        bias = rng.normal(size=3)
        faults["imu_cascades"] = [{"nodes": [n - 1], "start": 1.0, "end": 4.0,
                                   "bias": (1.5 * bias / np.linalg.norm(bias)).tolist(), "blind": bool(rng.uniform() < 0.5)}]
    else:
        faults["imu_cascades"] = []
    spec = get_spec(base_id, n_uav=n, duration=DURATION, anchors=tuple(map(tuple, anchors)), sensors=sensors,
                    faults=faults)
    return spec


def test_neither_oracle_falls_below_the_bound():
    rng = np.random.default_rng(20240646)
    started = time.perf_counter()
    ratios: dict[str, list[float]] = {m: [] for m in METHODS}
    failures = []
    t_crit = stats.t.ppf(0.999, len(SEEDS) - 1)
    for v in range(N_VARIANTS):
        spec = variant(rng)
        out = evaluate_task(list(METHODS), spec, SEEDS, references=False)
        for m in METHODS:
            eps = out.episodes[m]
            assert all(e["bound_rmse"] is not None and np.isfinite(e["bound_rmse"]) for e in eps), (v, spec)
            x = np.array([e["rmse"] ** 2 / e["bound_rmse"] ** 2 for e in eps])
            ratios[m].append(float(x.mean()))
            upper = x.mean() + t_crit * x.std(ddof=1) / np.sqrt(len(x))
            if upper < 1.0:
                failures.append((v, m, spec.task_id, spec.n_uav, round(float(x.mean()), 3), round(float(upper), 3)))
    elapsed = time.perf_counter() - started
    assert not failures, failures
    for m in METHODS:
        r = np.array(ratios[m])
        se = r.std(ddof=1) / np.sqrt(len(r))
        assert r.mean() - 1.0 > -3.0 * se, (m, r.mean(), se)
        print(f"{m}: mean MSE/bound² over {len(r)} variants {r.mean():.2f} (min {r.min():.2f}), {elapsed:.0f} s")
    assert len(ratios[METHODS[0]]) >= 200


@pytest.mark.parametrize("seed", [0, 1])
def test_variants_are_valid_and_diverse(seed):
    # the generator draws what the test claims to cover
    rng = np.random.default_rng(seed)
    specs = [variant(rng) for _ in range(40)]
    assert len({s.n_uav for s in specs}) >= 5
    assert len({s.sensors.peers.kind for s in specs}) == 3 and len({s.sensors.peers.topology for s in specs}) == 3
    assert any(s.faults.imu_cascades for s in specs) and any(not s.faults.imu_cascades for s in specs)
    assert any(s.faults.nlos_gauss_markov for s in specs) and any(s.faults.nlos_gauss_markov is None for s in specs)
    assert len({s.sensors.anchor_max_range for s in specs}) >= 4
