"""UTILFlight-v0: the real UTIL Crazyflie flight replayed behind the world interface.

Without the data only the spec, the factory and the error messages are tested; with it
(``$SWARMLOC_DATA`` or ``../shared/data``): determinism, the scored window, channel
validity against the UWB arrivals, an estimate path free of truth, the calibration, and
the accuracy ordering uniform ≥ chi2-gate ≥ oracle on twr-obs-log1.
"""

from __future__ import annotations

import gzip
import os
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import swarmloc.envs  # noqa: F401  (registers the tasks)
from swarmloc.envs.world.core import LinkTrustCore
from swarmloc.envs.recorded import util_flight
from swarmloc.envs.recorded.replay import RecordedWorld
from swarmloc.envs.recorded.util_import import find_util_data
from swarmloc.envs.tasks.specs import RecordedFlight, TaskSpec
from swarmloc.envs.tasks.catalogue import get_spec
from swarmloc.envs.world.sim import World
from swarmloc.envs.world.worlds import data_missing, is_recorded, make_world

TASK = "swarmloc/UTILFlight-v0"
SPEC = get_spec(TASK)
MISSING = data_missing(SPEC)
needs_data = pytest.mark.skipif(MISSING is not None,
                                reason=f"UTIL data absent: {(MISSING or '').partition(chr(10))[0]}")


def short(seconds: float, **overrides) -> TaskSpec:
    return get_spec(TASK, duration=seconds, **overrides)


# --------------------------------------------------------------------------- without data


def test_spec_describes_the_layout_without_data():
    assert is_recorded(SPEC) and isinstance(SPEC.trajectory, RecordedFlight)
    assert (SPEC.n_uav, SPEC.n_channels, SPEC.dt, SPEC.n_steps) == (1, 8, 0.01, 5047)
    assert SPEC.trajectory.start == 9.15 and SPEC.trajectory.log == "twr-obs-log1"
    assert SPEC.anchors == ((0.0, 0.0, 0.0),) * 8  # placeholders: the survey comes from the data
    assert TaskSpec.model_validate_json(SPEC.model_dump_json()) == SPEC
    assert get_spec(TASK, trajectory={"calibration": None}).trajectory.calibration is None


def test_simulated_world_refuses_a_recorded_spec():
    with pytest.raises(ValueError, match="make_world"):
        World(SPEC, 1)


def test_missing_data_names_source_and_import_command(tmp_path, monkeypatch):
    monkeypatch.setenv("SWARMLOC_DATA", str(tmp_path))
    why = data_missing(SPEC)
    assert why is not None
    for part in ("utiasDSL/util-uwb-dataset", "39efa0739607e39203a764f492e7ac91089a6e73",
                 "705abe8e12845b7b9433a1a579b7b9eead68437c", "2_data/sd-card-data/0607/twr-obs-log1",
                 "swarmloc data import-util"):
        assert part in why
    for build in (lambda: make_world(SPEC, 1), lambda: gym.make(TASK), lambda: LinkTrustCore(SPEC, 1)):
        with pytest.raises(FileNotFoundError, match="swarmloc data import-util"):
            build()
    assert data_missing(get_spec("swarmloc/Ideal-v0")) is None


def test_missing_log_is_named(tmp_path, monkeypatch):
    (tmp_path / "util-twr").mkdir()
    monkeypatch.setenv("SWARMLOC_DATA", str(tmp_path))
    why = data_missing(SPEC)
    assert why is not None and "'twr-obs-log1'" in why and "swarmloc data import-util" in why


# --------------------------------------------------------------------------- with data


def run(world: RecordedWorld, seeds: list[int], n: int) -> dict[str, np.ndarray]:
    """Reset and sense ``n`` steps; every buffer stacked over time."""
    x0 = world.reset(seeds).copy()
    out: dict[str, list] = {name: [] for name in ("pos", "vel", "imu", "z", "valid", "label", "injected")}
    for _ in range(n):
        buf = world.sense()
        for name in out:
            out[name].append(getattr(buf, name).copy())
    return {"x0": x0, **{name: np.array(v) for name, v in out.items()}}


@needs_data
def test_replay_is_deterministic_and_the_seed_only_moves_the_prior():
    spec = short(3.0)
    a = run(RecordedWorld(spec, 2), [3, 7], spec.n_steps)
    b = run(RecordedWorld(spec, 2), [3, 7], spec.n_steps)
    single = run(RecordedWorld(spec, 1), [7], spec.n_steps)
    for name in a:
        assert np.array_equal(a[name], b[name]), name
        assert np.array_equal(a[name][:, 1:] if name != "x0" else a[name][1:], single[name]), name
    assert not np.array_equal(a["x0"][0], a["x0"][1])  # different seeds: different initial priors
    for name in ("pos", "imu", "z", "valid", "label"):
        assert np.array_equal(a[name][:, 0], a[name][:, 1]), name  # … and the same recording
    rec = RecordedWorld(spec, 1).recording
    assert np.abs(a["x0"][:, 0, :3] - rec.pos[0]).max() < 5 * spec.filter.init_pos_sigma


