"""Per-episode fault schedules, built at reset from the spec and the episode seeds.

Scheduled faults (fixed windows) and randomised ones (drawn from the counter-based RNG
keyed by the episode seed) end up in the same flat arrays with a leading batch axis, so
the world kernel has one code path. Windows are half-open in time: ``start <= t < end``.
Continuous processes (Gauss–Markov NLOS, hybrid noise, packet loss) are parameters here
and evolve inside the kernel. On a TDOA task the anchor-targeted faults (uniform and
Gauss–Markov NLOS, UWB outages) act on the TDOA channels, one per anchor pair.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from swarmloc.envs.tasks.channels import ANCHOR, PEER, PEER_REL, TDOA, ChannelLayout
from swarmloc.envs.tasks.rng import Stream, normal, uniform
from swarmloc.envs.tasks.specs import GpsDriftRandom, TaskSpec, VisionOutageRandom

#: range-bias window modes: constant ``a``; uniform in [a, b] per draw; rising linearly from 0 to ``a`` over ``b`` s
BIAS_CONSTANT, BIAS_UNIFORM, BIAS_RAMP = 0, 1, 2
#: ``hybrid_param[5]``: the hybrid GPS noise model (``specs.HybridNoise.model``)
HYBRID_WEIGHTED_SUM, HYBRID_MIXTURE = 0, 1


#: schedule fields that describe the task, not an episode (no leading batch axis)
PER_TASK_FIELDS = ("gm_key", "hybrid_nodes", "packet_loss")
#: index offset of the per-episode Gauss–Markov draws in the schedule stream (clear of the others)
GM_DRAWS = 3_000_000
#: index offsets of the per-episode hybrid-noise ratio, GPS drift and camera outage draws
HYBRID_DRAWS, DRIFT_DRAWS, OUTAGE_DRAWS = 5_000_000, 6_000_000, 7_000_000


class FaultSchedule(NamedTuple):
    """Fault windows of B episodes (arrays have a leading batch axis B unless stated).

    A named tuple of arrays so the world kernel can take it as one argument.

    Attributes:
        bias_time: ``(B, W, 2)`` range-bias windows [start, end).
        bias_param: ``(B, W, 3)`` [mode, a, b]: constant ``a``, uniform in [a, b] per draw, or rising
            linearly from 0 to ``a`` over the first ``b`` seconds of the window (``BIAS_*``).
        bias_mask: ``(B, W, N, L)`` channels a bias window hits.
        imu_time: ``(B, Wi, 2)`` IMU-fault windows.
        imu_bias: ``(B, Wi, 3)`` accelerometer bias added inside the window [m/s²].
        imu_nodes: ``(B, Wi, N)`` faulty UAVs per window.
        imu_drop: ``(B, Wi)`` whether the faulty UAVs go blind (no measurement at all).
        outage_time: ``(B, Wo, 2)`` camera outage windows; ``outage_nodes`` ``(B, Wo, N)``
            (randomized outages pad to their most windows with empty ones, [0, 0) on no UAV).
        uwb_time: ``(B, Wu, 2)`` UWB outage windows; ``uwb_mask`` ``(B, Wu, N, L)`` the
            range / peer channels each window silences.
        drift_time: ``(B, Wg, 2)`` GPS drift windows; ``drift_rate`` ``(B, Wg, 3)`` [m/s];
            ``drift_nodes`` ``(B, Wg, N)``.
        gm_mask: ``(B, N, L)`` links subject to Gauss–Markov NLOS; ``gm_param`` ``(B, 7)``
            [onset_rate, mean_duration, mean_bias, bias_sigma, tau, max_bias, ramp onset (1/0)]
            (per episode: a randomized scenario draws them from the seed).
        gm_key: ``(N, L)`` int64 (per task) the index that keys each channel's Gauss–Markov draws
            (its NLOS-prone draw, onsets and process noise): ``i·L + l``, except that under
            ``peer_state="per_link"`` both directions of a peer link take the index of the lower
            UAV's channel to the higher one, so they evolve as one state (``gm_draw_keys``).
        hybrid_nodes: ``(N,)`` UAVs with hybrid GPS noise; ``hybrid_param`` ``(B, 6)``
            [ratio, t_scale, gauss_sigma, dof_low, dof_high, model] (model
            ``HYBRID_WEIGHTED_SUM`` or ``HYBRID_MIXTURE``; per episode: a randomized
            scenario draws the ratio from the seed).
        packet_loss: probability a valid measurement is lost.
        landmark_offset: ``(B, M, 3)`` error of the landmark map: landmark m truly sits at its
            public position + ``landmark_offset[b, m]`` [m] (``Sensors.landmark_map_sigma``).
    """

    bias_time: np.ndarray
    bias_param: np.ndarray
    bias_mask: np.ndarray
    imu_time: np.ndarray
    imu_bias: np.ndarray
    imu_nodes: np.ndarray
    imu_drop: np.ndarray
    outage_time: np.ndarray
    outage_nodes: np.ndarray
    uwb_time: np.ndarray
    uwb_mask: np.ndarray
    drift_time: np.ndarray
    drift_rate: np.ndarray
    drift_nodes: np.ndarray
    gm_mask: np.ndarray
    gm_param: np.ndarray
    gm_key: np.ndarray
    hybrid_nodes: np.ndarray
    hybrid_param: np.ndarray
    packet_loss: float
    landmark_offset: np.ndarray

    @property
    def faulty_nodes(self) -> np.ndarray:
        """``(B, N)`` UAVs that suffer an IMU fault at some point of the episode."""
        return self.imu_nodes.any(axis=1)

    def imu_fault_span(self) -> np.ndarray:
        """``(B, 2)`` union span [first start, last end) of IMU faults (NaN if none)."""
        b = self.imu_time.shape[0]
        if self.imu_time.shape[1] == 0:
            return np.full((b, 2), np.nan)
        return np.stack([self.imu_time[:, :, 0].min(axis=1), self.imu_time[:, :, 1].max(axis=1)], axis=1)

    def assign(self, idx: np.ndarray, other: FaultSchedule) -> None:
        """Overwrite, in place, the windows of episodes ``idx`` with those of ``other`` (``len(idx)`` episodes)."""
        for name in self._fields:
            if name not in PER_TASK_FIELDS:
                getattr(self, name)[idx] = getattr(other, name)


def _node_mask(nodes: tuple[int, ...], n: int) -> np.ndarray:
    mask = np.zeros(n, dtype=np.bool_)
    mask[list(nodes) if nodes else slice(None)] = True
    return mask


def _column(layout: ChannelLayout, i: int, kind: str, index: int) -> int:
    """Column of UAV i's channel to anchor/peer ``index`` (-1 when it has none)."""
    kinds = (ANCHOR,) if kind == "anchor" else (PEER, PEER_REL)
    hits = np.nonzero(np.isin(layout.kind[i], kinds) & (layout.target[i] == index))[0]
    return int(hits[0]) if hits.size else -1


