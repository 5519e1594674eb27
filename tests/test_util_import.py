"""Crazyflie µSD log reader and UTIL TWR importer.

Synthetic logs (built here byte by byte) test the format, the errors and the import
rules everywhere; the real UTIL logs, when the data folder is present, must reproduce
the shipped CSVs line for line. No dataset file may be tracked by git.
"""

from __future__ import annotations

import gzip
import hashlib
import shutil
import struct
import subprocess
import zlib
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest

from swarmloc.envs.recorded import util_import
from swarmloc.envs.recorded.cfusdlog import (
    UsdLogChecksumError,
    UsdLogError,
    decode_usd_log,
    read_usd_log,
)
from swarmloc.envs.recorded.util_import import (
    UtilImportError,
    find_util_data,
    import_util,
    read_anchor_survey,
)

REPO_ROOT = Path(__file__).resolve().parents[1]
LOGS = ("twr-obs-log1", "log00")
RAW_FILES = ("twr-obs-log1.bin", "log00.bin", "anchor_0607.txt")
CSV_FILES = ("imu", "uwb_range", "mocap", "tof", "flow", "baro")
# file names the dataset uses; none of them may be tracked by git
DATASET_NAMES = {*RAW_FILES, *LOGS, "anchors.csv", *(f"{name}.csv.gz" for name in CSV_FILES)}


# --------------------------------------------------------------------------- helpers


def encode_usd_log(
    version: int,
    event_types: list[tuple[int, str, list[tuple[str, str]]]],
    records: list[tuple[int, int, tuple]],
) -> bytes:
    """Write a µSD event log: header, records ``(event id, timestamp, values)``, CRC-32."""
    out = bytearray(struct.pack("<BHH", 0xBC, version, len(event_types)))
    payload_format = {}
    for event_id, name, variables in event_types:
        out += struct.pack("<H", event_id) + name.encode() + b"\0"
        out += struct.pack("<H", len(variables))
        for var_name, code in variables:
            out += f"{var_name}({code})".encode() + b"\0"
        payload_format[event_id] = "<" + "".join(code for _, code in variables)
    header_format = {1: "<HI", 2: "<HQ"}[version]
    for event_id, timestamp, values in records:
        out += struct.pack(header_format, event_id, timestamp)
        out += struct.pack(payload_format[event_id], *values)
    out += struct.pack("<I", zlib.crc32(out))
    return bytes(out)


UTIL_EVENTS = [
    (5, "estGyroscope", [("gyro.x", "f"), ("gyro.y", "f"), ("gyro.z", "f")]),
    (1, "estAcceleration", [("acc.x", "f"), ("acc.y", "f"), ("acc.z", "f")]),
    (3, "estDistance", [("id", "B"), ("distance", "f")]),
    (6, "estPose", [(f"locSrv.{k}", "f") for k in ("x", "y", "z", "qx", "qy", "qz", "qw")]),
    (10, "estTOF", [("range.zrange", "H")]),
    (4, "estFlow", [("motion.deltaX", "h"), ("motion.deltaY", "h")]),
    (2, "estBarometer", [("baro.asl", "f")]),
    (11, "estYawError", [("yawError", "f")]),
]


def synthetic_util_log(anchor_id: int = 2) -> bytes:
    """A tiny UTIL-like v2 log: 4 gyro samples, the third without accelerometer partner."""
    base = 5_000_000
    records = []
    for k in range(4):
        records.append((5, base + 1000 * k, (90.0, -180.0, 0.0)))
        if k != 2:
            records.append((1, base + 1000 * k + 15, (1.0, 0.0, -0.5)))
    records += [
        (3, base + 300, (anchor_id, 4.25)),
        (6, base + 400, (1.0, -2.0, 0.5, 0.0, 0.0, 0.0, 1.0)),
        (10, base + 500, (85,)),
        (4, base + 600, (-3, 7)),
        (2, base + 700, (190.5,)),
    ]
    return encode_usd_log(2, UTIL_EVENTS, records)


