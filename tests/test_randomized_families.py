"""The randomized HybridNoise, GradualFault and VisionLoss families (``*Random-v1``, ``*RandomShifted-v1``):
per-episode draws inside their documented ranges, shifted splits outside them, the kernel using each
episode's own draws, batched == single, the same numbers in another process, clear validation errors."""

from __future__ import annotations

import hashlib
import json
import math
import subprocess
import sys

import numpy as np
import pydantic
import pytest

from swarmloc.bench.evaluation.runner import evaluate_task
from swarmloc.envs.tasks.channels import GPS, LANDMARK
from swarmloc.envs.world.faults import FaultSchedule, build_schedule
from swarmloc.envs.tasks.specs import GpsDriftRandom, HybridNoise, VisionOutageRandom
from swarmloc.envs.tasks.catalogue import get_spec
from swarmloc.envs.tasks.v1 import (GPS_DRIFT_SHIFTED, GPS_DRIFT_TRAIN, HYBRID_SHIFTED_DOF, HYBRID_TRAIN_RATIO,
                                    VISION_OUTAGE_SHIFTED, VISION_OUTAGE_TRAIN)
from swarmloc.envs.world.sim import World

SEEDS = list(range(2_000_000, 2_000_064))
FAMILIES = ("HybridNoise", "GradualFault", "VisionLoss")
TASKS = [f"swarmloc/{f}Random{s}-v1" for f in FAMILIES for s in ("", "Shifted")]


def schedule(task_id: str, seeds: list[int], **overrides) -> FaultSchedule:
    spec = get_spec(task_id, **overrides)
    return build_schedule(spec, World(spec, 1).layout, np.asarray(seeds))


def outages(fs: FaultSchedule) -> tuple[np.ndarray, np.ndarray]:
    """Per episode the number of (non-empty) outages ``(B,)``, and the durations of all of them."""
    used = fs.outage_nodes.any(axis=2)
    length = fs.outage_time[:, :, 1] - fs.outage_time[:, :, 0]
    return used.sum(axis=1), length[used]


# --------------------------------------------------------------------------- draws and ranges


def test_hybrid_ratio_is_drawn_per_episode_inside_its_range():
    fs = schedule("swarmloc/HybridNoiseRandom-v1", SEEDS)
    assert fs.hybrid_param.shape == (len(SEEDS), 6)
    ratio = fs.hybrid_param[:, 0]
    lo, hi = HYBRID_TRAIN_RATIO
    assert np.all((lo <= ratio) & (ratio <= hi)) and np.unique(ratio).size == len(SEEDS)
    # only the ratio is drawn: scale, σ, ν range and the mixture model are the task's
    assert np.all(fs.hybrid_param[:, 1:] == fs.hybrid_param[0, 1:])
    # the shifted split: the same outlier rates, a heavier tail (ν below the training range)
    train_h = get_spec("swarmloc/HybridNoiseRandom-v1").faults.hybrid_noise
    shifted = schedule("swarmloc/HybridNoiseRandomShifted-v1", SEEDS).hybrid_param
    assert np.array_equal(shifted[:, 0], ratio)
    assert np.all(shifted[:, 3:5] == HYBRID_SHIFTED_DOF) and HYBRID_SHIFTED_DOF[1] < train_h.dof_low
    # the fixed tasks keep one ratio for every episode
    fixed = schedule("swarmloc/HybridNoise30-v1", SEEDS[:4]).hybrid_param
    assert np.all(fixed[:, 0] == 0.3)