def gm_draw_keys(layout: ChannelLayout, per_link: bool) -> np.ndarray:
    """``(N, L)`` int64 index of each channel's Gauss–Markov draws (``FaultSchedule.gm_key``).

    Args:
        layout: the task's channel layout.
        per_link: key both directions of a peer link by the unordered pair: the channel of
            UAV i to UAV j (i > j) takes the index of UAV j's channel to UAV i, so the two share
            every draw. False: each channel its own index ``i·L + l``.

    Returns:
        The index per channel; per channel it is ``i·L + l``, the draws of every v0/v1 task.
    """
    n, n_l = layout.kind.shape
    key = np.arange(n * n_l, dtype=np.int64).reshape(n, n_l)
    if per_link:
        for i, l in zip(*np.nonzero(layout.kind == PEER)):
            j = int(layout.target[i, l])
            if j < i:
                key[i, l] = j * n_l + _column(layout, j, "peer", int(i))
    return key


def build_schedule(spec: TaskSpec, layout: ChannelLayout, seeds: np.ndarray) -> FaultSchedule:
    """Build the fault schedule of B episodes with the given seeds.

    Args:
        spec: the task.
        layout: its channel layout.
        seeds: ``(B,)`` non-negative episode seeds.

    Returns:
        The per-episode ``FaultSchedule``.
    """
    f = spec.faults
    n, n_l = spec.n_uav, layout.n_channels
    n_b = len(seeds)

    # ---- range-bias windows: scheduled steps + random uniform-bias windows
    bias_rows: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []  # (time(B,2), param(B,3), mask(B,N,L))
    for step in f.nlos_steps:
        mask = np.zeros((n, n_l), dtype=np.bool_)
        for i in np.nonzero(_node_mask(step.nodes, n))[0]:
            col = _column(layout, int(i), step.target, step.index)
            if col >= 0:
                mask[i, col] = True
        bias_rows.append((
            np.tile([step.start, step.end], (n_b, 1)),
            np.tile([BIAS_RAMP, step.bias, step.ramp] if step.ramp > 0 else [BIAS_CONSTANT, step.bias, step.bias],
                    (n_b, 1)),
            np.broadcast_to(mask, (n_b, n, n_l)).copy(),
        ))
    if f.nlos_uniform is not None:
        nu = f.nlos_uniform
        eligible = np.zeros((n, n_l), dtype=np.bool_)
        kinds = [ANCHOR, TDOA] * ("anchor" in nu.targets) + [PEER, PEER_REL] * ("peer" in nu.targets)
        eligible[:] = np.isin(layout.kind, kinds) & layout.linked
        eligible &= _node_mask(nu.nodes, n)[:, None]
        for w, (t0, t1) in enumerate(nu.windows):
            mask = np.zeros((n_b, n, n_l), dtype=np.bool_)
            for b, seed in enumerate(seeds):
                for i, l in zip(*np.nonzero(eligible)):
                    u = uniform(int(seed), w, Stream.SCHEDULE, 1_000_000 + int(i) * n_l + int(l))
                    mask[b, i, l] = u < nu.link_fraction
            bias_rows.append((
                np.tile([t0, t1], (n_b, 1)),
                np.tile([BIAS_UNIFORM, nu.low, nu.high], (n_b, 1)),
                mask,
            ))

    # ---- IMU cascades: scheduled + randomised
    imu_rows: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
    for c in f.imu_cascades:
        imu_rows.append((
            np.tile([c.start, c.end], (n_b, 1)),
            np.tile(c.bias, (n_b, 1)),
            np.broadcast_to(_node_mask(c.nodes, n), (n_b, n)).copy(),
            np.full(n_b, c.blind),
        ))
    if f.imu_cascade_random is not None:
        r = f.imu_cascade_random
        times, biases, nodes = np.zeros((n_b, 2)), np.zeros((n_b, 3)), np.zeros((n_b, n), dtype=np.bool_)
        for b, seed in enumerate(seeds):
            s = int(seed)
            draw = lambda k: uniform(s, 0, Stream.SCHEDULE, k)  # noqa: E731
            order = np.argsort([draw(10 + i) for i in range(n)], kind="stable")
            nodes[b, order[: r.n_faulty]] = True
            start = r.start_range[0] + (r.start_range[1] - r.start_range[0]) * draw(1)
            length = r.duration_range[0] + (r.duration_range[1] - r.duration_range[0]) * draw(2)
            times[b] = (start, start + length)
            mag = r.bias_magnitude_range[0] + (r.bias_magnitude_range[1] - r.bias_magnitude_range[0]) * draw(3)
            # direction uniform on the upper hemisphere (bias pushes up and sideways)
            az, cz = 2 * np.pi * draw(4), draw(5)
            sz = np.sqrt(1.0 - cz * cz)
            biases[b] = mag * np.array([sz * np.cos(az), sz * np.sin(az), cz])
        imu_rows.append((times, biases, nodes, np.full(n_b, r.blind)))

    outage_rows = []
    if f.vision_outage is not None:
        for t0, t1 in f.vision_outage.windows:
            outage_rows.append((np.tile([t0, t1], (n_b, 1)),
                                np.broadcast_to(_node_mask(f.vision_outage.nodes, n), (n_b, n)).copy()))
    if f.vision_outage_random is not None:
        outage_rows += _random_outages(f.vision_outage_random, n, seeds)

    uwb_rows = []
    if f.uwb_outage is not None:
        out = f.uwb_outage
        kinds = [ANCHOR, TDOA] * ("anchor" in out.targets) + [PEER, PEER_REL] * ("peer" in out.targets)
        mask = np.isin(layout.kind, kinds) & _node_mask(out.nodes, n)[:, None]
        for t0, t1 in out.windows:
            uwb_rows.append((np.tile([t0, t1], (n_b, 1)), np.broadcast_to(mask, (n_b, n, n_l)).copy()))

    drift_rows = []
    for d in f.gps_drifts:
        direction = np.asarray(d.direction, dtype=float)
        direction /= max(np.linalg.norm(direction), 1e-12)
        drift_rows.append((np.tile([d.start, d.end], (n_b, 1)), np.tile(d.rate * direction, (n_b, 1)),
                           np.broadcast_to(_node_mask(d.nodes, n), (n_b, n)).copy()))
    if f.gps_drift_random is not None:
        drift_rows.append(_random_drift(f.gps_drift_random, n, seeds))

    gm_mask = np.zeros((n_b, n, n_l), dtype=np.bool_)
    gm_param = np.zeros((n_b, 7))
    per_link = f.nlos_gauss_markov is not None and f.nlos_gauss_markov.peer_state == "per_link"
    gm_key = gm_draw_keys(layout, per_link)
    if f.nlos_gauss_markov is not None:
        g = f.nlos_gauss_markov
        kinds = [ANCHOR, TDOA] * ("anchor" in g.targets) + [PEER] * ("peer" in g.targets)
        eligible = np.isin(layout.kind, kinds) & layout.linked & _node_mask(g.nodes, n)[:, None]
        gm_mask[:] = eligible
        gm_param[:] = [g.onset_rate, g.mean_duration, g.mean_bias, g.bias_sigma, g.tau, g.max_bias,
                       float(g.onset == "ramp")]
        for b, seed in enumerate(seeds):
            draw = lambda k: uniform(int(seed), 0, Stream.SCHEDULE, GM_DRAWS + k)  # noqa: E731
            if g.onset_rate_range is not None:
                lo, hi = g.onset_rate_range
                gm_param[b, 0] = lo + (hi - lo) * draw(0)
            if g.mean_bias_range is not None:
                lo, hi = g.mean_bias_range
                gm_param[b, 2] = lo * (hi / lo) ** draw(1)
            if g.link_fraction < 1.0:
                prone = np.array([[draw(2 + int(gm_key[i, l])) < g.link_fraction for l in range(n_l)]
                                  for i in range(n)])
                gm_mask[b] = eligible & prone

    hybrid_nodes = np.zeros(n, dtype=np.bool_)
    hybrid_param = np.zeros((n_b, 6))
    if f.hybrid_noise is not None:
        h = f.hybrid_noise
        hybrid_nodes = _node_mask(h.nodes, n)
        model = HYBRID_MIXTURE if h.model == "mixture" else HYBRID_WEIGHTED_SUM
        hybrid_param[:] = [h.ratio, h.t_scale, h.gauss_sigma, h.dof_low, max(h.dof_high, h.dof_low), model]
        if h.ratio_range is not None:
            lo, hi = h.ratio_range
            for b, seed in enumerate(seeds):
                hybrid_param[b, 0] = lo + (hi - lo) * uniform(int(seed), 0, Stream.SCHEDULE, HYBRID_DRAWS)

    def stack(rows: list, k: int, shape_tail: tuple, dtype=np.float64) -> np.ndarray:
        if not rows:
            return np.zeros((n_b, 0, *shape_tail), dtype=dtype)
        return np.ascontiguousarray(np.stack([row[k] for row in rows], axis=1).astype(dtype))

    return FaultSchedule(
        bias_time=stack(bias_rows, 0, (2,)),
        bias_param=stack(bias_rows, 1, (3,)),
        bias_mask=stack(bias_rows, 2, (n, n_l), np.bool_),
        imu_time=stack(imu_rows, 0, (2,)),
        imu_bias=stack(imu_rows, 1, (3,)),
        imu_nodes=stack(imu_rows, 2, (n,), np.bool_),
        imu_drop=stack(imu_rows, 3, (), np.bool_),
        outage_time=stack(outage_rows, 0, (2,)),
        outage_nodes=stack(outage_rows, 1, (n,), np.bool_),
        uwb_time=stack(uwb_rows, 0, (2,)),
        uwb_mask=stack(uwb_rows, 1, (n, n_l), np.bool_),
        drift_time=stack(drift_rows, 0, (2,)),
        drift_rate=stack(drift_rows, 1, (3,)),
        drift_nodes=stack(drift_rows, 2, (n,), np.bool_),
        gm_mask=np.ascontiguousarray(gm_mask),
        gm_param=gm_param,
        gm_key=gm_key,
        hybrid_nodes=hybrid_nodes,
        hybrid_param=hybrid_param,
        packet_loss=float(f.packet_loss),
        landmark_offset=_landmark_offsets(spec, seeds),
    )