SURVEY = """uwbDatasetFrame1,0.0,0.0,0.0
anchor0_1, -1.0,-1.0,0.1
""" + "".join(f"anchorAnt{i}, {i}.5,-{i}.25,0.1{i}\n" for i in range(8))


@pytest.fixture()
def synthetic_inputs(tmp_path: Path) -> tuple[Path, Path]:
    raw = tmp_path / "inputs" / "synth.bin"
    raw.parent.mkdir()
    raw.write_bytes(synthetic_util_log())
    survey = tmp_path / "inputs" / "survey.txt"
    survey.write_text(SURVEY)
    return raw, survey


def csv_lines(path: Path) -> list[str]:
    opener = gzip.open if path.suffix == ".gz" else open
    with opener(path, "rt") as f:
        return f.read().splitlines()


# --------------------------------------------------------------------------- reader


def test_v2_roundtrip() -> None:
    variables = [("a.b", "B"), ("c", "h"), ("d", "I"), ("e", "f"), ("g", "e")]
    events = [(7, "estX", variables), (0, "empty", [])]
    data = encode_usd_log(2, events, [(7, 2**40 + 3, (255, -2, 2**32 - 1, 1.5, -0.25)), (0, 9, ())])
    log = decode_usd_log(data)
    assert log.version == 2
    assert [et.name for et in log.event_types] == ["estX", "empty"]
    x = log.events["estX"]
    assert x.dtype.names == ("timestamp_us", "a.b", "c", "d", "e", "g")
    assert x["timestamp_us"].tolist() == [2**40 + 3]
    assert [x[name][0] for name, _ in variables] == [255, -2, 2**32 - 1, 1.5, -0.25]
    assert log.events["empty"]["timestamp_us"].tolist() == [9]


def test_v1_timestamps_are_milliseconds() -> None:
    events = [(1, "tick", [("v", "i")])]
    data = encode_usd_log(1, events, [(1, 1500, (-7,)), (1, 1501, (8,))])
    log = decode_usd_log(data)
    assert log.version == 1
    assert log.events["tick"]["timestamp_us"].tolist() == [1_500_000, 1_501_000]
    assert log.events["tick"]["v"].tolist() == [-7, 8]


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda d: b"\xbd" + d[1:], "offset 0: magic byte is 0xBD, expected 0xBC"),
        (lambda d: d[:1] + struct.pack("<H", 3) + d[3:], "format version 3 is not supported"),
        (lambda d: d[:5], "needs at least 9"),
        (lambda d: d[:-4] + bytes([d[-4] ^ 1]) + d[-3:], "CRC-32 mismatch"),
    ],
)
def test_malformed_logs_name_the_problem(mutate, message: str) -> None:
    data = encode_usd_log(2, [(1, "e", [("v", "f")])], [(1, 10, (1.0,))])
    with pytest.raises(UsdLogError, match=message):
        decode_usd_log(mutate(data))


def test_header_and_record_errors_name_the_offset() -> None:
    bad_type = encode_usd_log(2, [(1, "e", [("v", "q")])], [])
    expected = r"offset 11: variable 'v' has type 'q'; allowed types: BbHhIife"
    with pytest.raises(UsdLogError, match=expected):
        decode_usd_log(bad_type)
    events = [(1, "e", [("v", "B")]), (2, "f", [])]
    unknown_id = bytearray(encode_usd_log(2, events, [(1, 5, (1,)), (2, 6, ())]))
    first_record = len(unknown_id) - 4 - 11 - 10
    unknown_id[first_record] = 9
    expected = rf"offset {first_record}: record has event id 9; the header declares ids \[1, 2\]"
    with pytest.raises(UsdLogError, match=expected):
        decode_usd_log(bytes(unknown_id), check_crc=False)
    # a record cut short, with a trailer re-computed so that only the structure is wrong
    good = encode_usd_log(2, [(1, "e", [("v", "f")])], [(1, 5, (1.0,)), (1, 6, (2.0,))])
    cut = good[:-4 - 2]
    cut += struct.pack("<I", zlib.crc32(cut))
    with pytest.raises(UsdLogError, match=r"record of event id 1 needs 14 bytes .* truncated"):
        decode_usd_log(cut)