def test_gps_drift_is_drawn_per_episode_inside_its_ranges():
    spec = get_spec("swarmloc/GradualFaultRandom-v1")
    assert spec.faults.gps_drifts == () and spec.scoring.fault_window is None
    fs = schedule("swarmloc/GradualFaultRandom-v1", SEEDS)
    assert fs.drift_time.shape == (len(SEEDS), 1, 2)
    start, end = fs.drift_time[:, 0, 0], fs.drift_time[:, 0, 1]
    r = GPS_DRIFT_TRAIN
    assert np.all((r["start_range"][0] <= start) & (start <= r["start_range"][1]))
    assert np.all((r["duration_range"][0] <= end - start) & (end - start <= r["duration_range"][1]))
    rate = fs.drift_rate[:, 0]
    speed = np.linalg.norm(rate, axis=1)
    assert np.all((r["rate_range"][0] <= speed) & (speed <= r["rate_range"][1]))
    # the direction: the task's elevation, any azimuth
    np.testing.assert_allclose(rate[:, 2] / speed, math.sin(math.radians(r["elevation_deg"])), rtol=1e-12)
    azimuth = np.degrees(np.arctan2(rate[:, 1], rate[:, 0])) % 360.0
    assert np.histogram(azimuth, bins=4, range=(0, 360))[0].min() >= 5  # every quadrant (16 ± 3.5 expected)
    # which followers drift: one or both of UAVs 1, 2, never the leader; every choice occurs
    nodes = fs.drift_nodes[:, 0]
    assert not nodes[:, 0].any() and np.all(nodes.sum(axis=1) >= 1)
    assert {tuple(m) for m in nodes[:, 1:].astype(int)} == {(1, 0), (0, 1), (1, 1)}
    for values in (start, end - start, speed, azimuth):
        assert np.unique(values).size == len(SEEDS)


def test_gps_drift_shifted_split_is_faster_than_any_training_drift():
    train = schedule("swarmloc/GradualFaultRandom-v1", SEEDS)
    shifted = schedule("swarmloc/GradualFaultRandomShifted-v1", SEEDS)
    speed = np.linalg.norm(shifted.drift_rate[:, 0], axis=1)
    assert speed.min() > GPS_DRIFT_TRAIN["rate_range"][1] and speed.max() <= GPS_DRIFT_SHIFTED["rate_range"][1]
    # only the speed is shifted: the windows and followers are the training ranges'
    assert GPS_DRIFT_SHIFTED["start_range"] == GPS_DRIFT_TRAIN["start_range"]
    assert np.all(shifted.drift_time[:, 0, 0] >= GPS_DRIFT_TRAIN["start_range"][0])
    assert np.linalg.norm(train.drift_rate[:, 0], axis=1).max() < speed.min()


def test_vision_outages_are_drawn_per_episode_inside_their_ranges():
    for task_id, r in (("swarmloc/VisionLossRandom-v1", VISION_OUTAGE_TRAIN),
                       ("swarmloc/VisionLossRandomShifted-v1", VISION_OUTAGE_SHIFTED)):
        spec = get_spec(task_id)
        assert spec.faults.vision_outage is None and spec.scoring.fault_window is None
        fs = schedule(task_id, SEEDS)
        # padded to the most outages an episode can draw: the shape is the task's
        assert fs.outage_time.shape == (len(SEEDS), r["count_range"][1], 2)
        count, length = outages(fs)
        assert set(count.tolist()) == set(range(r["count_range"][0], r["count_range"][1] + 1))
        assert np.all((r["duration_range"][0] <= length) & (length <= r["duration_range"][1]))
        used = fs.outage_nodes.any(axis=2)
        t = fs.outage_time
        assert np.all(t[used][:, 0] >= r["span"][0]) and np.all(t[used][:, 1] <= r["span"][1])
        assert np.all(t[~used] == 0.0)  # padding: empty windows [0, 0) on no UAV
        assert np.all(fs.outage_nodes[used])  # the whole swarm's cameras fail
        for b in range(len(SEEDS)):  # in time order and never overlapping
            w = t[b][used[b]]
            assert np.all(w[1:, 0] >= w[:-1, 1])
        assert np.unique(t[:, 0, 0]).size == len(SEEDS)


def test_vision_outage_shifted_split_is_longer_than_any_training_outage():
    _, train = outages(schedule("swarmloc/VisionLossRandom-v1", SEEDS))
    count, shifted = outages(schedule("swarmloc/VisionLossRandomShifted-v1", SEEDS))
    assert shifted.min() >= VISION_OUTAGE_SHIFTED["duration_range"][0] > train.max()
    assert count.min() >= 2  # so an episode is blind for at least 20 s in all, longer than any training one

    def blind_time(task_id):
        fs = schedule(task_id, SEEDS)
        return (fs.outage_time[:, :, 1] - fs.outage_time[:, :, 0]).sum(axis=1)

    assert blind_time("swarmloc/VisionLossRandomShifted-v1").min() > blind_time("swarmloc/VisionLossRandom-v1").max()


# --------------------------------------------------------------------------- the kernel uses the draws


