"""The UTIL TDOA flights: importer, filtering rules, replay and the real-flight tasks.

A synthetic flight (written here) tests the rules everywhere. With the staged data
(``$SWARMLOC_DATA/util-tdoa`` or ``../shared/data/util-tdoa``): the importer reproduces the
staged CSVs byte for byte and the row counts of every flight, the impossible values are
dropped and counted as the README counts them, the tasks' windows are the airborne
windows, replays are deterministic. No dataset file may be tracked by git.
"""

from __future__ import annotations

import csv
import gzip
import subprocess
from pathlib import Path

import numpy as np
import pytest

from swarmloc.envs.world.core import LinkTrustCore
from swarmloc.envs.recorded import tdoa_flight as T
from swarmloc.envs.recorded.cfusdlog import read_usd_log
from swarmloc.envs.recorded.replay import RecordedWorld
from swarmloc.envs.recorded.tdoa_import import TdoaImportError, find_tdoa_data, import_util_tdoa, tdoa_tables
from swarmloc.envs.tasks.specs import ring_pairs
from swarmloc.envs.tasks.catalogue import UTIL_TDOA_FLIGHTS, get_spec
from swarmloc.envs.world.worlds import data_missing, make_world

REPO_ROOT = Path(__file__).resolve().parents[1]
TASKS = [f"swarmloc/{name}-v1" for name in UTIL_TDOA_FLIGHTS]
try:
    FOLDER: Path | None = find_tdoa_data()
except FileNotFoundError as exc:
    FOLDER, WHY = None, str(exc).splitlines()[0]
needs_data = pytest.mark.skipif(FOLDER is None, reason=f"UTIL TDOA data absent: {WHY if FOLDER is None else ''}")
#: the README's count of physically impossible values per flight (anomaly 2)
README_IMPOSSIBLE = {"c0425-tdoa2-traj2-los": 1, "c0425-tdoa3-traj14-los": 34, "c0426-tdoa2-traj1-nolabel": 2,
                     "c0426-tdoa2-traj3-wood": 8, "c0426-tdoa2-traj11-wood-card-plastic-metal": 17,
                     "c0426-tdoa3-traj15-noobs": 86, "c0426-tdoa3-traj13-wood-card-plastic-metal": 108,
                     "c0607-tdoa2-obs-log1-wood-plastic-metal": 0}


def flights() -> list[dict[str, str]]:
    with open(FOLDER / "flights.csv", newline="") as f:
        return list(csv.DictReader(f))


# --------------------------------------------------------------------------- without data


def write_gz(path: Path, header: str, rows: np.ndarray, fmt: str) -> None:
    with gzip.open(path, "wt") as f:
        f.write(header + "\n" + "".join(fmt % tuple(r) + "\n" for r in rows))


@pytest.fixture()
def synthetic(tmp_path: Path) -> Path:
    """A 4-anchor flight: hover at 1 m from 1 s to 3 s, on the floor before and after."""
    folder = tmp_path / "util-tdoa"
    (folder / "fl").mkdir(parents=True)
    anchors = np.array([[-3.0, -3.0, 0.2], [3.0, -3.0, 3.0], [3.0, 3.0, 0.2], [-3.0, 3.0, 3.0]])
    (folder / "anchors_cx.csv").write_text("anchor_id,x,y,z\n" + "".join(
        f"{i},{x},{y},{z}\n" for i, (x, y, z) in enumerate(anchors)))
    t_m = np.arange(0.0, 4.0, 0.005)
    z_m = np.where((t_m > 1.0) & (t_m < 3.0), 1.0, 0.02)
    mocap = np.column_stack([t_m, 0.5 + 0 * t_m, -0.2 + 0 * t_m, z_m, 0 * t_m, 0 * t_m, 0 * t_m, 1 + 0 * t_m])
    write_gz(folder / "fl" / "mocap.csv.gz", "t,x,y,z,qx,qy,qz,qw", mocap, "%.6f" + ",%.6f" * 7)
    t_i = np.arange(0.0, 4.0, 0.001)
    imu = np.column_stack([t_i, 0 * t_i, 0 * t_i, 9.81 + 0 * t_i, 0 * t_i, 0 * t_i, 0 * t_i])
    write_gz(folder / "fl" / "imu.csv.gz", "t,ax,ay,az,gx,gy,gz", imu, "%.6f" + ",%.6f" * 6)
    rows = []
    p = T.tag_positions(mocap, np.array([2.0]))[0]
    truth = {(i, j): T.range_differences(p[None], anchors, np.array([i]), np.array([j]))[0]
             for i in range(4) for j in range(4)}
    for k, t in enumerate(np.arange(0.5, 3.5, 0.004)):
        i, j = [(0, 1), (1, 2), (2, 3), (3, 0), (1, 3)][k % 5]
        rows.append((t, i, j, truth[i, j]))
    rows[100] = (rows[100][0], 0, 1, 25.0)                      # impossible: baseline ‖a_0 − a_1‖ ≈ 6.6 m
    rows[101] = (rows[101][0], 2, 1, -truth[1, 2])              # reversed pair: feeds channel (1, 2) negated
    write_gz(folder / "fl" / "tdoa.csv.gz", "t,idA,idB,tdoa_m", np.array(rows, dtype=object), "%.6f,%d,%d,%.6f")
    return folder


