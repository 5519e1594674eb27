"""Import the UTIL UWB dataset's Crazyflie µSD logs (two-way ranging) into gzip CSVs.

Output layout (one folder per log, the anchors beside them)::

    OUT/anchors.csv                 anchor_id,x,y,z            survey rows anchorAnt0..N
    OUT/<log>/imu.csv.gz            t,ax,ay,az,gx,gy,gz        m/s², rad/s
    OUT/<log>/uwb_range.csv.gz      t,anchor_id,range_m
    OUT/<log>/mocap.csv.gz          t,x,y,z,qx,qy,qz,qw        m, unit quaternion (scalar last)
    OUT/<log>/tof.csv.gz            t,range_m
    OUT/<log>/flow.csv.gz           t,delta_x_px,delta_y_px    raw PMW3901 counts
    OUT/<log>/baro.csv.gz           t,asl_m

``t`` is seconds since T0, the smallest raw timestamp over every record of the log,
printed with 6 decimals (exact: the onboard clock ticks in µs). The conversion rules are
those of the dataset README that ships with the CSVs; importing the raw logs reproduces
those CSVs line for line.
"""

from __future__ import annotations

import gzip
import math
import os
import re
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from swarmloc.envs.recorded.cfusdlog import UsdLog, read_usd_log

__all__ = [
    "IMPORT_COMMAND",
    "UTIL_SOURCE",
    "Table",
    "UtilImportError",
    "data_root",
    "find_util_data",
    "import_util",
    "main_import_util",
    "read_anchor_survey",
    "util_tables",
]

DATASET_DIR = "util-twr"
DATA_ENV_VAR = "SWARMLOC_DATA"
IMPORT_COMMAND = "swarmloc data import-util RAW_LOG --anchors SURVEY --out DIR"
UTIL_SOURCE = (
    "GitHub utiasDSL/util-uwb-dataset (no license file: internal benchmarking only, "
    "cite Zhao et al., 'UTIL', IJRR 43(10), 2024); the raw logs are only in old commits:\n"
    "  twr-obs-log1  commit 39efa0739607e39203a764f492e7ac91089a6e73, "
    "path 2_data/sd-card-data/0607/twr-obs-log1\n"
    "  log00         commit 705abe8e12845b7b9433a1a579b7b9eead68437c, "
    "path 2_data/sd-card-data/0607/log00\n"
    "  anchors       commit 39efa0739607e39203a764f492e7ac91089a6e73, "
    "path 2_data/survey-results/anchor_0607.txt\n"
    "  (e.g. git -C util-uwb-dataset show "
    "39efa07:2_data/sd-card-data/0607/twr-obs-log1 > twr-obs-log1.bin)"
)

# The dataset converts g with 9.81, not the standard 9.80665.
G_TO_MPS2 = 9.81
DEG_TO_RAD = math.pi / 180.0
MM_TO_M = 1e-3
# The accelerometer record of one IMU read follows its gyro record by 14–129 µs in the
# UTIL logs; a partner further than one 1 kHz IMU period away belongs to another read.
MAX_IMU_PAIR_LAG_US = 1000

_ANCHOR_ROW = re.compile(r"anchorAnt(\d+)")
_LOG_NAME = re.compile(r"[A-Za-z0-9_-][A-Za-z0-9._-]*")


class UtilImportError(ValueError):
    """A raw log or survey file does not fit the UTIL TWR layout (message says what)."""


