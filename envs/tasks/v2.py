"""The v2 tasks of benchmark v2: tasks where cooperation carries information, in two tracks.

Benchmark v1 measured the double counting of a CEKF that fuses a neighbour's estimate as a
known point (docs/benchmark-v2.md). Every v2 task fuses its peers by split covariance
intersection (``FilterSettings.peer_update = "split_ci"``: consistent, all of a step's peers
in one update), and names its board (``TaskSpec.track``):

* **cooperative** (the headline): swarms whose peers carry information the anchors,
  landmarks or GNSS do not: anchors that only reach part of the swarm (Scale), a cascaded
  IMU fault under non-coplanar anchors (CascadedFault), cameras lost on some UAVs while the
  others still see (VisionLoss), GNSS-denied followers leaning on leaders whose GNSS drifts
  (GradualFault, federated);
* **robust-ranging** (its own board): one UAV against faulty anchor ranging (AnchorNLOS,
  TDOA), beside the real flights (``real-v1``).

Each family has a fixed task, a randomized variant (``…Random-v2``, scenario parameters drawn
per episode: learned methods train on its training seeds) and a shifted split
(``…RandomShifted-v2``, drawn outside the training ranges). Whether a task enters the
headline is not decided here: ``swarmloc reproduce calibration --version 2`` measures the
admission criteria on dev seeds (``docs/calibration-v2.json``), and a task that fails one stays
registered with its reason.

Every parameter has its physical source in the factory's docstring; none is chosen to make
a method win. The NLOS process of the two-way-ranging v2 tasks (``NLOS_V2``) is the Gauss–Markov process
fitted to the UTIL obstacle flight's residuals (``nlos_fit_values.UTIL_NLOS_TWR``; ``swarmloc reproduce
nlos-fit``), on anchor and peer links, with one state per peer link (one exchange, one obstruction); the
simulated TDOA room's is the fit to the UTIL TDOA flights (``UTIL_NLOS_TDOA``).
"""

from __future__ import annotations

from collections.abc import Callable

from swarmloc.envs.tasks.catalogue import EIGHT_ANCHORS, ideal, scale, tdoa
from swarmloc.envs.tasks.nlos_fit_values import UTIL_NLOS_TDOA, UTIL_NLOS_TWR
from swarmloc.envs.tasks.specs import GpsDriftRandom, NlosGaussMarkov, TaskSpec, VisionOutage
from swarmloc.envs.tasks.v1 import (
    GPS_DRIFT_SHIFTED,
    GPS_DRIFT_TRAIN,
    cascaded_fault_random_shifted_v1,
    cascaded_fault_random_v1,
    cascaded_fault_v1,
    gradual_fault_v1,
    vision_loss_random_shifted_v1,
    vision_loss_random_v1,
    vision_loss_v1,
)

#: the NLOS process of the two-way-ranging v2 tasks: the UTIL TWR fit, one state per peer link (module docstring)
NLOS_V2 = {**UTIL_NLOS_TWR, "peer_state": "per_link"}
#: the randomized variants' draws per episode: onset rate uniform and mean bias log-uniform between the two UTIL
#: fits (TWR: 1.0 /s around a near-zero mean, the heavy tail of a cluttered lab; TDOA: 0.22 /s around 0.52 m, the
#: obstacle episodes behind wood, plastic and metal), and three links in four NLOS-prone
NLOS_V2_TRAIN = {"onset_rate_range": (0.2, 1.0), "mean_bias_range": (0.01, 0.5), "link_fraction": 0.75}
#: the shifted split: denser and larger biases than either UTIL fit (every link prone, 1–2 onsets per second,
#: mean bias 0.5–1.5 m: a hall cluttered with metal)
NLOS_V2_SHIFTED = {"onset_rate_range": (1.0, 2.0), "mean_bias_range": (0.5, 1.5), "link_fraction": 1.0}
#: UWB two-way ranging reaches an anchor within this distance in the v2 Scale hall: a DW1000 at
#: its 6.8 Mb/s indoor setting holds a reliable link to about 10–15 m through a cluttered hall;
#: 11 m reaches the near-wall anchors from anywhere on the 6 m circle and none across the hall
SCALE_ANCHOR_RANGE = 11.0
#: the v2 Scale sizes; the randomized variant flies 8 UAVs, its shifted split 16
SCALE_SIZES = (8, 16, 32)
#: a fourth anchor for the CascadedFault course, 8 m above its centre: v1's three anchors lie within
#: 0–2 m of the flight band, so the vertical was unobservable from them (oracle 1.79 m before any fault
#: against a bound of 0.28 m)
CASCADED_TOP_ANCHOR = (0.0, 0.0, 8.0)
#: VisionLoss-v2: the UAVs whose camera fails in each outage (half the swarm, every second UAV)
VISION_BLIND = (0, 2, 4)
#: VisionLossRandomShifted-v2: the other half (the shift is which UAVs go blind, and how long)
VISION_BLIND_SHIFTED = (1, 3, 5)
SPLIT_CI = {"peer_update": "split_ci"}