def test_each_episode_gets_its_own_contamination_ratio():
    """The share of Student-t fixes (those with a heavy-tail systematic error) follows the episode's ratio."""
    spec = get_spec("swarmloc/HybridNoiseRandom-v1", duration=30.0)
    seeds = [2_000_000 + k for k in range(6)]
    world = World(spec, len(seeds))
    world.reset(seeds)
    gps = world.layout.kind == GPS
    heavy = []
    for _ in range(spec.n_steps):
        buf = world.sense()
        heavy.append(np.abs(buf.systematic[:, gps]).sum(axis=-1)[:, 1:] > 0.0)  # followers 1..8
    share = np.mean(heavy, axis=(0, 2))
    ratio = world.schedule.hybrid_param[:, 0]
    assert np.ptp(ratio) > 0.2
    np.testing.assert_allclose(share, ratio, atol=0.04)


def test_drift_and_outages_act_inside_their_drawn_windows():
    spec = get_spec("swarmloc/GradualFaultRandom-v1")
    world = World(spec, 3)
    world.reset([2_000_000, 2_000_001, 2_000_002])
    fs = world.schedule
    gps = world.layout.kind == GPS
    for _ in range(spec.n_steps):
        buf = world.sense()
        t = world.times
        drifting = fs.drift_nodes[:, 0] & (t >= fs.drift_time[:, 0, 0])[:, None]
        assert np.array_equal(np.abs(buf.systematic[:, gps]).sum(axis=-1) > 0, drifting)
    spec = get_spec("swarmloc/VisionLossRandomShifted-v1")
    world = World(spec, 2)
    world.reset([2_000_000, 2_000_003])
    camera = world.layout.kind[0] == LANDMARK
    fs = world.schedule
    for _ in range(spec.n_steps):
        buf = world.sense()
        t = world.times
        inside = ((fs.outage_time[:, :, 0] <= t[:, None]) & (t[:, None] < fs.outage_time[:, :, 1])).any(axis=1)
        seen = buf.valid[:, :, camera].any(axis=(1, 2))
        assert not np.any(seen & inside)
        assert np.all(seen[~inside])  # the hall's landmarks are in view whenever the cameras work


# --------------------------------------------------------------------------- determinism


def world_buffers(spec, seeds: list[int], n_steps: int) -> dict[str, np.ndarray]:
    world = World(spec, len(seeds))
    world.reset(seeds)
    out: dict[str, list] = {"z": [], "valid": [], "label": [], "error_label": [], "systematic": []}
    for _ in range(n_steps):
        buf = world.sense()
        for key in out:
            out[key].append(getattr(buf, key).copy())
    return {k: np.array(v) for k, v in out.items()}


#: family → (episode duration [s], world steps compared): long enough to reach every drawn fault
RUNS = {"HybridNoise": (20.0, 200), "GradualFault": (300.0, 300), "VisionLoss": (100.0, 1000)}


@pytest.mark.parametrize("task_id", TASKS)
def test_batched_equals_single_runs_exactly(task_id):
    duration, n_steps = RUNS[task_id.split("/")[1].split("Random")[0]]
    spec = get_spec(task_id, duration=duration)
    seeds = [2_000_000, 2_000_001, 2_000_002]
    batched = world_buffers(spec, seeds, n_steps)
    for b, seed in enumerate(seeds):
        single = world_buffers(spec, [seed], n_steps)
        for key, value in single.items():
            assert np.array_equal(batched[key][:, b], value[:, 0]), f"{key} differs for seed {seed}"
    together = evaluate_task(["uniform"], spec, seeds).episodes["uniform"]
    for b, seed in enumerate(seeds):
        alone = evaluate_task(["uniform"], spec, [seed]).episodes["uniform"][0]
        assert together[b]["rmse"] == alone["rmse"]


def test_partial_reset_redraws_only_the_reset_episodes():
    spec = get_spec("swarmloc/HybridNoiseRandom-v1", duration=2.0)
    world = World(spec, 3)
    world.reset([1, 2, 3])
    before = world.schedule.hybrid_param.copy()
    world.reset([1, 9, 3], mask=np.array([False, True, False]))
    after = world.schedule.hybrid_param
    assert np.array_equal(after[[0, 2]], before[[0, 2]]) and after[1, 0] != before[1, 0]
    assert np.array_equal(after[1], schedule("swarmloc/HybridNoiseRandom-v1", [9]).hybrid_param[0])


