"""Import the UTIL UWB dataset's TDOA flight logs (Crazyflie µSD, format v2) into gzip CSVs.

Output layout (one folder per flight, the anchors of each constellation beside them)::

    OUT/anchors_<constellation>.csv   anchor_id,x,y,z          Vicon frame (the survey's ``an_pos``)
    OUT/<flight>/tdoa.csv.gz          t,idA,idB,tdoa_m         tdoa_m ≈ ‖p − a_idB‖ − ‖p − a_idA‖ [m]
    OUT/<flight>/mocap.csv.gz         t,x,y,z,qx,qy,qz,qw      m, unit quaternion (scalar last)
    OUT/<flight>/imu.csv.gz           t,ax,ay,az,gx,gy,gz      m/s², rad/s
    OUT/<flight>/tof.csv.gz           t,range_m                only where the log has ToF records
    OUT/<flight>/flow.csv.gz          t,delta_x_px,delta_y_px  only where the log has flow records
    OUT/<flight>/baro.csv.gz          t,asl_m                  only where the log has barometer records

The rules are those of the staged dataset README (``<data>/util-tdoa/README.md``), and
importing a raw log reproduces the staged CSVs byte for byte (checked by the tests):

* ``t`` is seconds since T0, the smallest raw timestamp over every record of the log,
  printed with 6 decimals (exact: the onboard clock ticks in µs).
* Each gyro sample is paired 1:1 with the accelerometer sample closest in time (ties go
  to the earlier one); the units are converted in float32, as the firmware logs them
  (acc in g × 9.81, gyro in °/s × π/180), then printed with 6 decimals.
* Every value is printed as logged, unfiltered: the gross TDOA outliers stay in the CSV.
  The filtering rules (impossible values, the on-the-floor segments, dropouts) are applied
  when a flight is replayed (``tdoa_flight``), where they are counted.
* A negative zero prints as ``0.000000``.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from swarmloc.envs.recorded.cfusdlog import UsdLog, read_usd_log
from swarmloc.envs.recorded.util_import import Table, dataset_folder, install_folder

__all__ = [
    "DATASET_DIR",
    "IMPORT_COMMAND",
    "TDOA_SOURCE",
    "TdoaImportError",
    "anchor_table_text",
    "find_tdoa_data",
    "import_util_tdoa",
    "read_survey_npz",
    "tdoa_tables",
]

DATASET_DIR = "util-tdoa"
IMPORT_COMMAND = ("swarmloc data import-util-tdoa RAW_LOG --flight NAME --survey anchor_<session>.npz "
                  "--constellation c<session> --out DIR")
TDOA_SOURCE = (
    "GitHub utiasDSL/util-uwb-dataset (no licence file: internal benchmarking only, "
    "cite Zhao et al., 'UTIL', IJRR 43(10), 2024); the raw TDOA logs and surveys are only in "
    "commit 39efa0739607e39203a764f492e7ac91089a6e73:\n"
    "  2_data/sd-card-data/0425/TDOA2/0425-traj2, 0425/TDOA3/0425-traj14, 0426/0426-traj{1,3,11,13,15},\n"
    "  2_data/sd-card-data/0607/tdoa2-obs-log1; surveys 3_scripts/survey/anchor_{0425,0426,0607}.npz\n"
    "  (e.g. git -C util-uwb-dataset show 39efa07:2_data/sd-card-data/0426/0426-traj11 > 0426-traj11.bin)"
)

# the dataset's g → m/s² factor, applied in float32 as the staged CSVs do
G_TO_MPS2 = np.float32(9.81)
_NAME = re.compile(r"[A-Za-z0-9_-][A-Za-z0-9._-]*")

_POSE = tuple(f"locSrv.{k}" for k in ("x", "y", "z", "qx", "qy", "qz", "qw"))
_REQUIRED: dict[str, tuple[str, ...]] = {
    "estTDOA": ("idA", "idB", "distanceDiff"),
    "estPose": _POSE,
    "estGyroscope": ("gyro.x", "gyro.y", "gyro.z"),
    "estAcceleration": ("acc.x", "acc.y", "acc.z"),
}
_OPTIONAL: dict[str, tuple[str, ...]] = {
    "estTOF": ("range.zrange",),
    "estFlow": ("motion.deltaX", "motion.deltaY"),
    "estBarometer": ("baro.asl",),
}


class TdoaImportError(ValueError):
    """A raw log or survey does not fit the UTIL TDOA layout (the message says what)."""


def _records(log: UsdLog, name: str, variables: tuple[str, ...], required: bool) -> np.ndarray | None:
    """The records of one event, checked for its variables and strictly increasing time; None if absent."""
    records = log.events.get(name)
    if records is None or len(records) == 0:
        if required:
            raise TdoaImportError(f"the log has no {name!r} records; a UTIL TDOA log has "
                                  f"{sorted(_REQUIRED)} (this one: {sorted(log.events)})")
        return None
    missing = [v for v in variables if v not in records.dtype.names]
    if missing:
        raise TdoaImportError(f"event {name!r} lacks variables {missing}; found {list(records.dtype.names[1:])}")
    steps = np.diff(records["timestamp_us"].astype(np.int64))
    if (steps <= 0).any():
        i = int(np.argmax(steps <= 0))
        raise TdoaImportError(f"event {name!r}: record {i + 1} is not after record {i} "
                              f"({int(records['timestamp_us'][i + 1])} ≤ {int(records['timestamp_us'][i])} µs)")
    return records


def _closest(t_ref: np.ndarray, t_other: np.ndarray) -> np.ndarray:
    """Index into ``t_other`` of the sample closest in time to each ``t_ref`` (ties: the earlier)."""
    after = np.searchsorted(t_other, t_ref, side="left")
    before = np.clip(after - 1, 0, len(t_other) - 1)
    after = np.clip(after, 0, len(t_other) - 1)
    return np.where(np.abs(t_other[before] - t_ref) <= np.abs(t_other[after] - t_ref), before, after)


def _f64(records: np.ndarray, *names: str) -> tuple[np.ndarray, ...]:
    # + 0.0 turns a negative zero into 0.0 (the staged CSVs print "0.000000")
    return tuple(records[name].astype(np.float64) + 0.0 for name in names)


def tdoa_tables(log: UsdLog) -> list[Table]:
    """Convert a decoded UTIL TDOA log into its CSV tables (rules in the module docstring).

    Args:
        log: the decoded µSD log.

    Returns:
        Tables tdoa, mocap, imu, then tof, flow, baro where the log has such records.

    Raises:
        TdoaImportError: a required event (estTDOA, estPose, estGyroscope,
            estAcceleration) has no records or lacks a variable, a stream's timestamps are
            not strictly increasing, or the gyro and accelerometer counts differ (the 1:1
            pairing of the README needs equal counts).
    """
    ev = {name: _records(log, name, v, True) for name, v in _REQUIRED.items()}
    opt = {name: _records(log, name, v, False) for name, v in _OPTIONAL.items()}
    t0 = min(int(r["timestamp_us"].min()) for r in log.events.values() if len(r))

    def t(records: np.ndarray) -> np.ndarray:
        return records["timestamp_us"].astype(np.int64) - t0

    gyro, acc = ev["estGyroscope"], ev["estAcceleration"]
    partner = _closest(t(gyro), t(acc))
    if len(gyro) != len(acc) or len(np.unique(partner)) != len(gyro):
        raise TdoaImportError(f"{len(gyro)} gyro and {len(acc)} accelerometer records do not pair 1:1 by "
                              "closest time")
    acc = acc[partner]
    tdoa, pose = ev["estTDOA"], ev["estPose"]
    tables = [
        Table("tdoa.csv.gz", "t,idA,idB,tdoa_m", ",%d,%d,%.6f", t(tdoa),
              (tdoa["idA"].astype(np.int64), tdoa["idB"].astype(np.int64)) + _f64(tdoa, "distanceDiff")),
        Table("mocap.csv.gz", "t,x,y,z,qx,qy,qz,qw", ",%.6f" * 7, t(pose), _f64(pose, *_POSE)),
        Table("imu.csv.gz", "t,ax,ay,az,gx,gy,gz", ",%.6f" * 6, t(gyro),
              tuple((acc[a] * G_TO_MPS2).astype(np.float64) + 0.0 for a in ("acc.x", "acc.y", "acc.z"))
              + tuple(np.deg2rad(gyro[g]).astype(np.float64) + 0.0 for g in ("gyro.x", "gyro.y", "gyro.z"))),
    ]
    if (tof := opt["estTOF"]) is not None:
        tables.append(Table("tof.csv.gz", "t,range_m", ",%.3f", t(tof),
                            (tof["range.zrange"].astype(np.float64) * 1e-3,)))
    if (flow := opt["estFlow"]) is not None:
        tables.append(Table("flow.csv.gz", "t,delta_x_px,delta_y_px", ",%d,%d", t(flow),
                            (flow["motion.deltaX"].astype(np.int64), flow["motion.deltaY"].astype(np.int64))))
    if (baro := opt["estBarometer"]) is not None:
        tables.append(Table("baro.csv.gz", "t,asl_m", ",%.6f", t(baro), _f64(baro, "baro.asl")))
    return tables


def read_survey_npz(path: str | Path) -> np.ndarray:
    """The Vicon-frame anchor positions ``(A, 3)`` of a UTIL survey ``.npz`` (field ``an_pos``).

    Raises:
        TdoaImportError: no ``an_pos`` field, or not an ``(A, 3)`` array.
    """
    with np.load(path) as survey:
        if "an_pos" not in survey.files:
            raise TdoaImportError(f"{path}: no 'an_pos' field (found {survey.files}); pass the dataset's "
                                  "converted survey anchor_<session>.npz")
        pos = np.asarray(survey["an_pos"], dtype=np.float64)
    if pos.ndim != 2 or pos.shape[1] != 3 or len(pos) == 0:
        raise TdoaImportError(f"{path}: an_pos has shape {pos.shape}, expected (A, 3)")
    return pos


def anchor_table_text(anchors: np.ndarray) -> str:
    """``anchors_<constellation>.csv`` text: positions rounded to 0.1 mm, as staged."""
    return "anchor_id,x,y,z\n" + "".join(f"{i},{x:.4f},{y:.4f},{z:.4f}\n" for i, (x, y, z) in enumerate(anchors))


def import_util_tdoa(raw_log: str | Path, out_dir: str | Path, flight: str, *, survey: str | Path | None = None,
                     constellation: str | None = None, overwrite: bool = False) -> dict[str, int]:
    """Import one UTIL TDOA µSD log (and optionally its constellation's survey) into ``out_dir``.

    Everything is decoded first and written into a temporary folder inside ``out_dir``
    that is then renamed into place, so a failure leaves ``out_dir`` as it was.

    Args:
        raw_log: the binary µSD log (e.g. ``0426-traj11.bin``).
        out_dir: the dataset folder (usually ``<SWARMLOC_DATA>/util-tdoa``); created if absent.
        flight: folder name of the flight, e.g. ``c0426-tdoa2-traj11-wood-card-plastic-metal``.
        survey: the session's converted survey ``anchor_<session>.npz``; with it,
            ``anchors_<constellation>.csv`` is written too.
        constellation: the constellation name (``c0426``); required with ``survey``.
        overwrite: replace an existing flight folder.

    Returns:
        Data rows per written file, keyed by the path relative to ``out_dir``.

    Raises:
        UsdLogError: the raw log is corrupt, truncated or not a µSD event log.
        TdoaImportError: the log or survey does not fit the UTIL TDOA layout, or a name is
            not a plain folder name.
        FileExistsError: the flight folder exists and ``overwrite`` is false.
    """
    raw_log, out_dir = Path(raw_log), Path(out_dir)
    for what, name in (("flight", flight), ("constellation", constellation)):
        if name is not None and not _NAME.fullmatch(name):
            raise TdoaImportError(f"{what} name {name!r} is not a plain name (letters, digits, '.', '_', '-')")
    if (survey is None) != (constellation is None):
        raise TdoaImportError("pass survey and constellation together (the anchors file is named after it)")
    target = out_dir / flight
    if target.exists() and not overwrite:
        raise FileExistsError(f"{target} already exists; pass overwrite=True to replace it")
    tables = tdoa_tables(read_usd_log(raw_log))
    anchors = None if survey is None else read_survey_npz(survey)
    if anchors is not None:
        ids = np.concatenate([tables[0].values[0], tables[0].values[1]])
        if ids.max() >= len(anchors):
            raise TdoaImportError(f"the log names anchor {int(ids.max())}; the survey has 0..{len(anchors) - 1}")

    files = {} if anchors is None else {f"anchors_{constellation}.csv": anchor_table_text(anchors)}
    install_folder(out_dir, flight, tables, files, overwrite)
    counts = {f"{flight}/{table.file_name}": table.n_rows for table in tables}
    if anchors is not None:
        counts[f"anchors_{constellation}.csv"] = len(anchors)
    return counts


def find_tdoa_data(data_dir: str | Path | None = None) -> Path:
    """Locate the UTIL TDOA dataset folder (``.../util-tdoa``).

    The data folder (the one that contains ``util-tdoa/``) is, in order: ``data_dir``; else
    ``$SWARMLOC_DATA``; else ``../shared/data`` next to this checkout.

    Raises:
        FileNotFoundError: the folder does not exist; the message says where the data comes
            from and which command imports it.
    """
    return dataset_folder(data_dir, DATASET_DIR, "UTIL TDOA", TDOA_SOURCE, IMPORT_COMMAND)