def _uniform_in(r: tuple[float, float], u: float) -> float:
    """The point u ∈ [0, 1) of the way through the range [low, high]."""
    return r[0] + (r[1] - r[0]) * u


def _count_in(r: tuple[int, int], u: float) -> int:
    """An integer uniform in [low, high] from u ∈ [0, 1)."""
    return r[0] + min(int(u * (r[1] - r[0] + 1)), r[1] - r[0])


def _random_drift(r: GpsDriftRandom, n: int, seeds: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The drift row of B episodes: window ``(B, 2)``, rate vector ``(B, 3)`` [m/s], drifting UAVs ``(B, N)``.

    Draws (``DRIFT_DRAWS`` + k of the schedule stream, step 0): k = 0 onset, 1 duration, 2 speed,
    3 azimuth, 4 how many UAVs drift, 10 + c the order in which candidate c is picked.
    """
    times, rates, nodes = np.zeros((len(seeds), 2)), np.zeros((len(seeds), 3)), np.zeros((len(seeds), n), np.bool_)
    el = np.radians(r.elevation_deg)
    for b, seed in enumerate(seeds):
        draw = lambda k: uniform(int(seed), 0, Stream.SCHEDULE, DRIFT_DRAWS + k)  # noqa: E731
        start = _uniform_in(r.start_range, draw(0))
        times[b] = (start, start + _uniform_in(r.duration_range, draw(1)))
        az = 2.0 * np.pi * draw(3)
        rates[b] = _uniform_in(r.rate_range, draw(2)) * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az),
                                                                   np.sin(el)])
        order = np.argsort([draw(10 + c) for c in range(len(r.nodes))], kind="stable")
        picked = [r.nodes[c] for c in order[: _count_in(r.n_drifting_range, draw(4))]]
        nodes[b, picked] = True
    return times, rates, nodes


def _random_outages(r: VisionOutageRandom, n: int, seeds: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """``r.max_windows`` outage rows of B episodes: window ``(B, 2)``, blind UAVs ``(B, N)`` each.

    Episode b draws c outages (``OUTAGE_DRAWS`` + 0 of the schedule stream, step 0); outage k < c
    lies in slot k of c equal slots of the span, duration at ``OUTAGE_DRAWS`` + 1 + 2k, start
    within the slot at + 2 + 2k. Rows k ≥ c stay empty: [0, 0) on no UAV.
    """
    rows = [(np.zeros((len(seeds), 2)), np.zeros((len(seeds), n), np.bool_)) for _ in range(r.max_windows)]
    mask = _node_mask(r.nodes, n)
    t0, t1 = r.span
    for b, seed in enumerate(seeds):
        draw = lambda k: uniform(int(seed), 0, Stream.SCHEDULE, OUTAGE_DRAWS + k)  # noqa: E731
        c = _count_in(r.count_range, draw(0))
        slot = (t1 - t0) / max(c, 1)
        for k in range(c):
            length = _uniform_in(r.duration_range, draw(1 + 2 * k))
            start = t0 + k * slot + (slot - length) * draw(2 + 2 * k)
            rows[k][0][b] = (start, start + length)
            rows[k][1][b] = mask
    return rows


#: index offset of the landmark-map draws in the schedule stream (clear of the others)
MAP_DRAWS = 4_000_000


def _landmark_offsets(spec: TaskSpec, seeds: np.ndarray) -> np.ndarray:
    """``(B, M, 3)`` per-episode landmark map errors, N(0, σ_map²) per axis, from the episode seed."""
    n_m, sigma = len(spec.landmarks), spec.sensors.landmark_map_sigma
    out = np.zeros((len(seeds), n_m, 3))
    if sigma > 0.0:
        for b, seed in enumerate(seeds):
            for m in range(n_m):
                for d in range(3):
                    out[b, m, d] = sigma * normal(int(seed), 0, Stream.SCHEDULE, MAP_DRAWS + 3 * m + d)
    return out
