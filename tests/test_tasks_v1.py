"""Benchmark v1 tasks: determinism, per-episode scenario draws, shifted splits, version history."""

from __future__ import annotations

import hashlib
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from swarmloc.bench.scoring.families import task_split
from swarmloc.envs.world.faults import build_schedule
from swarmloc.envs.tasks.catalogue import CATALOGUE, get_spec
from swarmloc.envs.tasks.v1 import CATALOGUE_V1, HISTORY_V1, NLOS_SHIFTED_RANGES, NLOS_TRAIN_RANGES
from swarmloc.envs.world.sim import World

sys.path.insert(0, str(Path(__file__).parent))
from test_world import rollout  # noqa: E402

V1_TASKS = sorted(CATALOGUE_V1)


@pytest.mark.parametrize("task_id", V1_TASKS)
def test_batched_equals_single_runs_exactly(task_id):
    seeds = [3, 2_000_001, 77]
    batched = rollout(task_id, seeds, 40)
    for b, seed in enumerate(seeds):
        single = rollout(task_id, [seed], 40)
        for key, value in single.items():
            assert np.array_equal(batched[key][:, b], value[:, 0]), f"{key} differs for seed {seed}"


def _digest(task_ids: list[str]) -> dict[str, str]:
    out = {}
    for task_id in task_ids:
        r = rollout(task_id, [11, 12], 30)
        h = hashlib.sha256()
        for key in sorted(r):
            h.update(np.ascontiguousarray(r[key]).tobytes())
        out[task_id] = h.hexdigest()
    return out


def test_same_numbers_in_another_process():
    code = ("import sys, json; sys.path.insert(0, %r)\n"
            "from test_tasks_v1 import _digest, V1_TASKS\n"
            "print(json.dumps(_digest(V1_TASKS)))\n") % str(Path(__file__).parent)
    done = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True)
    import json

    assert json.loads(done.stdout.strip().splitlines()[-1]) == _digest(V1_TASKS)


def test_every_v1_task_has_a_version_history_line_and_is_version_1():
    assert set(HISTORY_V1) == set(CATALOGUE_V1)
    for task_id in CATALOGUE_V1:
        spec = get_spec(task_id)
        assert spec.version == 1 and spec.task_id == task_id
        assert HISTORY_V1[task_id].startswith("v1: ")


def _nlos_draws(task_id: str, seeds: list[int]) -> tuple[np.ndarray, np.ndarray]:
    spec = get_spec(task_id)
    world = World(spec, len(seeds))
    schedule = build_schedule(spec, world.layout, np.asarray(seeds))
    return schedule.gm_param, schedule.gm_mask


def test_randomized_nlos_draws_per_episode_inside_the_training_ranges():
    seeds = list(range(2_000_000, 2_000_064))
    for task_id in ("swarmloc/NLOSRandom-v1", "swarmloc/ScaleRandom-v1"):
        param, mask = _nlos_draws(task_id, seeds)
        lo, hi = NLOS_TRAIN_RANGES["onset_rate_range"]
        assert np.all((lo <= param[:, 0]) & (param[:, 0] <= hi)) and np.unique(param[:, 0]).size == len(seeds)
        lo, hi = NLOS_TRAIN_RANGES["mean_bias_range"]
        assert np.all((lo <= param[:, 2]) & (param[:, 2] <= hi))
        # log-uniform: about half the draws below the geometric mean of the range
        assert 0.3 < np.mean(param[:, 2] < np.sqrt(lo * hi)) < 0.7
        # prone links: each eligible link with probability link_fraction, differently per episode
        eligible = mask.any(axis=0)
        share = mask[:, eligible].mean()
        assert abs(share - NLOS_TRAIN_RANGES["link_fraction"]) < 0.05
        assert len({m.tobytes() for m in mask}) == len(seeds)
    # the fixed task draws nothing: every episode has the task's parameters and all eligible links
    param, mask = _nlos_draws("swarmloc/NLOS-v1", seeds[:4])
    assert np.all(param == param[0]) and np.all(mask == mask[0])


def test_shifted_splits_draw_outside_the_training_ranges():
    seeds = list(range(2_000_000, 2_000_032))
    for task_id in ("swarmloc/NLOSRandomShifted-v1", "swarmloc/ScaleRandomShifted-v1"):
        param, mask = _nlos_draws(task_id, seeds)
        assert param[:, 0].min() > NLOS_TRAIN_RANGES["onset_rate_range"][1]
        assert NLOS_SHIFTED_RANGES["link_fraction"] == 1.0 and np.all(mask == mask[0])
        assert get_spec(task_id).n_uav > get_spec(task_id.replace("Shifted", "")).n_uav
    train = get_spec("swarmloc/CascadedFaultRandom-v1").faults.imu_cascade_random
    shifted = get_spec("swarmloc/CascadedFaultRandomShifted-v1").faults.imu_cascade_random
    assert shifted.bias_magnitude_range[1] < train.bias_magnitude_range[0]
    assert shifted.duration_range[0] >= train.duration_range[1]
    for task_id in CATALOGUE_V1:
        if task_split(task_id) == "shifted":
            assert task_id.replace("RandomShifted-", "Random-") in CATALOGUE


def test_v0_tasks_are_untouched_by_the_v1_fields():
    # the v1 fields default to the v0 behaviour: every v0 spec keeps them at their defaults
    for task_id in CATALOGUE:
        if task_id.endswith("-v0"):
            spec = get_spec(task_id)
            assert spec.sensors.camera_fov_deg == 360.0 and spec.sensors.landmark_map_sigma == 0.0
            g = spec.faults.nlos_gauss_markov
            assert g is None or (g.onset_rate_range is None and g.mean_bias_range is None and g.link_fraction == 1.0)
            assert spec.scoring.nodes_from_schedule == "all"


def test_nlos_step_v1_biases_ramp_in_over_five_seconds():
    spec = get_spec("swarmloc/NLOSStep-v1")
    world = World(spec, 1)
    world.reset([4])
    final = {0: 1.0, 2: 0.5, 4: 0.6}
    for k in range(1, spec.n_steps + 1):
        buf = world.sense()
        t = k * spec.dt
        inside = 20.0 <= t + 1e-9 and t < 30.0 - 1e-9
        for anchor, bias in final.items():
            want = bias * min(1.0, (t - 20.0) / 5.0) if inside else 0.0
            assert np.allclose(buf.injected[0, :, anchor], want, atol=1e-12), (t, anchor)
        assert not buf.injected[0, :, [1, 3, 5, 6, 7]].any()


def test_ramp_onset_starts_an_nlos_episode_at_zero_bias():
    # with onset="ramp" the first biased step of every NLOS episode is tiny; with "jump" it is drawn at full size
    firsts = {}
    for onset in ("ramp", "jump"):
        spec = get_spec("swarmloc/NLOS-v1", duration=30.0, faults={"nlos_gauss_markov": {"onset": onset}})
        world = World(spec, 4)
        world.reset([1, 2, 3, 4])
        before = np.zeros((4, spec.n_uav, spec.n_channels), dtype=bool)
        first = []
        for _ in range(spec.n_steps):
            buf = world.sense()
            biased = world.inputs.gm_left > 0
            first += list(buf.injected[biased & ~before])
            before = biased
        firsts[onset] = np.array(first)
    assert firsts["ramp"].size > 20 and firsts["jump"].size > 20
    # the AR(1) step from 0: μ(1 − φ) + σ√(1 − φ²)·n with φ = exp(−0.1/2): a few centimetres, never metres
    assert np.median(firsts["ramp"]) < 0.1 < np.median(firsts["jump"])