@dataclass(frozen=True)
class Table:
    """One output CSV, held as columns until it is written.

    Attributes:
        file_name: e.g. ``"imu.csv.gz"``.
        header: the header row, e.g. ``"t,range_m"``.
        value_format: ``%``-format of the columns after ``t``, e.g. ``",%.3f"``.
        t_us: ``int64`` µs since T0, one per row.
        values: the value columns, each of length ``len(t_us)``.
    """

    file_name: str
    header: str
    value_format: str
    t_us: np.ndarray
    values: tuple[np.ndarray, ...]

    @property
    def n_rows(self) -> int:
        """Number of data rows (the header not counted)."""
        return len(self.t_us)

    def to_text(self) -> str:
        """The CSV text: header, then one row per sample, newline-terminated."""
        seconds, micros = np.divmod(self.t_us, 1_000_000)
        row = "%d.%06d" + self.value_format
        columns = [seconds.tolist(), micros.tolist()] + [v.tolist() for v in self.values]
        lines = [self.header]
        lines.extend(map(row.__mod__, zip(*columns)))
        return "\n".join(lines) + "\n"


def read_anchor_survey(path: str | Path) -> np.ndarray:
    """Read the anchor antenna positions from a UTIL survey file (``anchor_0607.txt``).

    Only the rows ``anchorAnt<i>, x, y, z`` are used; the marker rows (``anchor<i>_<k>``,
    ``uwbDatasetFrame<k>``) are ignored.

    Args:
        path: the survey text file.

    Returns:
        ``(A, 3)`` float64 positions in m, row i for ``anchorAnt<i>``.

    Raises:
        UtilImportError: no anchor rows, a malformed anchor row, or ids that are not
            exactly 0..A-1.
    """
    positions: dict[int, tuple[float, float, float]] = {}
    for line_no, line in enumerate(Path(path).read_text().splitlines(), start=1):
        fields = [f.strip() for f in line.split(",")]
        match = _ANCHOR_ROW.fullmatch(fields[0])
        if match is None:
            continue
        try:
            if len(fields) != 4:
                raise ValueError
            xyz = tuple(float(f) for f in fields[1:])
        except ValueError:
            raise UtilImportError(
                f"{path}:{line_no}: anchor row {line!r} is not 'anchorAnt<i>, x, y, z'"
            ) from None
        anchor_id = int(match.group(1))
        if anchor_id in positions:
            raise UtilImportError(f"{path}:{line_no}: anchorAnt{anchor_id} appears twice")
        positions[anchor_id] = xyz  # type: ignore[assignment]
    if sorted(positions) != list(range(len(positions))) or not positions:
        raise UtilImportError(
            f"{path}: anchor ids {sorted(positions)} must be exactly 0..A-1 with A >= 1"
        )
    return np.array([positions[i] for i in range(len(positions))], dtype=np.float64)