def _v2(base: TaskSpec, track: str, **changes) -> TaskSpec:
    """``base`` as version 2 on track ``track`` with split covariance intersection and ``changes`` applied, validated."""
    data = {**base.model_dump(), "version": 2, "track": track, **changes}
    data["filter"] = {**data["filter"], **SPLIT_CI}
    return TaskSpec.model_validate(data)


def _nlos(targets: tuple[str, ...], **ranges) -> dict:
    """The v2 NLOS process on ``targets`` (with ``ranges``: its randomized draws), as a ``faults`` dict."""
    params = {**NLOS_V2, **ranges}
    if "peer" not in targets:
        params.pop("peer_state")
    return {"nlos_gauss_markov": NlosGaussMarkov(targets=targets, **params).model_dump()}


# --------------------------------------------------------------------------- cooperative


def scale_v2(n: int) -> Callable[[], TaskSpec]:
    def make() -> TaskSpec:
        base = scale(n)()
        sensors = {**base.sensors.model_dump(), "anchor_max_range": SCALE_ANCHOR_RANGE}
        return _v2(base, "cooperative", sensors=sensors, faults=_nlos(("anchor", "peer")))
    make.__doc__ = f"""{n} UAVs circling in the 20 × 20 m hall with eight wall anchors that reach {SCALE_ANCHOR_RANGE:g} m.

    Scale{n}-v1's hall, course and sensors (ranges σ 0.2 m), with two changes. The anchors are
    ranged only within {SCALE_ANCHOR_RANGE:g} m (``SCALE_ANCHOR_RANGE``), so a UAV sees the anchors
    of its side of the hall and learns the rest from the UAVs across the circle: the peers carry
    information (with every peer removed the bound rises; ``docs/calibration-v2.json``). And the
    NLOS process fitted to the UTIL obstacle flight (``NLOS_V2``) acts on anchor and peer links alike,
    one state per peer link.
    """
    return make


def scale_random_v2() -> TaskSpec:
    """Scale8-v2 with the NLOS onset rate, mean bias and prone links drawn per episode (``NLOS_V2_TRAIN``)."""
    base = scale_v2(8)()
    return _v2(base, "cooperative", name="ScaleRandom", faults=_nlos(("anchor", "peer"), **NLOS_V2_TRAIN))


def scale_random_shifted_v2() -> TaskSpec:
    """ScaleRandom-v2 shifted: sixteen UAVs instead of eight, denser and larger biases (``NLOS_V2_SHIFTED``)."""
    base = scale_v2(16)()
    return _v2(base, "cooperative", name="ScaleRandomShifted",
               faults=_nlos(("anchor", "peer"), **NLOS_V2_SHIFTED))


def _with_top_anchor(base: TaskSpec) -> tuple:
    return tuple(base.anchors) + (CASCADED_TOP_ANCHOR,)


def cascaded_fault_v2() -> TaskSpec:
    """CascadedFault-v1 (madrl Exp. 5: UAVs 1 and 2 blind with a biased IMU, 20–35 s) with a fourth anchor 8 m up.

    v1's three anchors stand within 0–2 m of the flight band, so their ranges do not fix the
    height: the error was mostly vertical before any fault. The fourth anchor
    (``CASCADED_TOP_ANCHOR``, on the ceiling above the course's centre) makes the healthy
    UAVs' anchor fix three-dimensional, so what the fault costs them is what their peers
    bring.
    """
    base = cascaded_fault_v1()
    return _v2(base, "cooperative", anchors=_with_top_anchor(base))