@needs_data
def test_scored_window_is_take_off_to_landing():
    folder = find_util_data()
    mocap = util_flight.read_flight_log(folder / "twr-obs-log1").mocap
    takeoff, landing = util_flight.airborne_window(mocap)
    start, end = SPEC.trajectory.start, SPEC.trajectory.start + SPEC.duration
    assert abs(takeoff - start) < 0.02 and abs(landing - end) < 0.02, (takeoff, landing)
    rec = RecordedWorld(SPEC, 1).recording
    assert rec.t[0] == pytest.approx(9.15) and rec.t[-1] == pytest.approx(59.62)
    assert rec.pos[:, 2].max() == pytest.approx(1.68, abs=0.01)  # README: max z 1.68 m
    with pytest.raises(ValueError, match="does not fit"):
        RecordedWorld(short(60.0), 1)


@needs_data
def test_channel_valid_exactly_when_a_range_arrived():
    spec = short(6.0)
    world = RecordedWorld(spec, 1)
    rec = world.recording
    uwb = util_flight.read_flight_log(world.data_folder / "twr-obs-log1").uwb
    t = rec.t
    for k in range(1, spec.n_steps + 1):
        inside = uwb[(uwb[:, 0] > t[k] - spec.dt + 1e-9) & (uwb[:, 0] <= t[k] + 1e-9)]
        for a in range(8):
            mine = inside[inside[:, 1] == a]
            assert rec.valid[k, a] == (len(mine) > 0), (k, a)
            if len(mine):
                assert rec.z[k, a] == pytest.approx(mine[-1, 2] - rec.bias[a])
    sensed = run(world, [0], spec.n_steps)
    assert np.array_equal(sensed["valid"][:, 0, 0], rec.valid[1:])
    assert np.array_equal(sensed["z"][:, 0, 0, :, 0], rec.z[1:])
    assert not (sensed["label"] & ~sensed["valid"]).any()
    per_anchor_hz = rec.valid[1:].sum(axis=0) / spec.duration
    assert ((per_anchor_hz > 8.0) & (per_anchor_hz < 13.0)).all()  # README: ≈10.4 Hz per anchor


@needs_data
def test_estimate_path_uses_no_truth(tmp_path):
    """Scramble the flight's mocap (position and attitude): IMU input and ranges do not change."""
    folder = find_util_data()
    fake = tmp_path / "util-twr"
    (fake / "twr-obs-log1").mkdir(parents=True)
    os.symlink(folder / "anchors.csv", fake / "anchors.csv")
    os.symlink(folder / "log00", fake / "log00")  # the calibration log's mocap is allowed
    for name in ("imu", "uwb_range"):
        os.symlink(folder / "twr-obs-log1" / f"{name}.csv.gz", fake / "twr-obs-log1" / f"{name}.csv.gz")
    mocap = util_flight.read_flight_log(folder / "twr-obs-log1").mocap.copy()
    rng = np.random.default_rng(0)
    mocap[:, 1:4] += rng.normal(0.0, 0.5, 3)
    q = rng.normal(size=(len(mocap), 4))
    mocap[:, 4:8] = q / np.linalg.norm(q, axis=1, keepdims=True)
    with gzip.open(fake / "twr-obs-log1" / "mocap.csv.gz", "wt") as f:
        f.write("t,x,y,z,qx,qy,qz,qw\n")
        np.savetxt(f, mocap, delimiter=",", fmt="%.7f")
    spec = short(5.0)
    real = RecordedWorld(spec, 1).recording
    scrambled = RecordedWorld(spec, 1, data_dir=tmp_path).recording
    for name in ("imu", "attitude", "z", "valid", "bias"):
        assert np.array_equal(getattr(real, name), getattr(scrambled, name)), name
    assert not np.array_equal(real.pos, scrambled.pos)


@needs_data
def test_attitude_comes_from_the_imu_and_agrees_with_mocap_tilt():
    rec = RecordedWorld(SPEC, 1).recording
    mocap = util_flight.read_flight_log(find_util_data() / "twr-obs-log1").mocap
    i = np.searchsorted(mocap[:, 0], rec.t, side="right") - 1
    q_true = mocap[i][:, [7, 4, 5, 6]]  # w, x, y, z
    up = np.array([[0.0, 0.0, 1.0]])

    def body_z(q):
        return util_flight.rotate_to_world(q, np.repeat(up, len(q), axis=0))

    tilt_error = np.degrees(np.arccos(np.clip(np.sum(body_z(rec.attitude) * body_z(q_true), axis=1), -1, 1)))
    assert np.percentile(tilt_error, 95) < 3.0  # roll/pitch from gyro + accelerometer only
    # gravity removed: the mean world acceleration over the flight is near zero
    assert np.abs(rec.imu[1:].mean(axis=0)).max() < 0.05