def util_tables(log: UsdLog, n_anchors: int) -> list[Table]:
    """Convert a decoded UTIL TWR log into the six CSV tables (units and rules above).

    Each gyro sample is paired with the first accelerometer sample logged at or after it,
    provided that sample comes before the next gyro sample and within
    ``MAX_IMU_PAIR_LAG_US``; gyro samples without a partner are dropped.

    Args:
        log: the decoded µSD log.
        n_anchors: number of surveyed anchors; every UWB ``anchor_id`` must be below it.

    Returns:
        Tables for imu, uwb_range, mocap, tof, flow, baro, in that order.

    Raises:
        UtilImportError: an expected event or variable is missing, a stream's timestamps
            are not strictly increasing, or a UWB anchor id is not surveyed.
    """
    ev = {name: _event(log, name, variables) for name, variables in _REQUIRED_EVENTS.items()}
    starts = [int(records["timestamp_us"].min()) for records in log.events.values() if len(records)]
    if not starts:
        raise UtilImportError("the log holds no records at all")
    t0 = min(starts)

    def t(records: np.ndarray) -> np.ndarray:
        return records["timestamp_us"].astype(np.int64) - t0

    def f64(records: np.ndarray, *names: str) -> tuple[np.ndarray, ...]:
        return tuple(records[name].astype(np.float64) for name in names)

    gyro, acc = ev["estGyroscope"], ev["estAcceleration"]
    partner = _pair_imu(t(gyro), t(acc))
    paired = partner >= 0
    gyro, acc = gyro[paired], acc[partner[paired]]
    uwb = ev["estDistance"]
    bad = uwb["id"] >= n_anchors
    if bad.any():
        raise UtilImportError(
            f"estDistance record {int(np.argmax(bad))} has anchor id {int(uwb['id'][bad][0])}; "
            f"the survey has anchors 0..{n_anchors - 1}"
        )
    pose, tof, flow, baro = ev["estPose"], ev["estTOF"], ev["estFlow"], ev["estBarometer"]
    return [
        Table(
            "imu.csv.gz", "t,ax,ay,az,gx,gy,gz", ",%.6f" * 6, t(gyro),
            tuple(a * G_TO_MPS2 for a in f64(acc, "acc.x", "acc.y", "acc.z"))
            + tuple(g * DEG_TO_RAD for g in f64(gyro, "gyro.x", "gyro.y", "gyro.z")),
        ),
        Table(
            "uwb_range.csv.gz", "t,anchor_id,range_m", ",%d,%.6f", t(uwb),
            (uwb["id"].astype(np.int64),) + f64(uwb, "distance"),
        ),
        Table(
            "mocap.csv.gz", "t,x,y,z,qx,qy,qz,qw", ",%.6f" * 3 + ",%.7f" * 4, t(pose),
            f64(pose, *(f"locSrv.{k}" for k in ("x", "y", "z", "qx", "qy", "qz", "qw"))),
        ),
        Table(
            "tof.csv.gz", "t,range_m", ",%.3f", t(tof),
            (tof["range.zrange"].astype(np.float64) * MM_TO_M,),
        ),
        Table(
            "flow.csv.gz", "t,delta_x_px,delta_y_px", ",%d,%d", t(flow),
            (flow["motion.deltaX"].astype(np.int64), flow["motion.deltaY"].astype(np.int64)),
        ),
        Table("baro.csv.gz", "t,asl_m", ",%.4f", t(baro), f64(baro, "baro.asl")),
    ]


_REQUIRED_EVENTS: dict[str, tuple[str, ...]] = {
    "estGyroscope": ("gyro.x", "gyro.y", "gyro.z"),
    "estAcceleration": ("acc.x", "acc.y", "acc.z"),
    "estDistance": ("id", "distance"),
    "estPose": tuple(f"locSrv.{k}" for k in ("x", "y", "z", "qx", "qy", "qz", "qw")),
    "estTOF": ("range.zrange",),
    "estFlow": ("motion.deltaX", "motion.deltaY"),
    "estBarometer": ("baro.asl",),
}


def _event(log: UsdLog, name: str, variables: tuple[str, ...]) -> np.ndarray:
    """The records of one required event, checked for variables and time order."""
    records = log.events.get(name)
    if records is None:
        raise UtilImportError(
            f"the log has no event {name!r}; a UTIL TWR log declares {sorted(_REQUIRED_EVENTS)} "
            f"(this one: {sorted(log.events)})"
        )
    missing = [v for v in variables if v not in records.dtype.names]
    if missing:
        raise UtilImportError(
            f"event {name!r} lacks variables {missing}; expected {list(variables)}, "
            f"found {list(records.dtype.names[1:])}"
        )
    steps = np.diff(records["timestamp_us"].astype(np.int64))
    if (steps <= 0).any():
        i = int(np.argmax(steps <= 0))
        t_us = records["timestamp_us"]
        raise UtilImportError(
            f"event {name!r}: record {i + 1} has timestamp {int(t_us[i + 1])} µs, "
            f"not after record {i} at {int(t_us[i])} µs; "
            "timestamps must be strictly increasing"
        )
    return records