def cascaded_fault_random_v2() -> TaskSpec:
    """CascadedFaultRandom-v1 (which two UAVs fail, when, how long, how hard: drawn per episode) with the fourth anchor."""
    base = cascaded_fault_random_v1()
    return _v2(base, "cooperative", anchors=_with_top_anchor(base))


def cascaded_fault_random_shifted_v2() -> TaskSpec:
    """CascadedFaultRandomShifted-v1 (weaker, longer IMU faults than training) with the fourth anchor."""
    base = cascaded_fault_random_shifted_v1()
    return _v2(base, "cooperative", anchors=_with_top_anchor(base))


def vision_loss_v2() -> TaskSpec:
    """VisionLoss-v1 (Indoor-v1's hall, camera, IMU and swarm) with the cameras of every second UAV lost.

    dtvirm §4.3 loses vision on some UAVs, not on the swarm at once: here UAVs 0, 2 and 4
    (``VISION_BLIND``) lose their camera 30–40 s and 60–70 s while UAVs 1, 3 and 5 still see
    landmarks, so the blind UAVs' peer ranges to the seeing ones carry what the landmarks no
    longer do. (v1 blinded the whole swarm, which left cooperation nothing to do: every trust
    method was within 2 % of uniform.)
    """
    base = vision_loss_v1()
    outage = VisionOutage(windows=base.faults.vision_outage.windows, nodes=VISION_BLIND)
    return _v2(base, "cooperative", faults={**base.faults.model_dump(), "vision_outage": outage.model_dump()})


def _vision_random(base: TaskSpec, nodes: tuple[int, ...]) -> TaskSpec:
    faults = base.faults.model_dump()
    faults["vision_outage_random"] = {**faults["vision_outage_random"], "nodes": nodes}
    return _v2(base, "cooperative", faults=faults)


def vision_loss_random_v2() -> TaskSpec:
    """VisionLossRandom-v1's outages (1–2 of 5–10 s, drawn per episode) on UAVs 0, 2 and 4 only."""
    return _vision_random(vision_loss_random_v1(), VISION_BLIND)


def vision_loss_random_shifted_v2() -> TaskSpec:
    """VisionLossRandomShifted-v1's longer outages (2–3 of 10–20 s) on the other half of the swarm, UAVs 1, 3 and 5."""
    return _vision_random(vision_loss_random_shifted_v1(), VISION_BLIND_SHIFTED)


#: GradualFault-v2: three leaders with a GNSS receiver, three followers without one
FEDERATED_LEADERS = (0, 1, 2)
FEDERATED_FOLLOWERS = (3, 4, 5)
#: the leaders' GNSS error is a Gauss–Markov process with this correlation time [s]: a single-frequency
#: receiver's position error (ionosphere, multipath, orbit and clock) is correlated over minutes; the measured
#: autocorrelation of a consumer receiver bends at about one minute (``Sensors.gps_correlation_time``'s sources)
FEDERATED_GPS_TAU = 60.0


def gradual_fault_v2() -> TaskSpec:
    """Three leaders with GNSS and three followers without it, in GradualFault-v1's formation; one leader's fix drifts.

    federated §5's formation and drift, with the followers GNSS-denied (under a canopy, in a
    jammed band): six UAVs fly the slow turning line 100 m up, leaders 0, 1, 2 in front
    (``FEDERATED_LEADERS``), followers 3, 4, 5 (``FEDERATED_FOLLOWERS``) further out on the
    sides. Each follower measures its position relative to every leader, and the leaders to
    each other (UWB range and angle of arrival, σ 1.5 m per axis at 30 m, GradualFault-v1's);
    only the leaders have a fix (σ 1 m per axis, the paper's leader receiver), whose error is
    correlated in time (Gauss–Markov, τ ``FEDERATED_GPS_TAU`` s) as a real receiver's is. From
    100 s to 200 s leader 0's fix drifts at 0.1 m/s per axis (the paper's drift; the offset
    stays after the window). The followers are scored: everything they know of where they
    are comes through the leaders, so a method must tell the drifting leader from the two
    that agree.
    """
    base = gradual_fault_v1()
    n = len(FEDERATED_LEADERS) + len(FEDERATED_FOLLOWERS)
    sensors = base.sensors.model_dump()
    sensors.update(gps_sigma=(1.0,) * n, gps_nodes=FEDERATED_LEADERS, gps_correlation_time=FEDERATED_GPS_TAU)
    sensors["peers"] = {**sensors["peers"], "leaders": FEDERATED_LEADERS}
    drift = base.faults.gps_drifts[0].model_dump()
    drift["nodes"] = (0,)
    return _v2(base, "cooperative", n_uav=n, sensors=sensors, faults={"gps_drifts": [drift]},
               scoring={**base.scoring.model_dump(), "nodes": FEDERATED_FOLLOWERS})


