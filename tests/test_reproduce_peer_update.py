"""``swarmloc reproduce peer-update``: the tasks it covers, its invariants and its report."""

from __future__ import annotations

import json

import numpy as np

from swarmloc.bench.reproduce.peer_update import (
    METHODS,
    VARIANTS,
    _ceiling_beaten_by,
    peer_tasks,
    render,
    reproduce_peer_update,
)
from swarmloc.envs.tasks.catalogue import get_spec


def test_covers_the_v1_tasks_with_peer_channels():
    tasks = peer_tasks()
    assert "swarmloc/HybridNoise10-v1" in tasks and "swarmloc/GradualFault-v1" in tasks  # ranges, relative positions
    assert "swarmloc/TDOA-v1" not in tasks  # no peers: nothing to compare


def test_ceiling_is_beaten_only_by_a_paired_ci():
    rng = np.random.default_rng(0)
    base = rng.uniform(0.4, 0.6, size=16)
    rmse = {m: base.copy() for m in METHODS}
    rmse["non-cooperative"] = base * 0.8  # better than the oracle on every seed
    rmse["chi2-soft"] = base * np.where(np.arange(16) % 2 == 0, 0.9, 1.1)  # better on half, worse on half
    assert _ceiling_beaten_by(rmse) == ["non-cooperative"]


def test_report_and_the_peerless_policy_is_unchanged(tmp_path):
    path = reproduce_peer_update(tmp_path / "pu.md", seeds=2, tasks=["Scale2-v1"], duration=8.0, variants=False)
    text = path.read_text()
    assert "| Scale2-v1 |" in text and "`point`" in text and "`ci`" in text
    raw = json.loads(path.with_suffix(".json").read_text())
    rmse = raw["tasks"][0]["rmse"]
    # non-cooperative uses no peer channel, so the peer update cannot change it, bit for bit
    assert rmse["point"]["non-cooperative"] == rmse["ci"]["non-cooperative"]
    # uniform fuses the peers, and the two updates differ
    assert rmse["point"]["uniform"] != rmse["ci"]["uniform"]


def test_variants_render_beside_the_tasks():
    """A variant row (here synthetic) renders in its own section; its spec overrides are valid."""
    for task, overrides in VARIANTS.values():
        get_spec(task, **overrides)
    row = {"task": "HybridNoise30-v1, no peers", "bound": [0.4, 0.4], "rmse": {}}
    for u in ("point", "ci"):
        row["rmse"][u] = {m: [0.5, 0.5] for m in METHODS}
        row[u] = {"ceiling_beaten_by": [], "uniform_over_bound": 1.25, "gate_over_uniform": 1.0}
    text = render([], 2, [row])
    assert "## Variants" in text and "| HybridNoise30-v1, no peers |" in text
