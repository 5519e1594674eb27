"""Benchmark v2 tasks: tracks, the consistent backbone, what each family changes, determinism, version history."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pydantic
import pytest

from swarmloc.bench.scoring.families import task_split
from swarmloc.envs.adapters.task_envs import _HISTORY
from swarmloc.envs.tasks.catalogue import CATALOGUE, get_spec
from swarmloc.envs.tasks.channels import ANCHOR, LANDMARK
from swarmloc.envs.tasks.v2 import (
    CASCADED_TOP_ANCHOR,
    CATALOGUE_V2,
    HISTORY_V2,
    SCALE_ANCHOR_RANGE,
    VISION_BLIND,
    VISION_BLIND_SHIFTED,
)
from swarmloc.envs.world.sim import World

sys.path.insert(0, str(Path(__file__).parent))
from test_world import rollout

V2_TASKS = sorted(CATALOGUE_V2)


def test_every_v2_task_names_its_track_fuses_peers_by_split_ci_and_has_a_history_line():
    assert set(HISTORY_V2) == set(CATALOGUE_V2)
    for task_id in CATALOGUE_V2:
        spec = get_spec(task_id)
        assert spec.version == 2 and spec.task_id == task_id
        assert spec.track in ("cooperative", "robust-ranging")
        assert spec.filter.peer_update == "split_ci"
        assert (spec.n_uav == 1) == (spec.track == "robust-ranging")
        history = _HISTORY[task_id]
        assert history[-1] == HISTORY_V2[task_id] and history[-1].startswith("v2: ")
        if task_split(task_id) == "shifted":  # every shifted split has its training split
            assert task_id.replace("RandomShifted-", "Random-") in CATALOGUE


def test_the_track_field_is_checked_and_left_out_of_older_specs():
    with pytest.raises(pydantic.ValidationError, match="v2 task must name its track"):
        get_spec("swarmloc/Ideal-v1", version=2)
    with pytest.raises(pydantic.ValidationError, match="one-UAV board; n_uav=4"):
        get_spec("swarmloc/Ideal-v1", track="robust-ranging")
    with pytest.raises(pydantic.ValidationError, match="track"):
        get_spec("swarmloc/Scale8-v2", track="headline")
    # v0 and v1 specs carry no track, and their canonical JSON (the suites' hashes) does not name it
    for task_id in CATALOGUE:
        spec = get_spec(task_id)
        if spec.version < 2:
            assert spec.track is None and '"track"' not in spec.model_dump_json()
    assert '"track":"cooperative"' in get_spec("swarmloc/Scale8-v2").model_dump_json()


def test_scale_v2_anchors_reach_only_part_of_the_hall():
    spec = get_spec("swarmloc/Scale8-v2")
    assert spec.sensors.anchor_max_range == SCALE_ANCHOR_RANGE
    assert set(spec.faults.nlos_gauss_markov.targets) == {"anchor", "peer"}
    world = World(spec, 2)
    world.reset([2_000_000, 2_000_001])
    seen = []
    for _ in range(100):
        b = world.sense()
        seen.append(b.valid[:, :, world.layout.kind[0] == ANCHOR].mean())
    # every UAV ranges some anchors, never all eight (the far wall is beyond 11 m)
    assert 0.1 < np.mean(seen) < 0.9


def test_cascaded_fault_v2_adds_a_ceiling_anchor_and_keeps_the_cascade():
    v1, v2 = get_spec("swarmloc/CascadedFault-v1"), get_spec("swarmloc/CascadedFault-v2")
    assert v2.anchors == v1.anchors + (CASCADED_TOP_ANCHOR,)
    assert v2.faults == v1.faults and v2.scoring == v1.scoring
    for task in ("CascadedFaultRandom", "CascadedFaultRandomShifted"):
        assert get_spec(f"{task}-v2").faults == get_spec(f"{task}-v1").faults
        assert get_spec(f"{task}-v2").anchors[-1] == CASCADED_TOP_ANCHOR


def test_vision_loss_v2_blinds_half_the_swarm_while_the_rest_sees():
    spec = get_spec("swarmloc/VisionLoss-v2")
    world = World(spec, 1)
    world.reset([2_000_000])
    landmark = world.layout.kind[0] == LANDMARK
    seen = np.zeros(spec.n_uav)
    for k in range(spec.n_steps):
        b = world.sense()
        if 31.0 <= (k + 1) * spec.dt <= 39.0:
            seen += b.valid[0][:, landmark].any(axis=1)
    blind = np.zeros(spec.n_uav, dtype=bool)
    blind[list(VISION_BLIND)] = True
    assert np.all(seen[blind] == 0) and np.all(seen[~blind] > 0)
    assert get_spec("VisionLossRandom-v2").faults.vision_outage_random.nodes == VISION_BLIND
    assert get_spec("VisionLossRandomShifted-v2").faults.vision_outage_random.nodes == VISION_BLIND_SHIFTED


@pytest.mark.parametrize("task_id", ["swarmloc/Scale8-v2", "swarmloc/CascadedFaultRandom-v2",
                                     "swarmloc/VisionLossRandom-v2", "swarmloc/AnchorNLOSRandom-v2",
                                     "swarmloc/TDOA-v2"])
def test_batched_equals_single_runs_exactly(task_id):
    seeds = [3, 2_000_001, 77]
    batched = rollout(task_id, seeds, 30)
    for b, seed in enumerate(seeds):
        single = rollout(task_id, [seed], 30)
        for key, value in single.items():
            assert np.array_equal(batched[key][:, b], value[:, 0]), f"{key} differs for seed {seed}"


def test_v1_tasks_are_deprecated_through_gymnasiums_warning_and_v2_and_real_flights_are_not():
    import warnings

    from swarmloc.envs.adapters.trust_env import build_spec

    with pytest.warns(DeprecationWarning, match="swarmloc/NLOS-v1 is a benchmark v1 task, frozen and deprecated"):
        build_spec("NLOS-v1", {})
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        build_spec("swarmloc/Scale8-v2", {})
        build_spec("swarmloc/UTILFlight-v1", {})  # a real flight: the robust-ranging track's, not deprecated
    with pytest.raises(TypeError, match="unknown argument.*'track'"):
        build_spec("swarmloc/Scale8-v2", {"track": "robust-ranging"})