def test_rules_on_a_synthetic_flight(synthetic: Path):
    start, n = 1.02, 190
    rec = T.load_tdoa_recording(synthetic, "fl", start, n, 0.01, "anchors_cx.csv", ring_pairs(4), 0.15)
    c = rec.counts
    assert c.logged == 750 and c.impossible == 1
    # rows outside (start, start + n·dt] are on the floor; (1, 3) is not a ring pair
    t_rows = np.arange(0.5, 3.5, 0.004)
    inside = (t_rows > start + 1e-9) & (t_rows <= start + n * 0.01 + 1e-9)
    assert c.outside == int((~inside).sum()) - int(not inside[100])
    assert c.off_layout == sum(1 for k in np.nonzero(inside)[0] if k % 5 == 4 and k != 100)
    assert c.used + c.superseded + c.off_layout + c.outside + c.impossible == c.logged
    assert T.airborne_window(T.read_tdoa_log(synthetic / "fl").mocap) == pytest.approx((1.005, 2.995))
    # on the hover the measurements equal the truth: residual 0, nothing labelled
    assert rec.valid[1:].any(axis=0).all() and not rec.label.any()
    assert np.abs(rec.residual[rec.valid]).max() < 1e-5
    assert rec.z.shape == (n + 1, 4) and not rec.valid[0].any()


def test_missing_data_names_source_and_import_command(tmp_path, monkeypatch):
    monkeypatch.setenv("SWARMLOC_DATA", str(tmp_path))
    for task in TASKS:
        why = data_missing(get_spec(task))
        assert why is not None and "utiasDSL/util-uwb-dataset" in why and "swarmloc data import-util-tdoa" in why
        assert "39efa0739607e39203a764f492e7ac91089a6e73" in why
    (tmp_path / "util-tdoa").mkdir()
    why = data_missing(get_spec(TASKS[0]))
    assert "'c0425-tdoa2-traj2-los' is missing" in why
    with pytest.raises(FileNotFoundError, match="import-util-tdoa"):
        make_world(get_spec(TASKS[0]), 1)


def test_import_refuses_bad_names_and_a_lone_survey(tmp_path):
    with pytest.raises(TdoaImportError, match="plain name"):
        import_util_tdoa(tmp_path / "x.bin", tmp_path, "../up")
    with pytest.raises(TdoaImportError, match="together"):
        import_util_tdoa(tmp_path / "x.bin", tmp_path, "fl", survey=tmp_path / "s.npz")


def test_no_dataset_file_is_tracked_by_git():
    files = subprocess.run(["git", "ls-files"], cwd=REPO_ROOT, capture_output=True, text=True, check=True).stdout
    bad = [f for f in files.splitlines()
           if "util-tdoa" in f or "util-twr" in f or f.endswith((".bin", "tdoa.csv.gz", "imu.csv.gz"))
           or Path(f).name.startswith(("anchors_c0", "anchor_0"))]
    assert not bad, f"dataset files are tracked: {bad}"


# --------------------------------------------------------------------------- with data


@needs_data
def test_row_counts_of_every_staged_flight():
    for row in flights():
        tables = {t.file_name: t for t in tdoa_tables(read_usd_log(FOLDER / row["raw_file"]))}
        for stream in ("tdoa", "mocap", "imu", "tof", "flow", "baro"):
            expected = row[f"n_{stream}"]
            assert (tables[f"{stream}.csv.gz"].n_rows if f"{stream}.csv.gz" in tables else "") == \
                (int(expected) if expected else ""), (row["flight"], stream)