def test_checksum_error_is_a_value_error() -> None:
    assert issubclass(UsdLogChecksumError, UsdLogError)
    assert issubclass(UsdLogError, ValueError)


# --------------------------------------------------------------------------- importer (synthetic)


def test_import_synthetic_applies_the_rules(synthetic_inputs, tmp_path: Path) -> None:
    raw, survey = synthetic_inputs
    out = tmp_path / "util-twr"
    counts = import_util(raw, survey, out)
    assert counts == {
        "synth/imu.csv.gz": 3,  # the gyro sample without accelerometer partner is dropped
        "synth/uwb_range.csv.gz": 1,
        "synth/mocap.csv.gz": 1,
        "synth/tof.csv.gz": 1,
        "synth/flow.csv.gz": 1,
        "synth/baro.csv.gz": 1,
        "anchors.csv": 8,
    }
    assert sorted(p.name for p in out.iterdir()) == ["anchors.csv", "synth"]
    assert csv_lines(out / "synth" / "imu.csv.gz") == [
        "t,ax,ay,az,gx,gy,gz",
        "0.000000,9.810000,0.000000,-4.905000,1.570796,-3.141593,0.000000",
        "0.001000,9.810000,0.000000,-4.905000,1.570796,-3.141593,0.000000",
        "0.003000,9.810000,0.000000,-4.905000,1.570796,-3.141593,0.000000",
    ]
    assert csv_lines(out / "synth" / "uwb_range.csv.gz") == [
        "t,anchor_id,range_m",
        "0.000300,2,4.250000",
    ]
    assert csv_lines(out / "synth" / "mocap.csv.gz")[1] == (
        "0.000400,1.000000,-2.000000,0.500000,0.0000000,0.0000000,0.0000000,1.0000000"
    )
    assert csv_lines(out / "synth" / "tof.csv.gz") == ["t,range_m", "0.000500,0.085"]
    assert csv_lines(out / "synth" / "flow.csv.gz") == ["t,delta_x_px,delta_y_px", "0.000600,-3,7"]
    assert csv_lines(out / "synth" / "baro.csv.gz") == ["t,asl_m", "0.000700,190.5000"]
    assert csv_lines(out / "anchors.csv")[:3] == [
        "anchor_id,x,y,z",
        "0,0.5000,-0.2500,0.1000",
        "1,1.5000,-1.2500,0.1100",
    ]


def test_import_is_atomic_on_failure(synthetic_inputs, tmp_path: Path, monkeypatch) -> None:
    raw, survey = synthetic_inputs
    out = tmp_path / "util-twr"
    out.mkdir()
    (out / "keep.txt").write_text("untouched")
    calls = []

    def failing_write(path: Path, text: str) -> None:
        calls.append(path)
        if len(calls) == 3:
            raise OSError("disk full (simulated)")
        path.write_text(text)

    monkeypatch.setattr(util_import, "_write_gzip_text", failing_write)
    with pytest.raises(OSError, match="simulated"):
        import_util(raw, survey, out)
    assert [p.name for p in out.iterdir()] == ["keep.txt"]

    raw.write_bytes(raw.read_bytes()[:-1])
    with pytest.raises(UsdLogChecksumError):
        import_util(raw, survey, out)
    assert [p.name for p in out.iterdir()] == ["keep.txt"]


def test_import_refuses_to_overwrite_unless_asked(synthetic_inputs, tmp_path: Path) -> None:
    raw, survey = synthetic_inputs
    out = tmp_path / "util-twr"
    import_util(raw, survey, out)
    with pytest.raises(FileExistsError, match="overwrite=True"):
        import_util(raw, survey, out)
    import_util(raw, survey, out, overwrite=True)
    assert sorted(p.name for p in out.iterdir()) == ["anchors.csv", "synth"]
    assert len(list((out / "synth").iterdir())) == 6


