"""Task specs reject bad values with messages naming the field and the allowed range."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from swarmloc.envs.tasks.specs import ImuCascade, NlosStep, TaskSpec
from swarmloc.envs.tasks.catalogue import get_spec


def base(**changes) -> dict:
    data = get_spec("swarmloc/CascadedFault-v0").model_dump()
    data.update(changes)
    return data


@pytest.mark.parametrize("changes, needle", [
    ({"n_uav": -1}, "n_uav"),
    ({"n_uav": 0}, "greater than or equal to 1"),
    ({"dt": 0.0}, "dt"),
    ({"dt": -0.1}, "greater than 0"),
    ({"duration": 0.01}, "duration=0.01 must be >= dt"),
    ({"unknown_key": 3}, "unknown_key"),
    ({"anchors": [(0.0, 0.0)]}, "anchors"),
    ({"sensors": {"anchor_sigma": -0.2}}, "anchor_sigma"),
    ({"filter": {"alpha_min": 0.0}}, "alpha_min"),
    ({"filter": {"alpha_th": 1.5}}, "less than or equal to 1"),
    ({"scoring": {"healthy_nodes": (0, 7)}}, "UAV indices must be in [0, 3]"),
    ({"sensors": {"gps_sigma": (1.0,)}}, "expected n_uav=4"),
])
def test_spec_rejects_bad_values(changes, needle):
    with pytest.raises(ValidationError) as info:
        TaskSpec.model_validate(base(**changes))
    assert needle in str(info.value)


def test_fault_windows_validated():
    with pytest.raises(ValidationError, match="end=10.0 must be > start=20.0"):
        NlosStep(index=0, start=20.0, end=10.0, bias=3.0)
    with pytest.raises(ValidationError, match="index"):
        NlosStep(index=-1, start=1.0, end=2.0, bias=3.0)
    with pytest.raises(ValidationError, match="bias"):
        NlosStep(index=0, start=1.0, end=2.0, bias=-3.0)
    with pytest.raises(ValidationError, match="end=1.0 must be > start=5.0"):
        ImuCascade(nodes=(1,), start=5.0, end=1.0)
    with pytest.raises(ValidationError, match="index=9 out of range for anchor"):
        get_spec("swarmloc/NLOSStep-v0", faults={"nlos_steps": [{"index": 9, "start": 1, "end": 2, "bias": 1}]})


def test_specs_are_frozen_and_unknown_task_is_named():
    spec = get_spec("swarmloc/Ideal-v0")
    with pytest.raises(ValidationError):
        spec.n_uav = 3  # type: ignore[misc]
    with pytest.raises(KeyError, match=r"unknown task ID 'swarmloc/Nope-v0'; known: swarmloc/AnchorFree-v0, swarmloc/AnchorNLOS-v2, "):
        get_spec("swarmloc/Nope-v0")


def test_overrides_are_validated_and_derived_quantities_follow():
    spec = get_spec("swarmloc/Ideal-v0", n_uav=6, duration=10.0)
    assert spec.n_steps == 100
    assert spec.n_channels == 6 + 5  # anchors + peers
    with pytest.raises(ValidationError, match="n_uav"):
        get_spec("swarmloc/Ideal-v0", n_uav=-2)


def test_nested_overrides_merge():
    spec = get_spec("swarmloc/NLOS-v0", sensors={"imu_sigma": 0.05})
    assert spec.sensors.imu_sigma == 0.05
    assert spec.sensors.anchor_sigma == get_spec("swarmloc/NLOS-v0").sensors.anchor_sigma


def test_per_episode_healthy_scoring_is_validated():
    healthy = {"nodes_from_schedule": "healthy"}
    assert get_spec("swarmloc/CascadedFaultRandom-v0").scoring.nodes_from_schedule == "all"  # v0 unchanged
    assert get_spec("swarmloc/CascadedFaultRandom-v0", scoring=healthy).scoring.nodes_from_schedule == "healthy"
    with pytest.raises(ValidationError, match="needs an IMU fault"):
        get_spec("swarmloc/Ideal-v0", scoring=healthy)
    with pytest.raises(ValidationError, match="could score no UAV: 2 scored UAV"):
        get_spec("swarmloc/CascadedFaultRandom-v0", scoring={**healthy, "nodes": (0, 1)})
    with pytest.raises(ValidationError, match="could score no UAV: 0 scored UAV"):
        get_spec("swarmloc/CascadedFault-v0", scoring={**healthy, "nodes": (1, 2)})
    with pytest.raises(ValidationError, match="nodes_from_schedule"):
        get_spec("swarmloc/CascadedFaultRandom-v0", scoring={"nodes_from_schedule": "faulty"})


@pytest.mark.parametrize(("task", "changes", "field"), [
    ("swarmloc/NLOS-v1", {"anchors": [[0.0, 0.0, float("nan")]]}, "anchors.0.2"),
    ("swarmloc/VisionLoss-v1", {"landmarks": [[0.0, float("inf"), 1.0]]}, "landmarks.0.1"),
    ("swarmloc/NLOS-v1", {"duration": float("nan")}, "duration"),
    ("swarmloc/NLOS-v1", {"sensors": {"anchor_max_range": float("inf")}}, "sensors.anchor_max_range"),
    ("swarmloc/NLOS-v1", {"trajectory": {"altitude": float("-inf")}}, "trajectory.accel_circle.altitude"),
])
def test_non_finite_numbers_are_refused_naming_the_field(task, changes, field):
    """NaN and ±inf anywhere in a spec (points, vectors, ranges, durations) are refused with the field's path."""
    import gymnasium as gym

    import swarmloc.envs  # noqa: F401

    with pytest.raises(ValidationError, match="finite number") as err:
        get_spec(task, **changes)
    assert field in str(err.value)
    with pytest.raises(ValidationError, match="finite number"):
        gym.make(task, **changes)


def test_every_registered_spec_is_finite():
    """The refusal changes no shipped task: every registered spec still validates."""
    from swarmloc.envs.tasks.catalogue import CATALOGUE

    for task in CATALOGUE:
        spec = get_spec(task)
        assert TaskSpec.model_validate_json(spec.model_dump_json()) == spec