def _pair_imu(t_gyro: np.ndarray, t_acc: np.ndarray) -> np.ndarray:
    """Index of the accelerometer partner of each gyro sample, -1 where there is none."""
    if len(t_acc) == 0:
        return np.full(len(t_gyro), -1, dtype=np.int64)
    first_after = np.searchsorted(t_acc, t_gyro, side="left")
    candidate = np.minimum(first_after, len(t_acc) - 1)
    next_gyro = np.append(t_gyro[1:], np.iinfo(np.int64).max)
    lag = t_acc[candidate] - t_gyro
    ok = (first_after < len(t_acc)) & (t_acc[candidate] < next_gyro) & (lag <= MAX_IMU_PAIR_LAG_US)
    return np.where(ok, candidate, -1)


def import_util(
    raw_log: str | Path,
    anchors_survey: str | Path,
    out_dir: str | Path,
    *,
    log_name: str | None = None,
    overwrite: bool = False,
) -> dict[str, int]:
    """Import one UTIL TWR µSD log and the anchor survey into ``out_dir``.

    Writes ``out_dir/<log_name>/{imu,uwb_range,mocap,tof,flow,baro}.csv.gz`` and
    ``out_dir/anchors.csv`` (see the module docstring). Everything is decoded first and
    written into a temporary folder inside ``out_dir`` that is then renamed into place,
    so a failure leaves ``out_dir`` as it was.

    Args:
        raw_log: the binary µSD log (e.g. ``twr-obs-log1.bin``).
        anchors_survey: the survey file (``anchor_0607.txt``).
        out_dir: the dataset folder (usually ``<SWARMLOC_DATA>/util-twr``); created if absent.
        log_name: folder name for this log; default: the file name of ``raw_log``
            without its suffix.
        overwrite: replace an existing ``out_dir/<log_name>`` folder.

    Returns:
        Data rows per written file, keyed by the path relative to ``out_dir``
        (e.g. ``{"log00/imu.csv.gz": 73722, ..., "anchors.csv": 8}``).

    Raises:
        UsdLogError: the raw log is corrupt, truncated or not a µSD event log.
        UtilImportError: the log or survey does not fit the UTIL TWR layout, or
            ``log_name`` is not a plain folder name.
        FileExistsError: ``out_dir/<log_name>`` exists and ``overwrite`` is false.
    """
    raw_log, out_dir = Path(raw_log), Path(out_dir)
    log_name = raw_log.stem if log_name is None else log_name
    if not _LOG_NAME.fullmatch(log_name) or log_name == "anchors.csv":
        raise UtilImportError(
            f"log name {log_name!r} is not a plain folder name (letters, digits, '.', '_', '-', "
            "not starting with '.'); pass log_name"
        )
    target = out_dir / log_name
    if target.exists() and not overwrite:
        raise FileExistsError(f"{target} already exists; pass overwrite=True to replace it")

    anchors = read_anchor_survey(anchors_survey)
    tables = util_tables(read_usd_log(raw_log), n_anchors=len(anchors))
    anchor_text = "anchor_id,x,y,z\n" + "".join(
        f"{i},{x:.4f},{y:.4f},{z:.4f}\n" for i, (x, y, z) in enumerate(anchors.tolist())
    )

    install_folder(out_dir, log_name, tables, {"anchors.csv": anchor_text}, overwrite)
    counts = {f"{log_name}/{table.file_name}": table.n_rows for table in tables}
    counts["anchors.csv"] = len(anchors)
    return counts