def test_import_rejects_unsurveyed_anchor_and_bad_survey(synthetic_inputs, tmp_path: Path) -> None:
    raw, survey = synthetic_inputs
    raw.write_bytes(synthetic_util_log(anchor_id=8))
    with pytest.raises(UtilImportError, match=r"anchor id 8; the survey has anchors 0..7"):
        import_util(raw, survey, tmp_path / "out")
    survey.write_text("anchorAnt0, 1.0, 2.0\n")
    expected = r"survey.txt:1: anchor row .* is not 'anchorAnt<i>, x, y, z'"
    with pytest.raises(UtilImportError, match=expected):
        read_anchor_survey(survey)
    survey.write_text("anchorAnt1, 1.0, 2.0, 3.0\n")
    with pytest.raises(UtilImportError, match=r"anchor ids \[1\] must be exactly 0..A-1"):
        read_anchor_survey(survey)
    assert not (tmp_path / "out").exists()


def test_import_rejects_a_log_without_the_util_events(tmp_path: Path) -> None:
    raw = tmp_path / "other.bin"
    events = [(1, "fixedFrequency", [("pm.vbat", "f")])]
    raw.write_bytes(encode_usd_log(2, events, [(1, 5, (3.7,))]))
    survey = tmp_path / "survey.txt"
    survey.write_text(SURVEY)
    with pytest.raises(UtilImportError, match="the log has no event 'estGyroscope'"):
        import_util(raw, survey, tmp_path / "out")


# --------------------------------------------------------------------------- data folder lookup


def test_find_util_data_order_and_message(tmp_path: Path, monkeypatch) -> None:
    explicit, from_env = tmp_path / "a", tmp_path / "b"
    (explicit / "util-twr").mkdir(parents=True)
    (from_env / "util-twr").mkdir(parents=True)
    monkeypatch.setenv("SWARMLOC_DATA", str(from_env))
    assert find_util_data(explicit) == explicit / "util-twr"
    assert find_util_data() == from_env / "util-twr"
    monkeypatch.setenv("SWARMLOC_DATA", str(tmp_path / "missing"))
    with pytest.raises(FileNotFoundError) as error:
        find_util_data()
    message = str(error.value)
    for needle in (
        "SWARMLOC_DATA",
        str(tmp_path / "missing" / "util-twr"),
        "utiasDSL/util-uwb-dataset",
        "39efa0739607e39203a764f492e7ac91089a6e73",
        "705abe8e12845b7b9433a1a579b7b9eead68437c",
        "2_data/survey-results/anchor_0607.txt",
        "swarmloc data import-util RAW_LOG --anchors SURVEY --out DIR",
    ):
        assert needle in message


# --------------------------------------------------------------------------- real UTIL logs


@pytest.fixture(scope="module")
def util_dir() -> Path:
    try:
        folder = find_util_data()
    except FileNotFoundError as error:
        pytest.skip(f"{str(error).splitlines()[0]} Set SWARMLOC_DATA to the imported data.")
    missing = [name for name in RAW_FILES if not (folder / "raw" / name).is_file()]
    if missing:
        pytest.skip(f"UTIL TWR raw logs absent from {folder / 'raw'}: {missing}")
    return folder


@pytest.fixture(scope="module")
def imported(util_dir: Path, tmp_path_factory) -> tuple[Path, dict[str, int]]:
    out = tmp_path_factory.mktemp("import") / "util-twr"
    counts: dict[str, int] = {}
    for log in LOGS:
        raw = util_dir / "raw"
        counts |= import_util(raw / f"{log}.bin", raw / "anchor_0607.txt", out)
    return out, counts