@needs_data
@pytest.mark.parametrize("flight, constellation", [("c0425-tdoa2-traj2-los", "c0425"),
                                                   ("c0426-tdoa3-traj13-wood-card-plastic-metal", "c0426")])
def test_import_reproduces_the_staged_csvs(tmp_path, flight, constellation):
    raw = next(r["raw_file"] for r in flights() if r["flight"] == flight)
    session = constellation.removeprefix("c")
    counts = import_util_tdoa(FOLDER / raw, tmp_path, flight, survey=FOLDER / f"raw/survey/anchor_{session}.npz",
                              constellation=constellation)
    staged = sorted(p.name for p in (FOLDER / flight).iterdir())
    assert sorted(p.name for p in (tmp_path / flight).iterdir()) == staged
    for name in staged:
        with gzip.open(tmp_path / flight / name) as mine, gzip.open(FOLDER / flight / name) as theirs:
            assert mine.read() == theirs.read(), name
    assert (tmp_path / f"anchors_{constellation}.csv").read_bytes() == \
        (FOLDER / f"anchors_{constellation}.csv").read_bytes()
    assert counts[f"{flight}/tdoa.csv.gz"] == int(next(r["n_tdoa"] for r in flights() if r["flight"] == flight))


@needs_data
def test_impossible_values_are_dropped_and_counted_as_the_readme_counts():
    for task in TASKS:
        spec = get_spec(task)
        rec = make_world(spec, 1).recording
        assert rec.counts.impossible == README_IMPOSSIBLE[spec.trajectory.log], task
        c = rec.counts
        assert c.used + c.superseded + c.off_layout + c.outside + c.impossible == c.logged
        assert c.used == int(rec.valid[1:].sum())
        # nothing replayed exceeds its baseline
        base = np.linalg.norm(rec.anchors[rec.pairs[:, 0]] - rec.anchors[rec.pairs[:, 1]], axis=1)
        assert (np.abs(rec.z) <= base + 1e-12).all()


@needs_data
def test_windows_are_the_airborne_windows():
    for task in TASKS:
        spec = get_spec(task)
        log = T.read_tdoa_log(FOLDER / spec.trajectory.log)
        first, last = T.airborne_window(log.mocap)
        start, end = spec.trajectory.start, spec.trajectory.start + spec.duration
        assert 0 <= start - first < 0.01 and 0 <= last - end < 0.01, (task, first, last)
        assert (np.interp(np.linspace(start, end, 200), log.mocap[:, 0], log.mocap[:, 3]) > 0.3).all()


@needs_data
def test_replay_is_deterministic_and_channels_follow_the_arrivals():
    spec = get_spec(TASKS[4], duration=2.0)  # the c0426 TDOA2 metal flight
    a, b = RecordedWorld(spec, 2), RecordedWorld(spec, 2)
    xa, xb = a.reset([1, 2]).copy(), b.reset([1, 2]).copy()
    assert np.array_equal(xa, xb) and not np.array_equal(xa[0], xa[1])
    log = T.read_tdoa_log(FOLDER / spec.trajectory.log)
    t = a.recording.t
    for k in range(1, spec.n_steps + 1):
        ba, bb = a.sense(), b.sense()
        assert np.array_equal(ba.z, bb.z) and np.array_equal(ba.valid, bb.valid)
        arrived = log.tdoa[(log.tdoa[:, 0] > t[k] - spec.dt + 1e-9) & (log.tdoa[:, 0] <= t[k] + 1e-9)]
        for c, (i, j) in enumerate(ring_pairs(8)):
            mine = arrived[(arrived[:, 1] == i) & (arrived[:, 2] == j)]
            assert ba.valid[0, 0, c] == (len(mine) > 0), (k, c)
            if len(mine):
                assert ba.z[0, 0, c, 0] == mine[-1, 3]


@needs_data
def test_uniform_core_tracks_the_los_flight():
    spec = get_spec(TASKS[0], duration=10.0)
    core = LinkTrustCore(spec, 1)
    core.reset([1_000_000])
    err = []
    for _ in range(spec.n_steps):
        step = core.step(np.ones((1, 1, spec.n_channels)))
        err.append(np.linalg.norm(step.estimate - step.truth))
    assert np.sqrt(np.mean(np.square(err))) < 0.4