def install_folder(out_dir: Path, name: str, tables: list[Table], files: dict[str, str], overwrite: bool) -> None:
    """Write ``tables`` (gzip) as the folder ``out_dir/name`` and ``files`` (ASCII text) beside it, atomically.

    Everything is written into a staging folder inside ``out_dir`` first and renamed into
    place, so a failed import leaves no half-written folder; an existing folder is replaced
    only with ``overwrite`` and put back if the rename fails.

    Raises:
        FileExistsError: ``out_dir/name`` appeared during the import and ``overwrite`` is false.
    """
    target = out_dir / name
    out_dir.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{name}.", suffix=".importing", dir=out_dir))
    try:
        (staging / name).mkdir()
        for table in tables:
            _write_gzip_text(staging / name / table.file_name, table.to_text())
        for file_name, text in files.items():
            (staging / file_name).write_text(text, encoding="ascii")
        replaced = None
        if target.exists():
            if not overwrite:
                raise FileExistsError(f"{target} appeared during the import; not replacing it")
            replaced = staging / "replaced"
            os.rename(target, replaced)
        try:
            os.rename(staging / name, target)
        except BaseException:
            if replaced is not None:  # put the previous import back
                os.rename(replaced, target)
            raise
        for file_name in files:
            os.replace(staging / file_name, out_dir / file_name)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def _write_gzip_text(path: Path, text: str) -> None:
    # mtime=0 and no stored file name: the same input gives the same bytes.
    with open(path, "wb") as raw, gzip.GzipFile(
        filename="", mode="wb", fileobj=raw, compresslevel=9, mtime=0
    ) as gz:
        gz.write(text.encode("ascii"))


def data_root(data_dir: str | Path | None = None) -> tuple[Path, str]:
    """The folder that holds the imported data sets, and where that choice came from.

    In order: ``data_dir``; else the environment variable ``SWARMLOC_DATA``; else
    ``../shared/data`` next to this checkout (a convenience for the project's own tests).

    Returns:
        ``(folder, origin)``: origin names the rule that chose it (for error messages).
    """
    if data_dir is not None:
        return Path(data_dir), "the data_dir argument"
    if os.environ.get(DATA_ENV_VAR):
        return Path(os.environ[DATA_ENV_VAR]), f"${DATA_ENV_VAR}"
    repo_root = Path(__file__).resolve().parents[2]
    return repo_root.parent / "shared" / "data", "the default next to the checkout"


def find_util_data(data_dir: str | Path | None = None) -> Path:
    """Locate the imported UTIL TWR dataset folder (``.../util-twr``).

    The data folder (the one that contains ``util-twr/``) is, in order: ``data_dir``;
    else the environment variable ``SWARMLOC_DATA``; else ``../shared/data`` next to this
    checkout (a convenience for the project's own tests).

    Args:
        data_dir: the folder that contains ``util-twr/``.

    Returns:
        The ``util-twr`` folder.

    Raises:
        FileNotFoundError: the folder does not exist; the message says where the data
            comes from and which command imports it.
    """
    return dataset_folder(data_dir, DATASET_DIR, "UTIL TWR", UTIL_SOURCE, IMPORT_COMMAND)


def dataset_folder(data_dir: str | Path | None, dataset_dir: str, name: str, source: str, import_command: str) -> Path:
    """The folder ``dataset_dir`` of an imported data set inside the data folder (``data_root``).

    Raises:
        FileNotFoundError: the folder does not exist; the message names the data set (``name``),
            where the data comes from (``source``) and the command that imports it.
    """
    base, origin = data_root(data_dir)
    folder = base / dataset_dir
    if not folder.is_dir():
        raise FileNotFoundError(
            f"{name} data not found: {folder} (from {origin}) is not a folder.\n"
            f"The data comes from {source}\n"
            f"Import each raw log with `{import_command}` using DIR = <data>/{dataset_dir}, "
            f"then set {DATA_ENV_VAR}=<data>."
        )
    return folder


def main_import_util(raw_log: str | Path, anchors: str | Path, out: str | Path) -> dict[str, int]:
    """Run ``import_util`` for a command line and print a short summary.

    Args:
        raw_log: the binary µSD log.
        anchors: the anchor survey file.
        out: the dataset folder that receives ``<log>/`` and ``anchors.csv``.

    Returns:
        Data rows per written file (as ``import_util``); errors propagate to the caller.
    """
    counts = import_util(raw_log, anchors, out)
    print(f"imported {raw_log} into {out}:")
    width = max(map(len, counts))
    for name, rows in counts.items():
        print(f"  {name:<{width}}  {rows:>7} rows")
    print("UTIL data has no license: internal benchmarking only; cite Zhao et al., IJRR 2024.")
    return counts