@pytest.mark.parametrize("log", LOGS)
@pytest.mark.parametrize("stream", CSV_FILES)
def test_real_logs_reproduce_shipped_csvs(util_dir: Path, imported, log: str, stream: str) -> None:
    out, counts = imported
    name = f"{log}/{stream}.csv.gz"
    ref_lines, our_lines = csv_lines(util_dir / name), csv_lines(out / name)
    assert counts[name] == len(ref_lines) - 1
    assert our_lines[0] == ref_lines[0]
    ref = np.loadtxt(util_dir / name, delimiter=",", skiprows=1, ndmin=2)
    ours = np.loadtxt(out / name, delimiter=",", skiprows=1, ndmin=2)
    assert ours.shape == ref.shape
    # equal to the printed precision: half a unit of each column's last printed digit
    decimals = [len(field.partition(".")[2]) for field in ref_lines[1].split(",")]
    tolerance = 0.5 * 10.0 ** -np.array(decimals, dtype=float) + 1e-12
    worst = np.abs(ours - ref).max(axis=0) if len(ref) else np.zeros(len(decimals))
    assert (worst <= tolerance).all(), f"max |ours - shipped| {worst}, allowed {tolerance}"
    assert our_lines == ref_lines


def test_real_anchors_reproduce_shipped_csv(util_dir: Path, imported) -> None:
    out, counts = imported
    assert counts["anchors.csv"] == 8
    assert csv_lines(out / "anchors.csv") == csv_lines(util_dir / "anchors.csv")


@pytest.mark.parametrize(
    ("damage", "what"),
    [
        (lambda d: d[: len(d) // 2], "truncated"),
        (lambda d: d[:1000] + bytes([d[1000] ^ 0x10]) + d[1001:], "flipped"),
    ],
)
def test_damaged_real_log_fails_on_crc(util_dir: Path, tmp_path: Path, damage, what: str) -> None:
    damaged = tmp_path / f"{what}.bin"
    damaged.write_bytes(damage((util_dir / "raw" / "log00.bin").read_bytes()))
    expected = r"CRC-32 mismatch: trailer at offset \d+ .* corrupt or truncated"
    with pytest.raises(UsdLogChecksumError, match=expected):
        read_usd_log(damaged)
    with pytest.raises(UsdLogChecksumError):
        import_util(damaged, util_dir / "raw" / "anchor_0607.txt", tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_truncated_real_log_without_crc_check_names_the_offset(util_dir: Path) -> None:
    data = (util_dir / "raw" / "log00.bin").read_bytes()
    # (a cut that happens to end on a record boundary is only caught by the CRC)
    with pytest.raises(UsdLogError, match=r"offset 4042502: record of event id 1 needs 22 bytes"):
        decode_usd_log(data[:-1003], check_crc=False)


# --------------------------------------------------------------------------- licensing


def test_no_dataset_file_is_tracked_by_git() -> None:
    if shutil.which("git") is None:
        pytest.skip("git is not installed")
    listing = subprocess.run(
        ["git", "-C", str(REPO_ROOT), "ls-files", "-z"], capture_output=True, check=False
    )
    if listing.returncode != 0:
        pytest.skip(f"{REPO_ROOT} is not a git checkout")
    tracked = [REPO_ROOT / p for p in listing.stdout.decode().split("\0") if p]
    assert tracked, "git ls-files listed nothing"
    named_like_data = [str(p.relative_to(REPO_ROOT)) for p in tracked if p.name in DATASET_NAMES]
    assert not named_like_data, f"dataset files must not be committed: {named_like_data}"

    shared = REPO_ROOT.parent / "shared" / "data"
    if not shared.is_dir():
        return
    data_hashes: dict[int, set[str]] = defaultdict(set)  # size -> sha256 of shared files
    for p in shared.rglob("*"):
        if p.is_file():
            data_hashes[p.stat().st_size].add(hashlib.sha256(p.read_bytes()).hexdigest())
    copies = [
        str(p.relative_to(REPO_ROOT))
        for p in tracked
        if p.is_file()
        and p.stat().st_size in data_hashes
        and hashlib.sha256(p.read_bytes()).hexdigest() in data_hashes[p.stat().st_size]
    ]
    assert not copies, f"these tracked files are copies of ../shared/data files: {copies}"
