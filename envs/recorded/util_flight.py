"""The UTIL TWR flight resampled onto filter steps: truth, IMU input, ranges, fault labels.

Everything a replayed episode needs is computed once per (log, window, dt, calibration)
and cached; the world (``replay.RecordedWorld``) only indexes it. The rules, each a
documented modelling choice (the dataset README in ``<data>/util-twr`` has the numbers):

* **Steps.** Step k is at log time ``t_k = start + k·dt`` (k = 0 … T); step k's
  measurements are what arrived in (t_{k−1}, t_k].
* **IMU input** (the estimate path: gyro + accelerometer only, no mocap). An ``imufusion``
  AHRS (ENU, gain 0.5, 2000 °/s gyro range, 10° acceleration rejection) runs over every
  IMU sample from the first of the log, so it has converged on the ground before take-off.
  Its heading starts at 0: there is no magnetometer and the mocap attitude is truth, so the
  body x axis is taken as the world x axis at power-on (in twr-obs-log1 the mocap says the
  Crazyflie sat at 7° yaw; that offset stays in the IMU input as a real heading error).
  Each specific-force sample is rotated into the world frame and gravity (9.81 m/s², the
  constant the dataset uses to convert g) is removed; the step's input is the mean over
  the samples in (t_{k−1}, t_k] (the last value is held over an interval without samples).
* **Ranges.** Anchor a's channel is valid at step k when a range of a arrived in
  (t_{k−1}, t_k]; the last one is used. With a calibration log, its per-anchor bias is
  subtracted: the mean of ``range − ‖p_mocap − anchor‖`` over all of that log's ranges of
  the anchor (mocap linearly interpolated, no lever arm, no time shift, as in the README).
  An anchor without ranges in the calibration log (anchors 2 and 5 in ``log00``) gets the
  median of the other anchors' biases.
* **Truth.** Mocap position linearly interpolated to t_k; velocity the central difference
  of that interpolant over ±25 ms (the mocap is quantised to 1 mm and repeats ~7 % of its
  poses, so a shorter span is noise).
* **Fault labels** (metrics and the privileged oracle only). A range whose residual
  against the interpolated truth at its own arrival time deviates from the anchor's median
  residual over the episode by more than 3× the anchor's robust spread is a fault. The
  spread is 1.4826·MAD of the anchor's residuals over the episode, capped at the median of
  the anchors' spreads: anchor 6's slow NLOS drift (README) inflates its own MAD to 0.41 m,
  which would hide the drift itself, while a line-of-sight anchor's spread is 0.04–0.08 m.
  Centering on the anchor's own median makes the labels flag outliers and NLOS
  excursions, not calibration error, and makes them the same for every calibration
  option (including none).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

GRAVITY = 9.81  # m/s², the dataset's g → m/s² factor: a 1 g reading is exactly this
AHRS_GAIN = 0.5
AHRS_GYRO_RANGE_DPS = 2000.0
AHRS_ACC_REJECTION_DEG = 10.0
AHRS_REJECTION_TIMEOUT_S = 5.0
VELOCITY_HALF_SPAN = 0.025  # s
LABEL_SPREADS = 3.0  # a range deviating more than this many robust spreads is a fault
MAD_TO_SIGMA = 1.4826
TAKEOFF_MARGIN = 0.03  # m above the resting height that counts as airborne


@dataclass(frozen=True)
class FlightLog:
    """The streams of one imported log that replay uses (arrays read-only).

    Attributes:
        imu: ``(n, 7)`` t, specific force (3) [m/s²], angular rate (3) [rad/s].
        uwb: ``(m, 3)`` t, anchor id, range [m].
        mocap: ``(p, 8)`` t, position (3) [m], quaternion x, y, z, w.
    """

    imu: np.ndarray
    uwb: np.ndarray
    mocap: np.ndarray


@dataclass(frozen=True)
class Recording:
    """A flight on filter steps k = 0 … T (arrays read-only; row k is step k).

    Attributes:
        log: the log's name.
        t: ``(T+1,)`` log time of each step [s].
        anchors: ``(A, 3)`` surveyed anchor positions [m].
        pos, vel: ``(T+1, 3)`` truth [m], [m/s].
        imu: ``(T+1, 3)`` world-frame acceleration, gravity removed, mean over the step [m/s²].
        attitude: ``(T+1, 4)`` the AHRS quaternion (w, x, y, z) at each step.
        z: ``(T+1, A)`` range per channel after the calibration [m] (0 where not valid).
        valid: ``(T+1, A)`` a range arrived in the step.
        label: ``(T+1, A)`` fault label (valid ranges only).
        residual: ``(T+1, A)`` range after calibration − true distance [m] (0 where not valid).
        bias: ``(A,)`` calibration bias subtracted from the raw ranges (zeros without one) [m].
        spread: ``(A,)`` robust spread of each anchor's residual in the episode, as used by
            the labels (1.4826·MAD, capped at the median anchor's) [m].
    """

    log: str
    t: np.ndarray
    anchors: np.ndarray
    pos: np.ndarray
    vel: np.ndarray
    imu: np.ndarray
    attitude: np.ndarray
    z: np.ndarray
    valid: np.ndarray
    label: np.ndarray
    residual: np.ndarray
    bias: np.ndarray
    spread: np.ndarray

    @property
    def n_steps(self) -> int:
        """T, the number of filter steps after step 0."""
        return len(self.t) - 1

    def label_rate(self) -> np.ndarray:
        """``(A,)`` fraction of each anchor's valid ranges in steps 1 … T that are labelled faults."""
        valid, label = self.valid[1:], self.label[1:]
        return label.sum(axis=0) / np.maximum(valid.sum(axis=0), 1)


def _read_only(*arrays: np.ndarray) -> None:
    for a in arrays:
        a.flags.writeable = False


def read_anchors(folder: Path, file_name: str = "anchors.csv") -> np.ndarray:
    """``(A, 3)`` anchor positions from ``<folder>/<file_name>`` (rows ordered by id).

    Raises:
        FileNotFoundError: the file is missing (the message names it).
        ValueError: the ids are not 0..A-1 in order.
    """
    path = folder / file_name
    if not path.is_file():
        raise FileNotFoundError(f"{path} is missing; the data set's README says where its anchor files come from")
    table = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    ids = table[:, 0].astype(int)
    if not np.array_equal(ids, np.arange(len(ids))):
        raise ValueError(f"{path}: anchor ids {ids.tolist()} must be 0..A-1 in order")
    return np.ascontiguousarray(table[:, 1:4])


@functools.lru_cache(maxsize=4)
def read_flight_log(log_dir: Path) -> FlightLog:
    """Read the imu, uwb_range and mocap CSVs of one imported log (cached).

    Raises:
        FileNotFoundError: a CSV is missing (the message names it).
    """
    return FlightLog(*read_tables(log_dir, (("imu", 7), ("uwb_range", 3), ("mocap", 8)),
                                  "re-import the log (see the dataset README)"))


def read_tables(log_dir: Path, tables: tuple[tuple[str, int], ...], how_to_import: str) -> list[np.ndarray]:
    """Read ``<log_dir>/<name>.csv.gz`` for each ``(name, columns)`` as read-only float arrays.

    Raises:
        FileNotFoundError: a CSV is missing (the message names it and ``how_to_import``).
        ValueError: a CSV has the wrong number of columns.
    """
    arrays = []
    for name, columns in tables:
        path = log_dir / f"{name}.csv.gz"
        if not path.is_file():
            raise FileNotFoundError(f"{path} is missing; {how_to_import}")
        table = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
        if table.shape[1] != columns:
            raise ValueError(f"{path}: expected {columns} columns, found {table.shape[1]}")
        arrays.append(np.ascontiguousarray(table))
    _read_only(*arrays)
    return arrays


def interpolate_positions(mocap: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Mocap position linearly interpolated at times ``t`` → ``(len(t), 3)``."""
    return np.stack([np.interp(t, mocap[:, 0], mocap[:, 1 + d]) for d in range(3)], axis=-1)


def range_residuals(uwb: np.ndarray, mocap: np.ndarray, anchors: np.ndarray) -> np.ndarray:
    """``range − ‖p_mocap(t) − anchor‖`` of every UWB row (mocap interpolated at the range time)."""
    ids = uwb[:, 1].astype(int)
    p = interpolate_positions(mocap, uwb[:, 0])
    return uwb[:, 2] - np.linalg.norm(p - anchors[ids], axis=-1)


def calibrate_range_bias(log: FlightLog, anchors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-anchor range bias from a calibration log: mean residual against its mocap.

    Args:
        log: the calibration log (``log00``: an almost static low hover).
        anchors: ``(A, 3)`` anchor positions.

    Returns:
        ``(A,)`` bias [m] and ``(A,)`` bool, whether the anchor had ranges in the log; an
        anchor without ranges gets the median of the others' biases.

    Raises:
        ValueError: the log has no range at all.
    """
    resid = range_residuals(log.uwb, log.mocap, anchors)
    ids = log.uwb[:, 1].astype(int)
    n_a = len(anchors)
    measured = np.bincount(ids, minlength=n_a)[:n_a] > 0
    if not measured.any():
        raise ValueError("the calibration log holds no UWB range")
    bias = np.zeros(n_a)
    for a in np.nonzero(measured)[0]:
        bias[a] = resid[ids == a].mean()
    bias[~measured] = np.median(bias[measured])
    return bias, measured


def ahrs_attitude(imu: np.ndarray) -> np.ndarray:
    """Attitude (w, x, y, z), body → world ENU, of every IMU sample from gyro + accelerometer.

    An ``imufusion`` AHRS without magnetometer, heading 0 at the first sample; the sample
    period of each update is the time since the previous sample (the first uses the
    median period). No mocap enters.

    Args:
        imu: ``(n, 7)`` rows t, specific force [m/s²], angular rate [rad/s].

    Returns:
        ``(n, 4)`` unit quaternions.
    """
    import imufusion

    t = imu[:, 0]
    period = np.diff(t, prepend=t[0] - (np.median(np.diff(t)) if len(t) > 1 else 1e-3))
    gyro_dps = np.degrees(imu[:, 4:7])
    acc_g = imu[:, 1:4] / GRAVITY
    ahrs = imufusion.Ahrs()
    rate = 1.0 / float(np.median(period))
    ahrs.set_settings(imufusion.AhrsSettings(
        convention=imufusion.CONVENTION_ENU, gain=AHRS_GAIN, gyroscope_range=AHRS_GYRO_RANGE_DPS,
        acceleration_rejection=AHRS_ACC_REJECTION_DEG, magnetic_rejection=0.0,
        rejection_timeout=int(round(AHRS_REJECTION_TIMEOUT_S * rate)), sample_rate=int(round(rate))))
    q = np.empty((len(t), 4))
    for k in range(len(t)):
        ahrs.set_sample_period(float(period[k]))
        ahrs.update_no_magnetometer(gyro_dps[k], acc_g[k])
        q[k] = ahrs.get_quaternion()
    return q


def rotate_to_world(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate body vectors ``v`` ``(n, 3)`` by unit quaternions ``q`` ``(n, 4)`` (w, x, y, z)."""
    w, x, y, z = q[:, 0:1], q[:, 1:2], q[:, 2:3], q[:, 3:4]
    u = np.concatenate([x, y, z], axis=1)
    # v' = v + 2w (u × v) + 2 u × (u × v)
    uv = np.cross(u, v)
    return v + 2.0 * w * uv + 2.0 * np.cross(u, uv)


def world_acceleration(imu: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Kinematic acceleration in the world frame: R(q)·f − g·e_z, ``(n, 3)`` [m/s²]."""
    a = rotate_to_world(q, imu[:, 1:4])
    a[:, 2] -= GRAVITY
    return a


def step_means(t_samples: np.ndarray, values: np.ndarray, t_steps: np.ndarray, dt: float) -> np.ndarray:
    """Mean of ``values`` over (t_k − dt, t_k] for every step time; empty intervals hold the last mean."""
    csum = np.concatenate([np.zeros((1, values.shape[1])), np.cumsum(values, axis=0)])
    i0 = np.searchsorted(t_samples, t_steps - dt, side="right")
    i1 = np.searchsorted(t_samples, t_steps, side="right")
    count = i1 - i0
    out = (csum[i1] - csum[i0]) / np.maximum(count, 1)[:, None]
    for k in np.nonzero(count == 0)[0]:
        out[k] = out[k - 1] if k > 0 else values[max(i1[k] - 1, 0)]
    return out


def episode_times(imu: np.ndarray, mocap: np.ndarray, start: float, dt: float, n_steps: int,
                  flight: str) -> np.ndarray:
    """The ``n_steps + 1`` step times of an episode from log time ``start``, checked to lie where IMU and mocap
    both cover (one step after their first sample, for the first IMU interval).

    Raises:
        ValueError: the window does not fit in ``flight`` (named in the message).
    """
    t = start + dt * np.arange(n_steps + 1)
    lo = max(imu[0, 0], mocap[0, 0]) + dt
    hi = min(imu[-1, 0], mocap[-1, 0])
    if t[0] < lo or t[-1] > hi:
        raise ValueError(f"episode window [{t[0]:.3f}, {t[-1]:.3f}] s does not fit in {flight}, whose IMU and "
                         f"mocap cover [{lo:.3f}, {hi:.3f}] s; shorten the duration or move the start")
    return t


def airborne_window(mocap: np.ndarray, margin: float = TAKEOFF_MARGIN) -> tuple[float, float]:
    """Take-off and landing times from the truth altitude.

    Airborne means mocap z more than ``margin`` above the resting height (the median z of
    the log's first second).

    Returns:
        ``(t_takeoff, t_landing)``: the first and last mocap times that are airborne [s].

    Raises:
        ValueError: the log never leaves the ground.
    """
    t, z = mocap[:, 0], mocap[:, 3]
    rest = np.median(z[t <= t[0] + 1.0])
    air = np.nonzero(z > rest + margin)[0]
    if air.size == 0:
        raise ValueError(f"the vehicle never rises {margin} m above its resting height {rest:.3f} m")
    return float(t[air[0]]), float(t[air[-1]])


def truth_and_imu(mocap: np.ndarray, imu_samples: np.ndarray, t: np.ndarray, dt: float,
                  positions: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> tuple[np.ndarray, ...]:
    """A flight's truth and filter input on the step times ``t`` (``(T+1,)``), as every recording builds them.

    Args:
        mocap: the mocap rows (time first).
        imu_samples: the IMU rows (time, gyro, accelerometer).
        t: the step times [s].
        dt: the filter step [s].
        positions: ``positions(mocap, times)`` → the true positions ``(len(times), 3)`` (the mocap
            origin, or a tag at a lever arm from it).

    Returns:
        ``pos``, ``vel`` (central difference over ±``VELOCITY_HALF_SPAN``), ``imu`` (the AHRS world
        acceleration averaged over each step, ``step_means``) and ``attitude`` (the AHRS quaternion
        of the last IMU sample at or before each step), each ``(T+1, ·)``.
    """
    pos = positions(mocap, t)
    # v(t) ≈ (p(t + h) − p(t − h)) / 2h
    h = VELOCITY_HALF_SPAN
    vel = (positions(mocap, t + h) - positions(mocap, t - h)) / (2.0 * h)
    q_samples = ahrs_attitude(imu_samples)
    imu = step_means(imu_samples[:, 0], world_acceleration(imu_samples, q_samples), t, dt)
    attitude = q_samples[np.maximum(np.searchsorted(imu_samples[:, 0], t, side="right") - 1, 0)]
    return pos, vel, imu, attitude


@functools.lru_cache(maxsize=4)
def load_recording(folder: Path, log: str, start: float, n_steps: int, dt: float,
                   calibration: str | None, anchors_file: str = "anchors.csv") -> Recording:
    """Resample one imported log onto filter steps (cached per argument tuple).

    Args:
        folder: the dataset folder (``.../util-twr``: ``anchors.csv`` and one folder per log).
        log: the flight log, e.g. ``"twr-obs-log1"``.
        start: log time of step 0 [s].
        n_steps: T, the number of steps after step 0.
        dt: filter step [s].
        calibration: the log that calibrates the range bias, or None for raw ranges.
        anchors_file: the anchor file in ``folder`` (``anchors.csv``: the raw total-station
            survey; ``anchors_vicon.csv``: the dataset's own conversion to the Vicon frame).

    Returns:
        The ``Recording`` (see the module docstring for every rule).

    Raises:
        FileNotFoundError: the log or calibration folder is missing.
        ValueError: the window does not fit inside the log's IMU and mocap, or a range
            names an anchor that is not surveyed.
    """
    anchors = read_anchors(folder, anchors_file)
    data = read_flight_log(_log_dir(folder, log))
    t = episode_times(data.imu, data.mocap, start, dt, n_steps, f"log {log!r}")
    ids = data.uwb[:, 1].astype(int)
    if (ids < 0).any() or (ids >= len(anchors)).any():
        raise ValueError(f"log {log!r} has ranges of anchor ids {sorted(set(ids.tolist()))}; "
                         f"anchors.csv surveys 0..{len(anchors) - 1}")
    n_a = len(anchors)

    # ---- truth, and IMU → world acceleration (gyro + accelerometer only)
    pos, vel, imu, attitude = truth_and_imu(data.mocap, data.imu, t, dt, interpolate_positions)

    # ---- ranges: the last range of each anchor in (t_{k−1}, t_k]
    if calibration is None:
        bias = np.zeros(n_a)
    else:
        bias, _ = calibrate_range_bias(read_flight_log(_log_dir(folder, calibration)), anchors)
    step = np.ceil((data.uwb[:, 0] - start) / dt - 1e-9).astype(np.int64)
    keep = (step >= 1) & (step <= n_steps)
    z = np.zeros((n_steps + 1, n_a))
    valid = np.zeros((n_steps + 1, n_a), dtype=bool)
    residual = np.zeros((n_steps + 1, n_a))
    resid_raw = range_residuals(data.uwb, data.mocap, anchors)
    rows = np.nonzero(keep)[0]
    # several ranges of one anchor in one step: keep the last (rows are in time order)
    key = step[rows] * n_a + ids[rows]
    _, last_from_end = np.unique(key[::-1], return_index=True)
    rows = rows[len(rows) - 1 - last_from_end]
    z[step[rows], ids[rows]] = data.uwb[rows, 2] - bias[ids[rows]]
    residual[step[rows], ids[rows]] = resid_raw[rows] - bias[ids[rows]]
    valid[step[rows], ids[rows]] = True

    # ---- fault labels: deviation from the anchor's own median beyond 3 robust spreads,
    #      the spread capped at the median anchor's (a drifting NLOS anchor must not hide its drift)
    centre = np.zeros(n_a)
    spread = np.zeros(n_a)
    seen = np.zeros(n_a, dtype=bool)
    for a in range(n_a):
        e = residual[1:, a][valid[1:, a]]
        if e.size:
            seen[a] = True
            centre[a] = np.median(e)
            spread[a] = MAD_TO_SIGMA * np.median(np.abs(e - centre[a]))
    if seen.any():
        spread[seen] = np.minimum(spread[seen], np.median(spread[seen]))
    label = valid & (np.abs(residual - centre) > LABEL_SPREADS * spread)

    rec = Recording(log=log, t=t, anchors=anchors, pos=pos, vel=vel, imu=imu, attitude=attitude, z=z, valid=valid,
                    label=label, residual=residual, bias=bias, spread=spread)
    _read_only(rec.t, rec.anchors, rec.pos, rec.vel, rec.imu, rec.attitude, rec.z, rec.valid, rec.label,
               rec.residual, rec.bias, rec.spread)
    return rec


def _log_dir(folder: Path, log: str) -> Path:
    path = folder / log
    if not path.is_dir():
        found = sorted(p.name for p in folder.iterdir() if p.is_dir() and not p.name.startswith("."))
        raise FileNotFoundError(f"log {log!r} not found in {folder} (found: {found}); import it with "
                                "`swarmloc data import-util RAW_LOG --anchors SURVEY --out DIR`")
    return path


__all__ = [
    "FlightLog",
    "GRAVITY",
    "Recording",
    "ahrs_attitude",
    "airborne_window",
    "calibrate_range_bias",
    "episode_times",
    "interpolate_positions",
    "load_recording",
    "range_residuals",
    "read_anchors",
    "read_flight_log",
    "rotate_to_world",
    "truth_and_imu",
    "world_acceleration",
]