def _gradual_random(name: str, drift: dict) -> TaskSpec:
    base = gradual_fault_v2()
    random = GpsDriftRandom(**{**drift, "nodes": FEDERATED_LEADERS, "n_drifting_range": (1, 1)})
    return _v2(base, "cooperative", name=name, faults={"gps_drift_random": random.model_dump()},
               scoring={**base.scoring.model_dump(), "fault_window": None})


def gradual_fault_random_v2() -> TaskSpec:
    """GradualFault-v2 with the drift drawn per episode: which leader, when (50–150 s), how long (50–100 s), how fast
    (0.05–0.25 m/s) and where to (GradualFaultRandom-v1's ranges, one leader of three)."""
    return _gradual_random("GradualFaultRandom", GPS_DRIFT_TRAIN)


def gradual_fault_random_shifted_v2() -> TaskSpec:
    """GradualFaultRandom-v2 shifted: a spoofer's drag-off at 0.3–0.5 m/s (GradualFaultRandomShifted-v1's)."""
    return _gradual_random("GradualFaultRandomShifted", GPS_DRIFT_SHIFTED)


# --------------------------------------------------------------------------- robust ranging


def anchor_nlos_v2() -> TaskSpec:
    """One UAV on the Ideal course among the eight anchors of NLOS-v1, its anchor links under the UTIL-fitted NLOS.

    The single-UAV board: no peers, so what a method gains is what it makes of eight anchor
    ranges (σ 0.15 m) under the NLOS process fitted to the UTIL obstacle flight (``NLOS_V2``),
    with a 0.1 m/s² IMU.
    """
    base = ideal()
    return _v2(base, "robust-ranging", name="AnchorNLOS", n_uav=1, anchors=EIGHT_ANCHORS,
               sensors={**base.sensors.model_dump(), "peers": {"kind": "none"}}, faults=_nlos(("anchor",)))


def anchor_nlos_random_v2() -> TaskSpec:
    """AnchorNLOS-v2 with the NLOS onset rate, mean bias and prone anchors drawn per episode (``NLOS_V2_TRAIN``)."""
    return _v2(anchor_nlos_v2(), "robust-ranging", name="AnchorNLOSRandom", faults=_nlos(("anchor",),
                                                                                        **NLOS_V2_TRAIN))


def anchor_nlos_random_shifted_v2() -> TaskSpec:
    """AnchorNLOSRandom-v2 shifted: every anchor NLOS-prone, denser and larger biases (``NLOS_V2_SHIFTED``)."""
    return _v2(anchor_nlos_v2(), "robust-ranging", name="AnchorNLOSRandomShifted",
               faults=_nlos(("anchor",), **NLOS_V2_SHIFTED))


def tdoa_v2() -> TaskSpec:
    """TDOA-v1's room (eight anchors, TDOA2 ring pairs, packet loss) flown by one UAV, its pair NLOS fitted to UTIL.

    The simulated counterpart of the real UTIL TDOA flights (one Crazyflie each): the UAV on
    the 1.0 m circle, and the NLOS process of each anchor pair the one fitted to the UTIL TDOA
    flights among obstacles (``UTIL_NLOS_TDOA``: 0.22 onsets per second, episodes of about 1 s,
    mean 0.52 m, σ 0.85 m, τ 0.17 s) instead of TDOA-v1's hand-chosen one; everything else as TDOA-v1.
    """
    return _v2(tdoa(), "robust-ranging", n_uav=1, faults={
        **tdoa().faults.model_dump(), "nlos_gauss_markov": NlosGaussMarkov(targets=("anchor",),
                                                                           **UTIL_NLOS_TDOA).model_dump()})


