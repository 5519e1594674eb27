"""GNSS in the world: which UAVs carry a receiver, several leaders, and GNSS error correlated in time.

``Sensors.gps_nodes`` (a UAV without a receiver keeps its GPS slot, never valid),
``PeerLinks.leaders`` (followers link to every leader, leaders to each other) and
``Sensors.gps_correlation_time`` (a first-order Gauss–Markov error per axis: stationary
variance σ², lag-1 autocorrelation φ = exp(−dt/τ)), each against its closed form, plus the
spec's refusals and the canonical JSON of every registered task (the new fields stay out of
it at their defaults). Small worlds on the serial kernel only: the whole file runs in seconds.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pydantic
import pytest

from swarmloc.envs.tasks.catalogue import CATALOGUE, get_spec
from swarmloc.envs.tasks.channels import GPS, PEER_REL, build_layout
from swarmloc.envs.tasks.docs import _measurement_model
from swarmloc.envs.tasks.specs import LeaderFollowerLine, PeerLinks, Sensors, TaskSpec
from swarmloc.envs.world.sim import World

GRADUAL = "swarmloc/GradualFault-v1"


def markov_spec(n_uav: int = 1, tau: float = 5.0, sigma: float = 2.0, duration: float = 50.0, **sensors) -> TaskSpec:
    """GPS only (no peers), per-axis σ ``sigma`` and time constant ``tau``, dt = 1 s."""
    return TaskSpec(name="GnssMarkov", n_uav=n_uav, dt=1.0, duration=duration, trajectory=LeaderFollowerLine(),
                    sensors=Sensors(gps_sigma=(sigma,) * n_uav, gps_correlation_time=tau,
                                    peers=PeerLinks(kind="none"), **sensors))


def gps_errors(world: World, n_steps: int) -> np.ndarray:
    """``(T, B, N, 3)`` the GPS fix minus the truth over ``n_steps`` sensed steps."""
    col = int(np.flatnonzero(world.layout.kind[0] == GPS)[0])
    out = np.empty((n_steps, world.batch_size, world.spec.n_uav, 3))
    for k in range(n_steps):
        buf = world.sense()
        out[k] = buf.z[:, :, col] - buf.pos
    return out


# --------------------------------------------------------------------------- canonical JSON


def test_new_fields_stay_out_of_every_registered_specs_json():
    # the v0 and v1 specs (and their suites' hashes) predate the fields; the GradualFault-v2 family uses them
    for task_id in CATALOGUE:
        spec = get_spec(task_id)
        text = spec.model_dump_json()
        uses = spec.version >= 2 and spec.name.startswith("GradualFault")
        for name in ("gps_nodes", "gps_correlation_time", "leaders"):
            assert (f'"{name}"' in text) == uses, (task_id, name)


def test_new_fields_round_trip_through_json():
    spec = get_spec(GRADUAL, n_uav=5, sensors={"gps_nodes": [0, 3], "gps_sigma": [1.0, 3.0, 3.0, 1.0, 3.0],
                                               "gps_correlation_time": 60.0, "peers": {"leaders": [0, 3]}},
                    faults={"gps_drifts": []})
    data = json.loads(spec.model_dump_json())
    assert data["sensors"]["gps_nodes"] == [0, 3] and data["sensors"]["gps_correlation_time"] == 60.0
    assert data["sensors"]["peers"]["leaders"] == [0, 3]
    assert TaskSpec.model_validate_json(spec.model_dump_json()) == spec


# --------------------------------------------------------------------------- receivers


def test_a_uav_without_a_receiver_keeps_its_slot_and_is_never_valid():
    spec = get_spec(GRADUAL, sensors={"gps_nodes": [0]}, faults={"gps_drifts": []})
    base = build_layout(get_spec(GRADUAL))
    layout = build_layout(spec)
    assert np.array_equal(layout.kind, base.kind) and np.array_equal(layout.sigma, base.sigma)
    gps = layout.kind == GPS
    assert layout.linked[gps].tolist() == [True, False, False]
    world = World(spec, 4)
    world.reset([0, 1, 2, 3])
    valid = np.array([world.sense().valid.copy() for _ in range(40)])  # (T, B, N, L)
    col = int(np.flatnonzero(gps[0])[0])
    assert valid[:, :, 0, col].all() and not valid[:, :, 1:, col].any()


@pytest.mark.parametrize("sensors, faults, message", [
    ({"gps_nodes": [0, 3]}, {"gps_drifts": []}, r"gps_nodes contains \[3\]; UAV indices must be in \[0, 2\]"),
    ({"gps_nodes": [0, 0]}, {"gps_drifts": []}, r"gps_nodes=\(0, 0\) lists a UAV twice"),
    ({"gps_nodes": [0]}, {}, r"gps_drifts\[0\]\.nodes=\(1, 2\) includes UAVs \[1, 2\] without a GNSS receiver"),
    ({"gps_nodes": [0, 1]}, {"gps_drifts": [], "gps_drift_random": {"nodes": [1, 2]}},
     r"gps_drift_random\.nodes=\(1, 2\) includes UAVs \[2\] without a GNSS receiver"),
    ({"gps_nodes": [0, 1, 2][:2]}, {"gps_drifts": [], "hybrid_noise": {"ratio": 0.3}},
     r"hybrid_noise\.nodes=\(\) \(every UAV\) includes UAVs \[2\]"),
    ({"gps_correlation_time": 30.0}, {"gps_drifts": [], "hybrid_noise": {"ratio": 0.3, "nodes": [1]}},
     r"gps_correlation_time=30\.0 with faults\.hybrid_noise is not modelled"),
    ({"gps_correlation_time": -1.0}, {}, r"greater than or equal to 0"),
    ({"peers": {"leaders": [0, 5]}}, {}, r"leaders contains \[5\]; UAV indices must be in \[0, 2\]"),
    ({"peers": {"leaders": [1, 1]}}, {}, r"leaders=\(1, 1\) lists a UAV twice"),
    ({"peers": {"leaders": []}}, {}, r"at least 1 item"),
    ({"peers": {"leaders": [0, 1], "topology": "all"}}, {}, r"leaders=\(0, 1\) needs topology='leader'"),
])
def test_refusals_name_the_value_and_the_allowed_range(sensors, faults, message):
    with pytest.raises(pydantic.ValidationError, match=message):
        get_spec(GRADUAL, sensors=sensors, faults=faults)


def test_receivers_and_correlation_need_a_gps_slot():
    for sensors in ({"gps_nodes": [0]}, {"gps_correlation_time": 10.0}):
        with pytest.raises(pydantic.ValidationError, match="need sensors.gps_sigma"):
            get_spec("swarmloc/Ideal-v0", sensors=sensors)


# --------------------------------------------------------------------------- leaders


def peer_links(spec: TaskSpec) -> set[tuple[int, int]]:
    """(receiver, neighbour) of every linked peer slot."""
    layout = build_layout(spec)
    hit = (layout.kind == PEER_REL) & layout.linked
    return {(int(i), int(layout.target[i, l])) for i, l in zip(*np.nonzero(hit))}


def test_one_leader_links_as_before():
    spec = get_spec(GRADUAL, n_uav=5, sensors={"gps_sigma": [1.0] + [3.0] * 4})
    assert spec.sensors.peers.leaders == (0,)
    assert peer_links(spec) == {(i, 0) for i in range(1, 5)}


def test_followers_link_to_every_leader_and_leaders_to_each_other():
    spec = get_spec(GRADUAL, n_uav=6, sensors={"gps_sigma": [1.0] * 6, "peers": {"leaders": [4, 1]}})
    leaders, followers = {1, 4}, {0, 2, 3, 5}
    assert peer_links(spec) == {(f, j) for f in followers for j in leaders} | {(1, 4), (4, 1)}


# --------------------------------------------------------------------------- Gauss–Markov error


def test_markov_error_has_the_stationary_variance_and_lag_one_autocorrelation():
    tau, sigma, n_t, n_b = 5.0, 2.0, 4000, 8
    phi = math.exp(-1.0 / tau)
    world = World(markov_spec(tau=tau, sigma=sigma, duration=float(n_t)), n_b)
    world.reset(np.arange(n_b) + 100)
    e = gps_errors(world, n_t)[:, :, 0, :] / sigma  # (T, B, 3), unit stationary variance
    n = e.size
    var = float(np.mean(e * e))
    # var(s²) of an AR(1) sample of n: 2/n · (1 + φ²)/(1 − φ²); var(r₁) ≈ (1 − φ²)/n
    assert abs(var - 1.0) < 4.0 * math.sqrt(2.0 / n * (1 + phi**2) / (1 - phi**2)), var
    r1 = float(np.sum(e[1:] * e[:-1]) / np.sum(e[:-1] * e[:-1]))
    assert abs(r1 - phi) < 4.0 * math.sqrt((1 - phi**2) / n), (r1, phi)
    assert abs(float(np.mean(e))) < 4.0 * math.sqrt((1 + phi) / (1 - phi) / n)


def test_markov_error_is_stationary_from_the_first_step():
    # e_1 = φ e_0 + σ√(1−φ²) n_1 has variance σ² only if e_0 ~ N(0, σ²): a cold start (e_0 = 0) gives 1 − φ²
    tau, n_b, rounds = 20.0, 16, 60
    world = World(markov_spec(tau=tau, sigma=1.0, duration=2.0), n_b)
    first = []
    for r in range(rounds):
        world.reset(np.arange(n_b) + 1000 * r)
        first.append(gps_errors(world, 1)[0])
    e = np.array(first)
    assert abs(float(np.mean(e * e)) - 1.0) < 4.0 * math.sqrt(2.0 / e.size), float(np.mean(e * e))


def test_markov_error_batched_equals_single_and_partial_reset():
    spec = markov_spec(n_uav=3, tau=30.0, duration=60.0)
    seeds = [5, 17, 2**40, 3]
    batched = World(spec, len(seeds))
    batched.reset(seeds)
    together = gps_errors(batched, 30)
    for b, seed in enumerate(seeds):
        single = World(spec, 1)
        single.reset([seed])
        assert np.array_equal(gps_errors(single, 30)[:, 0], together[:, b]), seed
    # a partial reset restarts episode 2 from its new seed; the others run on untouched
    batched.reset([0, 0, 99, 0], mask=np.array([False, False, True, False]))
    after = gps_errors(batched, 10)
    fresh = World(spec, 1)
    fresh.reset([99])
    assert np.array_equal(after[:, 2], gps_errors(fresh, 10)[:, 0])
    rest = World(spec, 1)
    rest.reset([seeds[0]])
    assert np.array_equal(after[:, 0], gps_errors(rest, 40)[30:, 0])


def test_markov_error_is_noise_not_a_fault():
    world = World(markov_spec(n_uav=2, tau=60.0, sigma=1.5, duration=40.0), 3)
    world.reset([1, 2, 3])
    for _ in range(40):
        buf = world.sense()
        assert not buf.systematic.any() and not buf.injected.any()
        assert not buf.label.any() and not buf.error_label.any()


def test_measurement_model_names_receivers_leaders_and_correlation():
    spec = get_spec(GRADUAL, n_uav=4, sensors={"gps_sigma": [1.0, 3.0, 3.0, 1.0], "gps_nodes": [0, 3],
                                               "gps_correlation_time": 60.0, "peers": {"leaders": [0, 3]}},
                    faults={"gps_drifts": []})
    text = _measurement_model(spec)
    assert "position fix on UAVs [0, 3]" in text and "UAVs [1, 2] are never valid" in text
    assert "τ = 60 s" in text and f"{math.exp(-1 / 60):.3g}" in text
    assert "leaders [0, 3]" in text
    assert "gps_nodes" not in text and "gps_correlation_time" not in text  # described, not listed raw
    plain = _measurement_model(get_spec(GRADUAL))
    assert "GPS: position fix per UAV, σ = [1.0, 3.0, 3.0] m." in plain and "leaders" not in plain