@needs_data
def test_calibration_from_log00_and_raw_option():
    rec = RecordedWorld(SPEC, 1).recording
    readme_log00 = {0: -0.293, 1: -0.334, 3: -0.342, 4: -0.336, 6: -0.394, 7: -0.237}
    for a, mean in readme_log00.items():
        assert rec.bias[a] == pytest.approx(mean, abs=0.0015)
    assert rec.bias[2] == rec.bias[5] == np.median(rec.bias[list(readme_log00)])  # no ranges in log00
    raw = RecordedWorld(short(2.0, trajectory={"calibration": None}), 1).recording
    calibrated = RecordedWorld(short(2.0), 1).recording
    assert not raw.bias.any()
    assert np.allclose((raw.z - calibrated.z)[raw.valid], calibrated.bias[np.nonzero(raw.valid)[1]])
    assert np.array_equal(raw.label, calibrated.label)  # labels do not depend on the calibration


@needs_data
def test_fault_labels_flag_the_nlos_anchor():
    rec = RecordedWorld(SPEC, 1).recording
    rate = rec.label_rate()
    assert int(np.argmax(rate)) == 6 and rate[6] > 0.3  # README: anchor 6 drifts like NLOS
    assert (rate[[0, 1, 2, 3, 4, 5, 7]] < 0.15).all()
    assert (rec.spread > 0.0).all() and (rec.spread < 0.1).all()


@needs_data
def test_core_on_an_injected_world_with_partial_reset():
    spec = short(0.5)
    core = LinkTrustCore(spec, 2, world=RecordedWorld(spec, 2))
    ones = np.ones((2, 1, 8))
    core.reset([4, 5])
    for _ in range(20):
        core.step(ones)
    core.reset([0, 9], mask=np.array([False, True]))  # episode 1 restarts, episode 0 keeps going
    est = []
    for _ in range(30):
        est.append(core.step(ones).estimate[1].copy())
    fresh = LinkTrustCore(spec, 1)
    fresh.reset([9])
    assert np.array_equal(np.array(est), np.array([fresh.step(ones[:1]).estimate[0].copy() for _ in range(30)]))
    assert core._out.done[0] and core._out.steps[0] == spec.n_steps
    with pytest.raises(ValueError, match="injected world"):
        LinkTrustCore(spec, 3, world=RecordedWorld(spec, 2))


@needs_data
def test_gymnasium_env_runs_on_the_recording():
    env = gym.make(TASK, duration=0.3)
    obs, _ = env.reset(seed=1)
    assert obs.shape == (1, 8, 11)
    steps = 0
    truncated = False
    while not truncated:
        obs, reward, terminated, truncated, info = env.step(np.ones((1, 8), dtype=np.float32))
        steps += 1
    assert steps == 30 and np.isfinite(reward) and info["position_error"][0] < 0.5
    env.close()


@needs_data
def test_accuracy_uniform_chi2_oracle_on_twr_obs_log1():
    """The acceptance numbers: uniform ≤ 0.35 m, chi2-gate ≤ uniform, oracle ≤ both (full flight)."""
    runner = pytest.importorskip("swarmloc.bench.evaluation.runner")
    from swarmloc.agents.registry import load_method

    seeds = [1_000_000, 1_000_001]
    rmse = {}
    for name in ("uniform", "chi2-gate", "oracle"):
        metrics, _ = runner.rollout(load_method(name), SPEC, seeds)
        rmse[name] = np.array([m["rmse"] for m in metrics])
    assert (rmse["uniform"] <= 0.35).all(), rmse
    assert (rmse["chi2-gate"] <= rmse["uniform"]).all(), rmse
    assert (rmse["oracle"] <= np.minimum(rmse["uniform"], rmse["chi2-gate"])).all(), rmse


def test_import_command_is_registered(tmp_path):
    cli = pytest.importorskip("swarmloc.cli")
    status = cli.main(["data", "import-util", str(tmp_path / "missing.bin"), "--anchors",
                       str(tmp_path / "survey.txt"), "--out", str(tmp_path / "out")])
    assert status == 2 and not (tmp_path / "out").exists()


def test_data_folder_is_outside_the_repository():
    data = Path(__file__).resolve().parents[1]
    try:
        folder = find_util_data()
    except FileNotFoundError:
        pytest.skip("UTIL data absent")
    assert data not in folder.resolve().parents