#: registered ID → spec factory, the v2 tasks (``tasks.CATALOGUE`` includes them)
CATALOGUE_V2: dict[str, Callable[[], TaskSpec]] = {
    **{f"swarmloc/Scale{n}-v2": scale_v2(n) for n in SCALE_SIZES},
    "swarmloc/ScaleRandom-v2": scale_random_v2,
    "swarmloc/ScaleRandomShifted-v2": scale_random_shifted_v2,
    "swarmloc/CascadedFault-v2": cascaded_fault_v2,
    "swarmloc/CascadedFaultRandom-v2": cascaded_fault_random_v2,
    "swarmloc/CascadedFaultRandomShifted-v2": cascaded_fault_random_shifted_v2,
    "swarmloc/VisionLoss-v2": vision_loss_v2,
    "swarmloc/VisionLossRandom-v2": vision_loss_random_v2,
    "swarmloc/VisionLossRandomShifted-v2": vision_loss_random_shifted_v2,
    "swarmloc/GradualFault-v2": gradual_fault_v2,
    "swarmloc/GradualFaultRandom-v2": gradual_fault_random_v2,
    "swarmloc/GradualFaultRandomShifted-v2": gradual_fault_random_shifted_v2,
    "swarmloc/AnchorNLOS-v2": anchor_nlos_v2,
    "swarmloc/AnchorNLOSRandom-v2": anchor_nlos_random_v2,
    "swarmloc/AnchorNLOSRandomShifted-v2": anchor_nlos_random_shifted_v2,
    "swarmloc/TDOA-v2": tdoa_v2,
}

_SCALE_HISTORY = ("v2: anchors ranged within 11 m and the NLOS process fitted to the UTIL obstacle flight on anchor "
                  "and peer links (one state per peer link), peers fused by split covariance intersection "
                  "(benchmark v2: the peers carry information).")
#: the Version History line of each v2 task (task_envs adds it)
HISTORY_V2: dict[str, str] = {
    **{f"swarmloc/Scale{n}-v2": _SCALE_HISTORY for n in SCALE_SIZES},
    "swarmloc/ScaleRandom-v2": _SCALE_HISTORY,
    "swarmloc/ScaleRandomShifted-v2": _SCALE_HISTORY,
    **{task: "v2: a fourth anchor 8 m above the course (v1's three lay in the flight band: the height was "
             "unobservable), peers fused by split covariance intersection."
       for task in ("swarmloc/CascadedFault-v2", "swarmloc/CascadedFaultRandom-v2",
                    "swarmloc/CascadedFaultRandomShifted-v2")},
    **{task: "v2: the cameras of half the swarm fail, not every camera at once (dtvirm §4.3), peers fused by split "
             "covariance intersection."
       for task in ("swarmloc/VisionLoss-v2", "swarmloc/VisionLossRandom-v2", "swarmloc/VisionLossRandomShifted-v2")},
    **{task: "v2: three leaders with GNSS (its error correlated in time, τ 60 s) and three GNSS-denied followers "
             "that lean on them, one leader's fix drifting, peers fused by split covariance intersection (v1: one "
             "leader, followers with their own GPS)."
       for task in ("swarmloc/GradualFault-v2", "swarmloc/GradualFaultRandom-v2",
                    "swarmloc/GradualFaultRandomShifted-v2")},
    **{task: "v2: new, the robust-ranging board's simulated anchor NLOS (one UAV)."
       for task in ("swarmloc/AnchorNLOS-v2", "swarmloc/AnchorNLOSRandom-v2", "swarmloc/AnchorNLOSRandomShifted-v2")},
    "swarmloc/TDOA-v2": "v2: one UAV (the robust-ranging board) instead of four without peers, and the pair NLOS "
                        "process fitted to the UTIL TDOA flights.",
}
