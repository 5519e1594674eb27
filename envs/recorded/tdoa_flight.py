"""A UTIL TDOA flight resampled onto filter steps, with the staged README's filtering rules.

The rules turn an imported flight (``tdoa_import``: ``tdoa``, ``mocap``, ``imu`` CSVs and the
constellation's ``anchors_<c>.csv``) into what a replayed episode reads. Each is explicit
here and counted where it drops something (``TdoaRowCounts``); the numbers behind them are
in the dataset README (``<data>/util-tdoa/README.md``):

* **Impossible values are dropped.** A range difference larger than the distance between
  its two anchors, |tdoa| > ‖a_i − a_j‖, cannot be measured by any position (triangle
  inequality); the logs hold 0–108 of them per flight (up to 270 m). They are dropped
  before anything else and counted (``impossible``). The test needs no truth.
* **The on-the-floor segments are not replayed.** While the Crazyflie rests on the floor
  the c0425/c0426 range differences are metres off (README, anomaly 1). A task's episode
  is the airborne window: from the first to the last mocap sample above
  ``AIRBORNE_ALTITUDE`` (0.3 m, the README's rule) — the spec's ``start`` and ``duration``
  hold it, and ``airborne_window`` recomputes it from the truth altitude (tests hold the
  two equal). Rows outside it are counted (``outside``).
* **Channels.** A task's channels are anchor pairs (``Sensors.tdoa.pairs``). A row of pair
  (i, j) feeds channel (i, j); a row of (j, i) feeds channel (i, j) negated (TDOA3 logs
  both orders of a pair: d_i − d_j = −(d_j − d_i)); a row of any other pair (TDOA2's
  occasional non-neighbour pairs, 0.4–5 % of its rows, when a packet was missed) is
  counted (``off_layout``) and not used.
* **Steps and dropouts.** Step k is at log time ``start + k·dt``; a channel is valid at
  step k when a row of it arrived in (t_{k−1}, t_k], and the last one is used (earlier ones
  are counted, ``superseded``). A step without an arrival is a masked channel: TDOA3's
  irregular arrivals and TDOA2 gaps are dropouts, never interpolated.
* **Truth** is the UWB tag: the mocap position plus the body-frame lever arm
  ``TAG_LEVER_ARM`` rotated by the mocap attitude (the dataset scripts' value for its
  vehicle; the README computes its residual statistics with it), linearly interpolated;
  velocity the central difference over ±25 ms, as for the TWR flight.
* **Residual and labels.** A row's residual is its value minus the true range difference
  at its own arrival time. The fault labels (``Recording.label``, the world's
  ``SenseBuffers.label`` on a real flight) mark |residual| > ``FAULT_LABEL_SIGMAS``·σ, the
  simulated world's injected-fault rule with the residual standing for the injected error; no
  calibration removes the persistent per-pair offsets (0.1–0.25 m in LOS), which stay
  below that threshold.
* **IMU input** exactly as for the TWR flight (``util_flight``: AHRS, world acceleration,
  step means); no mocap enters.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from swarmloc.envs.recorded.util_flight import (
    MAD_TO_SIGMA,
    Recording,
    _read_only,
    episode_times,
    read_anchors,
    read_tables,
    truth_and_imu,
)

#: m, the README's airborne rule (mocap z above it)
AIRBORNE_ALTITUDE = 0.3
#: m, body frame: the UWB tag's offset from the mocap origin (dataset scripts, ``t_uv``)
TAG_LEVER_ARM = (-0.01245, 0.00127, 0.0908)
#: fault label on a real TDOA flight: |residual| above this many nominal σ (the simulated
#: world's ``INJECTED_FAULT_SIGMAS``)
FAULT_LABEL_SIGMAS = 3.0


@dataclass(frozen=True)
class TdoaLog:
    """The streams of one imported TDOA flight that replay uses (arrays read-only).

    Attributes:
        tdoa: ``(m, 4)`` t, idA, idB, range difference [m].
        mocap: ``(p, 8)`` t, position (3) [m], quaternion x, y, z, w.
        imu: ``(n, 7)`` t, specific force (3) [m/s²], angular rate (3) [rad/s].
    """

    tdoa: np.ndarray
    mocap: np.ndarray
    imu: np.ndarray


@dataclass(frozen=True)
class TdoaRowCounts:
    """What the filtering rules did to a flight's TDOA rows (see the module docstring).

    Attributes:
        logged: rows in ``tdoa.csv.gz``.
        impossible: |tdoa| > anchor baseline: dropped.
        outside: outside the episode window (on the floor, before take-off or after landing).
        off_layout: a pair that is not one of the task's channels.
        superseded: an earlier arrival of the same channel in the same step.
        used: rows that became a channel measurement.
    """

    logged: int
    impossible: int
    outside: int
    off_layout: int
    superseded: int
    used: int


@dataclass(frozen=True)
class TdoaRecording(Recording):
    """A TDOA flight on filter steps (``Recording`` with one channel per anchor pair).

    Attributes (beyond ``Recording``'s, whose per-channel arrays have one column per pair):
        pairs: ``(L, 2)`` the anchor pair (i, j) of each channel.
        counts: what the filtering rules dropped.
    """

    pairs: np.ndarray
    counts: TdoaRowCounts


@functools.lru_cache(maxsize=4)
def read_tdoa_log(log_dir: Path) -> TdoaLog:
    """Read the tdoa, mocap and imu CSVs of one imported TDOA flight (cached).

    Raises:
        FileNotFoundError: a CSV is missing (the message names it and the import command).
        ValueError: a CSV has the wrong number of columns.
    """
    return TdoaLog(*read_tables(log_dir, (("tdoa", 4), ("mocap", 8), ("imu", 7)),
                                "import the flight with `swarmloc data import-util-tdoa`"))


def airborne_window(mocap: np.ndarray, altitude: float = AIRBORNE_ALTITUDE) -> tuple[float, float]:
    """First and last mocap times with z above ``altitude`` (the README's airborne rule).

    Raises:
        ValueError: the vehicle never rises above ``altitude``.
    """
    air = np.nonzero(mocap[:, 3] > altitude)[0]
    if air.size == 0:
        raise ValueError(f"the vehicle never rises above {altitude} m")
    return float(mocap[air[0], 0]), float(mocap[air[-1], 0])


def rotate_body_to_world(q_xyzw: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R(q)·v for unit quaternions ``(n, 4)`` scalar last (body → world, the mocap convention)."""
    u, w = q_xyzw[:, :3], q_xyzw[:, 3:4]
    v = np.broadcast_to(v, u.shape)
    # v' = v + 2w (u × v) + 2 u × (u × v)
    uv = np.cross(u, v)
    return v + 2.0 * w * uv + 2.0 * np.cross(u, uv)


def tag_positions(mocap: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The UWB tag's true position at times ``t``: mocap position + R(q)·lever arm, interpolated → ``(len(t), 3)``."""
    cols = [np.interp(t, mocap[:, 0], mocap[:, 1 + c]) for c in range(7)]
    p, q = np.stack(cols[:3], axis=-1), np.stack(cols[3:], axis=-1)
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return p + rotate_body_to_world(q, np.asarray(TAG_LEVER_ARM))


def range_differences(p: np.ndarray, anchors: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """‖p − a_j‖ − ‖p − a_i‖ row by row (``p`` ``(n, 3)``, anchor indices ``(n,)``)."""
    return np.linalg.norm(p - anchors[j], axis=-1) - np.linalg.norm(p - anchors[i], axis=-1)


def impossible_rows(tdoa: np.ndarray, anchors: np.ndarray) -> np.ndarray:
    """``(m,)`` bool: rows whose |range difference| exceeds the baseline ‖a_i − a_j‖ of their pair."""
    i, j = tdoa[:, 1].astype(int), tdoa[:, 2].astype(int)
    return np.abs(tdoa[:, 3]) > np.linalg.norm(anchors[i] - anchors[j], axis=-1)


def channel_of_rows(tdoa: np.ndarray, pairs: np.ndarray, n_anchors: int) -> tuple[np.ndarray, np.ndarray]:
    """Channel index (−1: not a channel) and sign (+1, or −1 for the reversed pair) of each row."""
    lookup = np.full((n_anchors, n_anchors), -1, dtype=np.int64)
    sign = np.zeros((n_anchors, n_anchors))
    for c, (i, j) in enumerate(pairs):
        lookup[i, j], sign[i, j] = c, 1.0
        lookup[j, i], sign[j, i] = c, -1.0
    i, j = tdoa[:, 1].astype(int), tdoa[:, 2].astype(int)
    return lookup[i, j], sign[i, j]


@functools.lru_cache(maxsize=8)
def load_tdoa_recording(folder: Path, log: str, start: float, n_steps: int, dt: float, anchors_file: str,
                        pairs: tuple[tuple[int, int], ...], sigma: float) -> TdoaRecording:
    """Resample one imported TDOA flight onto filter steps (cached per argument tuple).

    Args:
        folder: the dataset folder (``.../util-tdoa``).
        log: the flight folder, e.g. ``"c0426-tdoa2-traj11-wood-card-plastic-metal"``.
        start: log time of step 0 [s] (take-off, see ``airborne_window``).
        n_steps: T, the number of steps after step 0.
        dt: filter step [s].
        anchors_file: the constellation's anchor file, e.g. ``"anchors_c0426.csv"``.
        pairs: the task's channels, one anchor pair (i, j) each.
        sigma: the nominal range-difference σ [m] (the labels' unit).

    Returns:
        The ``TdoaRecording`` (every rule in the module docstring).

    Raises:
        FileNotFoundError: the flight or the anchor file is missing.
        ValueError: the window does not fit inside the flight's IMU and mocap, or a row or a
            pair names an anchor that is not surveyed.
    """
    log_dir = folder / log
    if not log_dir.is_dir():
        raise FileNotFoundError(f"flight {log!r} not found in {folder}; import it with "
                                "`swarmloc data import-util-tdoa`")
    if not (folder / anchors_file).is_file():
        raise FileNotFoundError(f"{folder / anchors_file} is missing; import the constellation's survey with "
                                "`swarmloc data import-util-tdoa ... --survey anchor_<session>.npz --constellation c<session>`")
    anchors = read_anchors(folder, anchors_file)
    data = read_tdoa_log(log_dir)
    n_a, n_l = len(anchors), len(pairs)
    pair_arr = np.array(pairs, dtype=np.int64).reshape(-1, 2)
    ids = data.tdoa[:, 1:3].astype(int)
    if ids.max() >= n_a or pair_arr.max() >= n_a:
        raise ValueError(f"flight {log!r} or the task names anchors beyond the {n_a} of {anchors_file}")
    t = episode_times(data.imu, data.mocap, start, dt, n_steps, f"flight {log!r}")

    # ---- truth (the tag) and IMU input
    pos, vel, imu, attitude = truth_and_imu(data.mocap, data.imu, t, dt, tag_positions)

    # ---- the rules, in order: impossible values, the window, the layout, one arrival per step
    rows = data.tdoa
    impossible = impossible_rows(rows, anchors)
    step = np.ceil((rows[:, 0] - start) / dt - 1e-9).astype(np.int64)
    inside = (step >= 1) & (step <= n_steps)
    channel, sign = channel_of_rows(rows, pair_arr, n_a)
    on_layout = channel >= 0
    keep = np.nonzero(~impossible & inside & on_layout)[0]
    key = step[keep] * n_l + channel[keep]
    _, last_from_end = np.unique(key[::-1], return_index=True)
    last = keep[len(keep) - 1 - last_from_end]
    counts = TdoaRowCounts(
        logged=len(rows), impossible=int(impossible.sum()), outside=int((~impossible & ~inside).sum()),
        off_layout=int((~impossible & inside & ~on_layout).sum()), superseded=len(keep) - len(last), used=len(last))

    value = sign[last] * rows[last, 3]
    i, j = pair_arr[channel[last], 0], pair_arr[channel[last], 1]
    truth_at_arrival = range_differences(tag_positions(data.mocap, rows[last, 0]), anchors, i, j)
    z = np.zeros((n_steps + 1, n_l))
    valid = np.zeros((n_steps + 1, n_l), dtype=bool)
    residual = np.zeros((n_steps + 1, n_l))
    z[step[last], channel[last]] = value
    valid[step[last], channel[last]] = True
    residual[step[last], channel[last]] = value - truth_at_arrival
    label = valid & (np.abs(residual) > FAULT_LABEL_SIGMAS * sigma)
    spread = np.zeros(n_l)
    for c in range(n_l):
        e = residual[1:, c][valid[1:, c]]
        if e.size:
            spread[c] = MAD_TO_SIGMA * np.median(np.abs(e - np.median(e)))

    rec = TdoaRecording(log=log, t=t, anchors=anchors, pos=pos, vel=vel, imu=imu, attitude=attitude, z=z,
                        valid=valid, label=label, residual=residual, bias=np.zeros(n_l), spread=spread,
                        pairs=pair_arr, counts=counts)
    _read_only(rec.t, rec.anchors, rec.pos, rec.vel, rec.imu, rec.attitude, rec.z, rec.valid, rec.label,
               rec.residual, rec.bias, rec.spread, rec.pairs)
    return rec


__all__ = [
    "AIRBORNE_ALTITUDE",
    "FAULT_LABEL_SIGMAS",
    "TAG_LEVER_ARM",
    "TdoaLog",
    "TdoaRecording",
    "TdoaRowCounts",
    "airborne_window",
    "channel_of_rows",
    "impossible_rows",
    "load_tdoa_recording",
    "range_differences",
    "read_tdoa_log",
    "tag_positions",
]