def _schedule_digest() -> dict[str, str]:
    out = {}
    for task_id in TASKS:
        fs = schedule(task_id, SEEDS[:8])
        h = hashlib.sha256()
        for name in ("hybrid_param", "drift_time", "drift_rate", "drift_nodes", "outage_time", "outage_nodes"):
            h.update(np.ascontiguousarray(getattr(fs, name)).tobytes())
        out[task_id] = h.hexdigest()
    return out


def test_same_draws_in_another_process():
    code = ("import json, sys; sys.path.insert(0, %r)\n"
            "from test_randomized_families import _schedule_digest\n"
            "print(json.dumps(_schedule_digest()))\n") % str(__import__("pathlib").Path(__file__).parent)
    done = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True)
    assert json.loads(done.stdout.strip().splitlines()[-1]) == _schedule_digest()


# --------------------------------------------------------------------------- validation


@pytest.mark.parametrize("model, fields, message", [
    (HybridNoise, dict(ratio=0.3, ratio_range=(0.5, 0.2)), "ratio_range=.*low must be <= high"),
    (HybridNoise, dict(ratio=0.3, ratio_range=(0.5, 1.2)), "less than or equal to 1"),
    (GpsDriftRandom, dict(nodes=(1, 2), rate_range=(0.3, 0.1)), "rate_range=.*low must be <= high"),
    (GpsDriftRandom, dict(nodes=(1, 2), start_range=(-1.0, 5.0)), "greater than or equal to 0"),
    (GpsDriftRandom, dict(nodes=(1, 2), duration_range=(0.0, 5.0)), "greater than 0"),
    (GpsDriftRandom, dict(nodes=(1, 2), n_drifting_range=(1, 3)), "at most len\\(nodes\\)=2"),
    (GpsDriftRandom, dict(nodes=(1, 2), n_drifting_range=(-1, 1)), "greater than or equal to 0"),
    (GpsDriftRandom, dict(nodes=(1, 1)), "lists a UAV twice"),
    (GpsDriftRandom, dict(nodes=()), "at least 1"),
    (VisionOutageRandom, dict(count_range=(3, 2)), "count_range=.*low must be <= high"),
    (VisionOutageRandom, dict(count_range=(-1, 2)), "greater than or equal to 0"),
    (VisionOutageRandom, dict(duration_range=(10.0, 5.0)), "duration_range=.*low must be <= high"),
    (VisionOutageRandom, dict(span=(50.0, 40.0)), "span=.*end must be > start"),
    (VisionOutageRandom, dict(count_range=(1, 5), duration_range=(5.0, 20.0)), "do not fit in span"),
])
def test_fault_models_refuse_bad_ranges(model, fields, message):
    with pytest.raises(pydantic.ValidationError, match=message):
        model(**fields)


def test_task_spec_checks_the_random_faults_against_the_task():
    with pytest.raises(pydantic.ValidationError, match=r"gps_drift_random.nodes contains \[5\]"):
        get_spec("swarmloc/GradualFaultRandom-v1", faults={"gps_drift_random": {"nodes": (1, 5)}})
    with pytest.raises(pydantic.ValidationError, match="GPS faults need sensors.gps_sigma"):
        get_spec("swarmloc/Ideal-v1", faults={"gps_drift_random": {"nodes": (0,)}})
    with pytest.raises(pydantic.ValidationError, match="vision_outage_random needs landmarks"):
        get_spec("swarmloc/Ideal-v1", faults={"vision_outage_random": {}})
    # no outage at all is allowed: every window is padding
    fs = schedule("swarmloc/VisionLossRandom-v1", SEEDS[:3], faults={"vision_outage_random": {"count_range": (0, 0)}})
    assert fs.outage_time.shape == (3, 0, 2)


def test_documented_ranges_reach_the_task_pages():
    from swarmloc.envs.tasks.docs import _faults

    text = " ".join(_faults(get_spec("swarmloc/GradualFaultRandom-v1")))
    assert "0.05–0.25 m/s" in text and "[50.0, 150.0] s" in text
    text = " ".join(_faults(get_spec("swarmloc/HybridNoiseRandomShifted-v1")))
    assert "drawn per episode uniform in [0.05, 0.5]" in text and "ν ∈ [2, 2]" in text
    text = " ".join(_faults(get_spec("swarmloc/VisionLossRandomShifted-v1")))
    assert "2–3 per episode" in text and "10–20 s" in text
