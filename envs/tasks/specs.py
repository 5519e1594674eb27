"""Frozen, validated task specifications.

A task is one ``TaskSpec``: the swarm, its truth trajectories, sensors, faults, scoring
and the nominal filter settings. Specs are pydantic models with ``extra="forbid"``:
unknown keys and impossible values raise ``pydantic.ValidationError`` naming the field
and the allowed range. Specs round-trip through JSON (``spec.model_dump_json()`` /
``TaskSpec.model_validate_json``). Derived quantities (channel count, step count) are
properties, never stored defaults that could go stale.
"""

from __future__ import annotations

from typing import Annotated, Literal, Union

from pydantic import BaseModel, ConfigDict, Field, model_validator

Vec3 = tuple[float, float, float]
PositiveFloat = Annotated[float, Field(gt=0.0)]
NonNegFloat = Annotated[float, Field(ge=0.0)]
Probability = Annotated[float, Field(ge=0.0, le=1.0)]


class Frozen(BaseModel):
    """Base for every spec model: immutable, unknown keys and non-finite numbers (NaN, ±inf) rejected."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)


# --------------------------------------------------------------------------- truth


class AccelCircle(Frozen):
    """Straight accelerate-then-circle (madrl Exp. 1): from rest along +x, then a circle.

    UAV i starts at ``(0, i·spacing, altitude)``; it accelerates uniformly for
    ``accel_time`` seconds up to the circle speed ``radius·omega`` and then turns left on
    a circle of ``radius`` tangent to its straight path.
    """

    kind: Literal["accel_circle"] = "accel_circle"
    accel_time: PositiveFloat = 15.0
    radius: PositiveFloat = 10.0
    omega: PositiveFloat = 0.25
    altitude: float = 2.0
    spacing: float = 3.0


class PhasedCircles(Frozen):
    """Circles with per-UAV phase offsets and a vertical sine (pf-nn §4.1)."""

    kind: Literal["phased_circles"] = "phased_circles"
    center: Vec3 = (0.0, 0.0, 2.0)
    radius: PositiveFloat = 5.0
    omega: float = 0.15
    phase_step: float = Field(default=1.0471975511965976, description="phase offset between UAVs [rad]")
    z_amplitude: NonNegFloat = 0.5
    z_omega: NonNegFloat = 0.3
    radius_step: NonNegFloat = Field(default=0.0, description="radius grows by this per UAV index [m]")


class FigureEightChain(Frozen):
    """Leader on a figure-eight (Gerono lemniscate); followers trail it in a chain.

    Follower i flies the leader's path delayed by ``i·lag`` seconds, offset sideways by
    ``i·offset`` metres (a leader–follower chain, imm-arkf §2.4).
    """

    kind: Literal["figure_eight_chain"] = "figure_eight_chain"
    radius: PositiveFloat = 20.0
    omega: PositiveFloat = 0.1
    altitude: float = 10.0
    lag: NonNegFloat = 1.0
    offset: float = 0.5


class LeaderFollowerLine(Frozen):
    """Leaders and followers flying a slow turning line in formation (federated §5)."""

    kind: Literal["leader_follower_line"] = "leader_follower_line"
    speed: PositiveFloat = 10.0
    turn_rate: float = 0.005
    altitude: float = 100.0
    spacing: PositiveFloat = 30.0


class RandomWaypoints(Frozen):
    """Smooth random waypoints: cosine-blended segments between seeded waypoints."""

    kind: Literal["random_waypoints"] = "random_waypoints"
    segment_time: PositiveFloat = 8.0
    low: Vec3 = (-10.0, -10.0, 1.0)
    high: Vec3 = (10.0, 10.0, 4.0)


class RecordedFlight(Frozen):
    """A real flight replayed from an imported data set instead of a simulated trajectory.

    Nothing is simulated: truth, IMU and ranges come from the log (see
    ``swarmloc.envs.recorded.replay``); build the world with ``swarmloc.envs.make_world``.
    Step 0 of an episode is log time ``start``; the episode lasts the spec's ``duration``.
    The data set is not shipped: it is located at run time (``SWARMLOC_DATA``).
    """

    kind: Literal["recorded"] = "recorded"
    dataset: Literal["util-twr", "util-tdoa"] = Field(
        default="util-twr", description="imported data set folder: UTIL two-way ranging or TDOA flights")
    log: str = Field(default="twr-obs-log1", pattern=r"^[A-Za-z0-9_-][A-Za-z0-9._-]*$", description="flight log")
    start: NonNegFloat = Field(default=9.15, description="log time of step 0 [s]")
    calibration: str | None = Field(
        default="log00", pattern=r"^[A-Za-z0-9_-][A-Za-z0-9._-]*$",
        description="log whose ranges against mocap give the per-anchor range bias; None = raw ranges")
    anchors: str = Field(default="anchors.csv", pattern=r"^[A-Za-z0-9_-][A-Za-z0-9._-]*\.csv$",
                         description="the data set's anchor file (anchor_id,x,y,z) the flight uses")

    @model_validator(mode="after")
    def _tdoa_has_no_calibration(self) -> "RecordedFlight":
        if self.dataset == "util-tdoa" and self.calibration is not None:
            raise ValueError(f"calibration={self.calibration!r}: the UTIL TDOA flights have no calibration log "
                             "(use None)")
        return self


Trajectory = Annotated[
    Union[AccelCircle, PhasedCircles, FigureEightChain, LeaderFollowerLine, RandomWaypoints, RecordedFlight],
    Field(discriminator="kind"),
]

# --------------------------------------------------------------------------- sensors


class PeerLinks(Frozen):
    """UWB links between UAVs.

    ``kind="range"``: scalar range; ``"relative_position"``: the neighbour's position
    relative to the receiver (UWB range + bearing, federated §2.2). ``topology`` says who
    links to whom: every pair, a chain (i ↔ i±1), or each follower to the leader(s).

    With ``topology="leader"`` the UAVs of ``leaders`` lead: a follower (any other UAV)
    measures every leader and no other follower, and each leader measures the other leaders
    and no follower. federated §2.2: a few leaders carry precise GNSS/INS navigation and the
    followers range to them (there each follower ranges to its nearest leader only; here to
    every leader, as far as ``max_range`` lets it). The default ``(0,)`` is every v0/v1 leader
    task: one leader, which measures nobody.
    """

    kind: Literal["none", "range", "relative_position"] = "range"
    topology: Literal["all", "chain", "leader"] = "all"
    sigma: PositiveFloat = 0.15
    max_range: PositiveFloat = 1e6
    leaders: tuple[Annotated[int, Field(ge=0)], ...] = Field(
        default=(0,), min_length=1, exclude_if=lambda value: value == (0,),
        description="the leading UAVs of topology='leader' (a follower links to every leader, the leaders to each "
                    "other); (0,) = UAV 0 alone (every v0/v1 task; left out of the spec's canonical JSON at that "
                    "value)")

    @model_validator(mode="after")
    def _leaders(self) -> "PeerLinks":
        if len(set(self.leaders)) != len(self.leaders):
            raise ValueError(f"leaders={self.leaders} lists a UAV twice")
        if self.leaders != (0,) and self.topology != "leader":
            raise ValueError(f"leaders={self.leaders} needs topology='leader' (got {self.topology!r}): only the "
                             "leader topology has leaders")
        return self


class Tdoa(Frozen):
    """UWB time difference of arrival (TDOA): the anchors broadcast, every UAV only listens.

    Channel ``(i, j)`` of ``pairs`` measures the range difference
    z = ‖p − a_j‖ − ‖p − a_i‖ + v, v ~ N(0, σ²) (the UTIL convention: i = idA, j = idB).
    On a task with TDOA the anchors are transmitters only: they give no two-way ranges.
    TDOA2 (the anchors in a ring, each pair of neighbours) is ``ring_pairs(A)``; TDOA3
    (every pair) is ``all_pairs(A)``.
    """

    pairs: tuple[tuple[Annotated[int, Field(ge=0)], Annotated[int, Field(ge=0)]], ...] = Field(min_length=1)
    sigma: PositiveFloat = Field(default=0.15, description="range-difference noise std [m]")

    @model_validator(mode="after")
    def _distinct(self) -> "Tdoa":
        seen = set()
        for i, j in self.pairs:
            if i == j:
                raise ValueError(f"TDOA pair ({i}, {j}) needs two different anchors")
            if frozenset((i, j)) in seen:
                raise ValueError(f"TDOA pair ({i}, {j}) appears twice (in either order)")
            seen.add(frozenset((i, j)))
        return self


def ring_pairs(n_anchors: int) -> tuple[tuple[int, int], ...]:
    """TDOA2 pairs: each anchor with the next one in the ring, ``(k, k + 1 mod A)``."""
    return tuple((k, (k + 1) % n_anchors) for k in range(n_anchors))


def all_pairs(n_anchors: int) -> tuple[tuple[int, int], ...]:
    """TDOA3 pairs: every unordered pair ``(i, j)``, i < j (a reversed arrival is the same channel, negated)."""
    return tuple((i, j) for i in range(n_anchors) for j in range(i + 1, n_anchors))


class Sensors(Frozen):
    """Nominal sensor models (standard deviations are per axis / per range).

    GNSS. ``gps_sigma`` gives every UAV a GPS slot; ``gps_nodes`` says which UAVs actually
    carry a receiver. (federated §2.2 gives its followers a low-grade receiver and its
    leaders a precise one; followers with none, leaning on the leaders alone, are the
    GNSS-denied end of that scheme.)
    The error of a fix is white by default; with ``gps_correlation_time`` τ > 0 each axis is
    a first-order Gauss–Markov process e_k = φ e_{k−1} + σ√(1−φ²) n_k, φ = exp(−dt/τ), whose
    stationary std is the fix's ``gps_sigma`` and whose lag-1 autocorrelation is φ; it starts
    stationary (e_0 ~ N(0, σ²)). Why: a standalone single-frequency fix's error is dominated
    by the residual ionospheric, tropospheric and satellite orbit and clock errors and by
    multipath, which change with the satellite geometry and the surroundings over tens of
    seconds to tens of minutes, not by the receiver's tracking noise (P. D. Groves, *Principles
    of GNSS, Inertial, and Multisensor Integrated Navigation Systems*, 2nd ed., Artech House,
    2013, the chapter on GNSS error sources); measured on a consumer receiver (Garmin 12XL,
    twenty days of static fixes), the autocorrelation of the horizontal error bends at about
    one minute and decays over tens of minutes after it (D. L. Wilson, "Correlation of
    errors", http://www.erols.com/dlwilson/gpscorr.htm). So τ is tens of seconds to minutes;
    the task chooses it, this model is the mechanism. The correlated error is the fix's
    nominal noise, not a fault: it is not in ``SenseBuffers.systematic`` and not labelled
    (``labels.py``). It does not combine with ``Faults.hybrid_noise``, which replaces the
    fix's white noise by a per-fix heavy-tailed draw (the spec refuses the pair).
    """

    imu_sigma: NonNegFloat = 0.1
    imu_bias_sigma: NonNegFloat = Field(default=0.0, description="constant per-episode accelerometer bias std [m/s²]")
    anchor_sigma: PositiveFloat = 0.15
    anchor_max_range: PositiveFloat = Field(
        default=1e6, exclude_if=lambda value: value == 1e6,
        description="UWB two-way ranging to an anchor only within this distance [m]; 1e6 = everywhere (every "
                    "registered task; left out of the spec's canonical JSON at that value)")
    peers: PeerLinks = PeerLinks()
    camera_sigma: PositiveFloat = 0.15
    camera_max_range: PositiveFloat = 10.0
    camera_fov_deg: Annotated[float, Field(gt=0.0, le=360.0)] = Field(
        default=360.0, description="camera field of view [deg], centred on the UAV's velocity; 360 = omnidirectional")
    landmark_map_sigma: NonNegFloat = Field(
        default=0.0, description="error std per axis of the landmark map (the public landmark positions), drawn per "
                                 "episode [m]; 0 = the map is exact")
    gps_sigma: tuple[PositiveFloat, ...] = Field(default=(), description="per-UAV GPS std [m]; empty = no GPS")
    gps_nodes: tuple[Annotated[int, Field(ge=0)], ...] = Field(
        default=(), exclude_if=lambda value: value == (),
        description="UAVs with a GNSS receiver; empty = every UAV (every v0/v1 task; left out of the spec's "
                    "canonical JSON then). A UAV outside it keeps its GPS slot and its gps_sigma entry (the layout "
                    "is static) but the slot is never linked, so never valid")
    gps_correlation_time: NonNegFloat = Field(
        default=0.0, exclude_if=lambda value: value == 0.0,
        description="time constant τ of the GNSS error [s]: each axis's error is a first-order Gauss–Markov "
                    "process of stationary std gps_sigma, e_k = φ e_{k−1} + σ√(1−φ²) n_k, φ = exp(−dt/τ), "
                    "stationary from the start of an episode; 0 = white (every v0/v1 task; left out of the "
                    "spec's canonical JSON then). A single-frequency receiver's position error is correlated "
                    "over tens of seconds to minutes (``Sensors``)")
    velocity_sigma: PositiveFloat | None = Field(
        default=None, description="visual odometry: world-frame velocity std per axis [m/s]; None = no VO")
    velocity_bias_sigma: NonNegFloat = Field(
        default=0.0, description="constant per-episode VO velocity bias std per axis [m/s] (drift)")
    tdoa: Tdoa | None = Field(
        default=None, description="UWB TDOA between anchor pairs instead of two-way anchor ranges; None = ranges")


# --------------------------------------------------------------------------- faults


class NlosStep(Frozen):
    """A scheduled constant positive range bias on one channel kind/index (madrl Exp. 4, 6)."""

    target: Literal["anchor", "peer"] = "anchor"
    index: int = Field(ge=0, description="anchor index, or peer UAV index")
    nodes: tuple[int, ...] = Field(default=(), description="receiving UAVs; empty = all")
    start: NonNegFloat
    end: PositiveFloat
    bias: PositiveFloat
    ramp: NonNegFloat = Field(
        default=0.0, description="seconds over which the bias grows linearly from 0 to `bias` (an obstacle moving "
                                 "into the path); 0 = a step (v0)")

    @model_validator(mode="after")
    def _window(self) -> "NlosStep":
        if self.end <= self.start:
            raise ValueError(f"end={self.end} must be > start={self.start}")
        if self.ramp > self.end - self.start:
            raise ValueError(f"ramp={self.ramp} must be <= end − start = {self.end - self.start}")
        return self


class NlosGaussMarkov(Frozen):
    """Random time-correlated positive NLOS bias episodes (madrl Exp. 2).

    Each affected link turns NLOS with rate ``onset_rate`` [1/s]; an episode lasts an
    exponential time of mean ``mean_duration``; during it the bias follows a first-order
    Gauss–Markov process around ``mean_bias`` with time constant ``tau`` and stationary
    std ``bias_sigma``, clipped to [0, max_bias].

    With ``onset="ramp"`` an NLOS episode starts at zero bias and relaxes towards the mean
    (b ← μ + φ(b − μ) + σ√(1−φ²)·n from b = 0), as when an obstacle moves into the path
    progressively; a one-step innovation test then sees no jump at the onset.

    Randomized scenarios (the ``*Random`` tasks) draw per episode, from the episode seed:
    the onset rate uniformly in ``onset_rate_range``, the mean bias log-uniformly in
    ``mean_bias_range`` (NLOS excess delays span an order of magnitude), and which of the
    eligible links are NLOS-prone at all (each with probability ``link_fraction``). A
    range left ``None`` keeps the fixed value.

    With ``peer_state="per_link"`` the two directions of a peer link are one NLOS state:
    their draws are keyed by the unordered pair, so both evolve identically.
    """

    targets: tuple[Literal["anchor", "peer"], ...] = ("anchor", "peer")
    nodes: tuple[int, ...] = Field(default=(), description="receiving UAVs affected; empty = all")
    onset_rate: PositiveFloat = 0.02
    mean_duration: PositiveFloat = 6.0
    mean_bias: NonNegFloat = 2.5
    bias_sigma: NonNegFloat = 1.0
    tau: PositiveFloat = 2.0
    max_bias: PositiveFloat = 5.0
    onset_rate_range: tuple[PositiveFloat, PositiveFloat] | None = Field(
        default=None, description="per-episode onset rate, uniform in [low, high] [1/s]; None = onset_rate")
    mean_bias_range: tuple[PositiveFloat, PositiveFloat] | None = Field(
        default=None, description="per-episode mean bias, log-uniform in [low, high] [m]; None = mean_bias")
    link_fraction: Annotated[float, Field(gt=0.0, le=1.0)] = Field(
        default=1.0, description="probability that an eligible link is NLOS-prone in an episode (drawn per episode)")
    onset: Literal["jump", "ramp"] = Field(
        default="jump", description="'jump': an NLOS episode starts at a bias drawn from the stationary law (v0); "
                                    "'ramp': it starts at 0 and the Gauss–Markov process relaxes towards the mean "
                                    "with time constant tau (the path is blocked progressively)")
    peer_state: Literal["per_channel", "per_link"] = Field(
        default="per_channel", exclude_if=lambda value: value == "per_channel",
        description="'per_channel': UAV i ranging j and UAV j ranging i are two channels with independent NLOS "
                    "states (every v0/v1 task; left out of the spec's canonical JSON at that value); 'per_link': "
                    "the two directions of a peer link share one state (one exchange, one obstruction): the same "
                    "NLOS-prone draw, the same onsets and the same bias at every step. Anchor channels are "
                    "unaffected; ``nodes`` still selects receiving UAVs, so a link with one end outside it is "
                    "biased in one direction only")

    @model_validator(mode="after")
    def _ranges(self) -> "NlosGaussMarkov":
        for name in ("onset_rate_range", "mean_bias_range"):
            r = getattr(self, name)
            if r is not None and r[1] < r[0]:
                raise ValueError(f"{name}={r}: low must be <= high")
        return self


class NlosUniform(Frozen):
    """UWB NLOS windows with a bias uniform in [low, high] per measurement (dtvirm §4)."""

    targets: tuple[Literal["anchor", "peer"], ...] = ("peer",)
    windows: tuple[tuple[float, float], ...] = ((30.0, 40.0),)
    nodes: tuple[int, ...] = ()
    link_fraction: Probability = 0.3
    low: NonNegFloat = 3.0
    high: PositiveFloat = 5.0


class ImuCascade(Frozen):
    """IMU bias on chosen nodes, which also go blind (madrl Exp. 5).

    With ``blind=True`` the faulty nodes receive no measurement inside the window and
    rely solely on uncorrected dead reckoning, as in the paper; their broadcast estimates
    then carry the drift to their neighbours.
    """

    nodes: tuple[int, ...]
    start: NonNegFloat
    end: PositiveFloat
    bias: Vec3 = (1.5, 1.2, 0.5)
    blind: bool = True

    @model_validator(mode="after")
    def _window(self) -> "ImuCascade":
        if self.end <= self.start:
            raise ValueError(f"end={self.end} must be > start={self.start}")
        return self


class ImuCascadeRandom(Frozen):
    """Randomised cascade: ``n_faulty`` nodes drawn per episode, start uniform in a range."""

    n_faulty: int = Field(default=2, ge=1)
    start_range: tuple[NonNegFloat, NonNegFloat] = (10.0, 25.0)
    duration_range: tuple[PositiveFloat, PositiveFloat] = (10.0, 15.0)
    bias_magnitude_range: tuple[PositiveFloat, PositiveFloat] = (1.0, 2.0)
    blind: bool = True


class VisionOutage(Frozen):
    """Camera blackouts: no landmark channel is valid inside a window."""

    windows: tuple[tuple[float, float], ...] = ((30.0, 40.0), (60.0, 70.0))
    nodes: tuple[int, ...] = ()


class VisionOutageRandom(Frozen):
    """Randomized camera blackouts: how many, when and how long drawn per episode from the seed.

    Each episode has c outages, c uniform in the integers of ``count_range``. ``span`` is cut
    into c equal slots and outage k lies in slot k: its duration uniform in
    ``duration_range``, its start uniform over the positions where it fits in the slot. So
    the outages never overlap and spread over the span. No landmark channel of ``nodes`` is
    valid inside an outage, as in ``VisionOutage``.
    """

    count_range: tuple[Annotated[int, Field(ge=0)], Annotated[int, Field(ge=0)]] = Field(
        default=(1, 2), description="outages per episode, uniform in the integers of [low, high]")
    duration_range: tuple[PositiveFloat, PositiveFloat] = Field(
        default=(5.0, 10.0), description="outage duration, uniform in [low, high] [s]")
    span: tuple[NonNegFloat, PositiveFloat] = Field(
        default=(10.0, 90.0), description="the outages lie in [start, end) of the episode [s]")
    nodes: tuple[int, ...] = Field(default=(), description="UAVs whose camera fails; empty = all")

    @model_validator(mode="after")
    def _ranges(self) -> "VisionOutageRandom":
        for name in ("count_range", "duration_range"):
            r = getattr(self, name)
            if r[1] < r[0]:
                raise ValueError(f"{name}={r}: low must be <= high")
        t0, t1 = self.span
        if t1 <= t0:
            raise ValueError(f"span={self.span}: end must be > start")
        if self.count_range[1] * self.duration_range[1] > t1 - t0:
            raise ValueError(f"{self.count_range[1]} outages of up to {self.duration_range[1]:g} s do not fit in "
                             f"span={self.span} ({t1 - t0:g} s): lower count_range or duration_range, or widen span")
        return self

    @property
    def max_windows(self) -> int:
        """Outage windows per episode in the fault schedule: the most an episode can draw."""
        return self.count_range[1]


class GpsDrift(Frozen):
    """Gradual GPS fault: the fix drifts at ``rate`` [m/s] along ``direction`` (federated §5)."""

    nodes: tuple[int, ...]
    start: NonNegFloat
    end: PositiveFloat
    rate: PositiveFloat = 0.1
    direction: Vec3 = (1.0, 0.0, 0.0)


class GpsDriftRandom(Frozen):
    """Randomized gradual GPS fault: one drift per episode, drawn from the episode seed.

    Per episode: k of the candidate ``nodes`` drift (k uniform in the integers of
    ``n_drifting_range``, which ones uniformly), all by the same offset: from a start uniform
    in ``start_range`` for a duration uniform in ``duration_range`` the fix moves at a speed
    uniform in ``rate_range`` [m/s, total] along a direction at ``elevation_deg`` above the
    horizontal with an azimuth uniform in [0°, 360°); after the window the offset stays (as
    ``GpsDrift``). One offset for every drifting receiver: a slow ramp of a satellite's
    signal or a spoofer dragging the fixes off reaches every receiver that tracks it alike.
    """

    nodes: tuple[int, ...] = Field(min_length=1, description="UAVs that may drift")
    n_drifting_range: tuple[Annotated[int, Field(ge=0)], Annotated[int, Field(ge=0)]] = Field(
        default=(1, 1), description="drifting UAVs per episode, uniform in the integers of [low, high]")
    start_range: tuple[NonNegFloat, NonNegFloat] = Field(
        default=(50.0, 150.0), description="drift onset, uniform in [low, high] [s]")
    duration_range: tuple[PositiveFloat, PositiveFloat] = Field(
        default=(50.0, 100.0), description="drift duration, uniform in [low, high] [s]")
    rate_range: tuple[PositiveFloat, PositiveFloat] = Field(
        default=(0.05, 0.25), description="drift speed (norm of the 3-D rate), uniform in [low, high] [m/s]")
    elevation_deg: Annotated[float, Field(ge=-90.0, le=90.0)] = Field(
        default=0.0, description="angle of the drift direction above the horizontal [deg]")

    @model_validator(mode="after")
    def _ranges(self) -> "GpsDriftRandom":
        if len(set(self.nodes)) != len(self.nodes):
            raise ValueError(f"nodes={self.nodes} lists a UAV twice")
        for name in ("n_drifting_range", "start_range", "duration_range", "rate_range"):
            r = getattr(self, name)
            if r[1] < r[0]:
                raise ValueError(f"{name}={r}: low must be <= high")
        if self.n_drifting_range[1] > len(self.nodes):
            raise ValueError(f"n_drifting_range={self.n_drifting_range}: at most len(nodes)={len(self.nodes)} "
                             "UAVs can drift")
        return self


class HybridNoise(Frozen):
    """Heavy-tailed GPS noise on the fixes of ``nodes`` (imm-arkf §2.1), in one of two models.

    * ``"weighted_sum"`` (every v0 task): eq. 1 as printed, v = a·t_ν(σ_t) + (1 − a)·N(0, σ_g²)
      per axis, a = ``ratio``, ν drawn per axis and step in [dof_low, dof_high]. A blend of
      two near-Gaussian draws: its spread is *below* σ_g and it has no outliers.
    * ``"mixture"`` (Benchmark v1): a contamination mixture. Each fix is, with probability
      p = ``ratio``, a trivariate Student-t draw σ_t·n / sqrt(χ²_ν / ν) (n ~ N(0, I₃), one χ²
      for the three axes: the paper's multivariate t; ν drawn per fix in [dof_low, dof_high]),
      else N(0, σ_g² I). A multipath-hit fix is off in every axis at once.

    ``gauss_sigma`` should equal the fix's nominal ``Sensors.gps_sigma``: the filters and the
    information bound take that σ as the fix's noise.

    Randomized scenarios (``HybridNoiseRandom``) draw the ratio per episode, from the episode
    seed, uniformly in ``ratio_range``; left ``None`` the fixed ``ratio`` holds.
    """

    ratio: Probability
    nodes: tuple[int, ...] = ()
    t_scale: PositiveFloat = 1.0
    gauss_sigma: PositiveFloat = 1.0
    # ≤ 63: the RNG keeps 64 normal draws per Student-t draw (rng.student_t_at)
    dof_low: int = Field(default=25, ge=1, le=63)
    dof_high: int = Field(default=50, ge=1, le=63)
    model: Literal["weighted_sum", "mixture"] = Field(
        default="weighted_sum",
        description="'weighted_sum': v = a·t + (1 − a)·g per axis (imm-arkf eq. 1 as printed, v0); 'mixture': "
                    "each fix Student-t with probability `ratio`, else Gaussian (v1)")
    ratio_range: tuple[Probability, Probability] | None = Field(
        default=None, description="per-episode ratio, uniform in [low, high] (drawn per episode); None = ratio")

    @model_validator(mode="after")
    def _ratio_range(self) -> "HybridNoise":
        if self.ratio_range is not None and self.ratio_range[1] < self.ratio_range[0]:
            raise ValueError(f"ratio_range={self.ratio_range}: low must be <= high")
        return self


class UwbOutage(Frozen):
    """UWB loss windows: no range of the chosen kinds arrives inside a window (dtvirm §4.4 (1))."""

    windows: tuple[tuple[float, float], ...] = ((20.0, 25.0),)
    nodes: tuple[int, ...] = Field(default=(), description="receiving UAVs; empty = all")
    targets: tuple[Literal["anchor", "peer"], ...] = ("peer",)

    @model_validator(mode="after")
    def _windows(self) -> "UwbOutage":
        for t0, t1 in self.windows:
            if not 0.0 <= t0 < t1:
                raise ValueError(f"UWB outage window ({t0}, {t1}) must satisfy 0 <= start < end")
        return self


class Faults(Frozen):
    """Every fault of a task; all are seeded and composable."""

    nlos_steps: tuple[NlosStep, ...] = ()
    nlos_gauss_markov: NlosGaussMarkov | None = None
    nlos_uniform: NlosUniform | None = None
    imu_cascades: tuple[ImuCascade, ...] = ()
    imu_cascade_random: ImuCascadeRandom | None = None
    vision_outage: VisionOutage | None = None
    packet_loss: Probability = 0.0
    uwb_outage: UwbOutage | None = None
    gps_drifts: tuple[GpsDrift, ...] = ()
    hybrid_noise: HybridNoise | None = None
    vision_outage_random: VisionOutageRandom | None = None
    gps_drift_random: GpsDriftRandom | None = None


# --------------------------------------------------------------------------- filter / scoring


class FilterSettings(Frozen):
    """The CEKF backbone's nominal settings (madrl §2.3)."""

    alpha_th: Probability = 0.05
    alpha_min: Annotated[float, Field(gt=0.0, le=1.0)] = 0.01
    init_pos_sigma: PositiveFloat = 0.5
    init_vel_sigma: PositiveFloat = 0.2
    # "split_ci" first: the refusal of an unknown value then reads "'split_ci', 'point' or 'ci'"
    peer_update: Literal["split_ci", "point", "ci"] = Field(
        default="point", exclude_if=lambda value: value == "point",
        description="'point': a peer measurement takes the neighbour's broadcast prior position as a known point "
                    "(madrl §2.3; every registered task); 'ci': covariance intersection with the neighbour's "
                    "broadcast covariance, its error correlation unknown, peer by peer; 'split_ci': split "
                    "covariance intersection of all of a step's peers in one update, each UAV's covariance split "
                    "into a part no neighbour holds and the rest (docs/world.md, 'The peer update'). "
                    "Left out of the spec's canonical JSON at 'point', so the registered tasks' hashes predate it")


class Scoring(Frozen):
    """Which nodes and interval are scored, and the fault window metrics look at.

    ``nodes_from_schedule`` makes the scored set per episode: with ``"healthy"`` an episode
    scores those of ``nodes`` (all UAVs if empty) that its fault schedule leaves without an
    IMU fault (CascadedFaultRandom-v1: the faulty nodes are drawn per episode). Every metric
    over scored UAVs (``rmse``, ``jitter``, ``delay_ms``, …) and the information bound use
    that set; ``"all"`` (the default, every v0 task) scores ``nodes`` in every episode.
    """

    nodes: tuple[int, ...] = Field(default=(), description="scored UAVs; empty = all")
    nodes_from_schedule: Literal["all", "healthy"] = Field(
        default="all",
        description="'all': every episode scores `nodes`; 'healthy': only those of `nodes` the episode's fault "
                    "schedule leaves without an IMU fault (needs an IMU fault)")
    healthy_nodes: tuple[int, ...] = Field(default=(), description="nodes for healthy-node RMSE; empty = not defined")
    fault_window: tuple[float, float] | None = None
    start: NonNegFloat = 0.0
    align_first_seconds: NonNegFloat = Field(
        default=0.0,
        description="score after the yaw + 3-D translation that best aligns the estimates of the first this-many "
                    "seconds of the scored interval with the truth (anchor-free tasks); 0 = no alignment")


class TaskSpec(Frozen):
    """One benchmark task: everything the world needs to simulate an episode."""

    name: str = Field(min_length=1, max_length=64)
    version: int = Field(default=0, ge=0)
    n_uav: int = Field(ge=1, le=256)
    dt: PositiveFloat = 0.1
    duration: PositiveFloat
    trajectory: Trajectory
    anchors: tuple[Vec3, ...] = ()
    landmarks: tuple[Vec3, ...] = ()
    sensors: Sensors = Sensors()
    faults: Faults = Faults()
    filter: FilterSettings = FilterSettings()
    scoring: Scoring = Scoring()
    track: Literal["cooperative", "robust-ranging"] | None = Field(
        default=None, exclude_if=lambda value: value is None,
        description="the board of benchmark v2 the task belongs to: 'cooperative' (a swarm whose peers carry "
                    "information; the headline) or 'robust-ranging' (one UAV against faulty ranging); every v2 "
                    "task names one, v0 and v1 tasks none (left out of the spec's canonical JSON then, so their "
                    "hashes predate it)")

    @model_validator(mode="after")
    def _consistent(self) -> "TaskSpec":
        n = self.n_uav
        if self.version >= 2 and self.track is None:
            raise ValueError(f"version={self.version}: a v2 task must name its track ('cooperative' or "
                             "'robust-ranging')")
        if self.track == "robust-ranging" and n != 1:
            raise ValueError(f"track='robust-ranging' is the one-UAV board; n_uav={n} (use 1, or track="
                             "'cooperative')")
        if self.duration < self.dt:
            raise ValueError(f"duration={self.duration} must be >= dt={self.dt}")
        gps = self.sensors.gps_sigma
        if gps and len(gps) != n:
            raise ValueError(f"sensors.gps_sigma has {len(gps)} entries; expected n_uav={n} (or none)")
        node_lists = [("scoring.nodes", self.scoring.nodes), ("scoring.healthy_nodes", self.scoring.healthy_nodes)]
        f = self.faults
        node_lists += [("faults.imu_cascades.nodes", c.nodes) for c in f.imu_cascades]
        node_lists += [("faults.nlos_steps.nodes", s.nodes) for s in f.nlos_steps]
        node_lists += [("faults.gps_drifts.nodes", d.nodes) for d in f.gps_drifts]
        if f.gps_drift_random is not None:
            node_lists.append(("faults.gps_drift_random.nodes", f.gps_drift_random.nodes))
        if f.vision_outage_random is not None:
            node_lists.append(("faults.vision_outage_random.nodes", f.vision_outage_random.nodes))
        if f.uwb_outage is not None:
            node_lists.append(("faults.uwb_outage.nodes", f.uwb_outage.nodes))
        if f.hybrid_noise is not None:
            node_lists.append(("faults.hybrid_noise.nodes", f.hybrid_noise.nodes))
        for field, nodes in node_lists:
            bad = [i for i in nodes if not 0 <= i < n]
            if bad:
                raise ValueError(f"{field} contains {bad}; UAV indices must be in [0, {n - 1}]")
        tdoa = self.sensors.tdoa
        if tdoa is not None:
            bad = [p for p in tdoa.pairs if max(p) >= len(self.anchors)]
            if bad:
                raise ValueError(f"sensors.tdoa.pairs {bad} name anchors beyond the {len(self.anchors)} of the task")
            if any(s.target == "anchor" for s in f.nlos_steps):
                raise ValueError("faults.nlos_steps on an anchor of a TDOA task is not modelled (an anchor's delay "
                                 "moves every pair it belongs to, with either sign); use nlos_gauss_markov or "
                                 "nlos_uniform, which act per TDOA channel")
        for s in f.nlos_steps:
            limit = len(self.anchors) if s.target == "anchor" else n
            if s.index >= limit:
                raise ValueError(f"faults.nlos_steps index={s.index} out of range for {s.target} (count {limit})")
        if f.imu_cascade_random is not None and f.imu_cascade_random.n_faulty >= n:
            raise ValueError(f"faults.imu_cascade_random.n_faulty={f.imu_cascade_random.n_faulty} must be < n_uav={n}")
        if self.scoring.nodes_from_schedule == "healthy":
            self._check_healthy_scoring()
        if (f.gps_drifts or f.gps_drift_random or f.hybrid_noise) and not gps:
            raise ValueError("GPS faults need sensors.gps_sigma for every UAV")
        self._check_gnss()
        if self.sensors.velocity_bias_sigma > 0 and self.sensors.velocity_sigma is None:
            raise ValueError("sensors.velocity_bias_sigma needs sensors.velocity_sigma (a VO sensor)")
        if self.scoring.align_first_seconds > 0 and not (
                self.dt <= self.scoring.align_first_seconds <= self.duration - self.scoring.start):
            raise ValueError(f"scoring.align_first_seconds={self.scoring.align_first_seconds} must be 0 or in "
                             f"[dt, duration − scoring.start] = [{self.dt}, {self.duration - self.scoring.start}]")
        for name in ("vision_outage", "vision_outage_random"):
            if getattr(f, name) is not None and not self.landmarks:
                raise ValueError(f"faults.{name} needs landmarks")
        if not (self.anchors or self.landmarks or gps or self.sensors.peers.kind != "none"):
            raise ValueError("a task needs at least one measurement channel (anchors, landmarks, gps or peers)")
        return self

    def _check_gnss(self) -> None:
        """GNSS receivers (``sensors.gps_nodes``), their error's correlation, the leaders, and the GPS faults on them."""
        n, s, f = self.n_uav, self.sensors, self.faults
        for field, nodes in (("sensors.gps_nodes", s.gps_nodes), ("sensors.peers.leaders", s.peers.leaders)):
            bad = [i for i in nodes if i >= n]
            if bad:
                raise ValueError(f"{field} contains {bad}; UAV indices must be in [0, {n - 1}]")
        if len(set(s.gps_nodes)) != len(s.gps_nodes):
            raise ValueError(f"sensors.gps_nodes={s.gps_nodes} lists a UAV twice")
        if (s.gps_nodes or s.gps_correlation_time > 0) and not s.gps_sigma:
            raise ValueError("sensors.gps_nodes and sensors.gps_correlation_time need sensors.gps_sigma (a GPS slot "
                             "per UAV)")
        if s.gps_correlation_time > 0 and f.hybrid_noise is not None:
            raise ValueError(f"sensors.gps_correlation_time={s.gps_correlation_time} with faults.hybrid_noise is not "
                             "modelled: hybrid noise replaces a fix's white noise by an independent heavy-tailed draw "
                             "per fix, which a Gauss–Markov error cannot also be (use one or the other)")
        receivers = set(s.gps_nodes or range(n))
        faulty = [(f"faults.gps_drifts[{k}].nodes", d.nodes) for k, d in enumerate(f.gps_drifts)]
        if f.gps_drift_random is not None:
            faulty.append(("faults.gps_drift_random.nodes", f.gps_drift_random.nodes))
        if f.hybrid_noise is not None:
            faulty.append(("faults.hybrid_noise.nodes", f.hybrid_noise.nodes))
        for field, nodes in faulty:
            without = sorted(set(nodes or range(n)) - receivers)
            if without:
                named = f"{field}={nodes}" if nodes else f"{field}=() (every UAV)"
                raise ValueError(f"{named} includes UAVs {without} without a GNSS receiver; a GPS fault needs a "
                                 f"receiver: use UAVs of sensors.gps_nodes={tuple(sorted(receivers))}")

    def _check_healthy_scoring(self) -> None:
        """``scoring.nodes_from_schedule="healthy"`` must leave every episode at least one scored UAV."""
        f, s = self.faults, self.scoring
        if not f.imu_cascades and f.imu_cascade_random is None:
            raise ValueError("scoring.nodes_from_schedule='healthy' needs an IMU fault (faults.imu_cascades or "
                             "faults.imu_cascade_random): without one every node is healthy (use 'all')")
        if s.align_first_seconds > 0:
            raise ValueError("scoring.nodes_from_schedule='healthy' with scoring.align_first_seconds > 0 is not "
                             "supported: the alignment is fitted on a fixed set of scored UAVs")
        scored = set(self.scored_nodes) - {i for c in f.imu_cascades for i in (c.nodes or range(self.n_uav))}
        drawn = f.imu_cascade_random.n_faulty if f.imu_cascade_random is not None else 0
        if len(scored) <= drawn:
            raise ValueError(f"scoring.nodes_from_schedule='healthy' could score no UAV: {len(scored)} scored UAV(s) "
                             f"outside the scheduled IMU cascades, and {drawn} are drawn faulty per episode")

    # ---- derived quantities
    @property
    def task_id(self) -> str:
        """Registered ID, e.g. ``swarmloc/NLOS-v0``."""
        return f"swarmloc/{self.name}-v{self.version}"

    @property
    def n_steps(self) -> int:
        """Filter steps per episode (T)."""
        return int(round(self.duration / self.dt))

    @property
    def n_peer_channels(self) -> int:
        return 0 if self.sensors.peers.kind == "none" else self.n_uav - 1

    @property
    def n_channels(self) -> int:
        """Channels per UAV (L): anchor ranges (or TDOA pairs) + peers + landmark slots + GPS."""
        return self.n_anchor_channels + self.n_peer_channels + len(self.landmarks) + (1 if self.sensors.gps_sigma else 0)

    @property
    def n_anchor_channels(self) -> int:
        """Anchor channels per UAV: one range per anchor, or one range difference per TDOA pair."""
        return len(self.anchors) if self.sensors.tdoa is None else len(self.sensors.tdoa.pairs)

    @property
    def scored_nodes(self) -> tuple[int, ...]:
        return self.scoring.nodes or tuple(range(self.n_uav))

    @property
    def peer_nis_neighbour_cov(self) -> bool:
        """Whether a peer channel's observed NIS includes the neighbour's broadcast covariance.

        v1 tasks (``version >= 1``): S = H P_i Hᵀ + u P_j uᵀ + R0 for a peer range and
        P_i + P_j + R0 I for a relative position, the variance of the innovation against a
        neighbour's prior p̂_j with covariance P_j (docs/world.md, "What a Track A policy
        observes"). v0 tasks keep S = H P_i Hᵀ + R0, bit for bit (frozen).
        """
        return self.version >= 1
