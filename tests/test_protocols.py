"""Method protocols: no truth or labels reach a method; TrustEstimator == the env's core; loading."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from swarmloc.agents.estimators.dead_reckoning import DeadReckoning
from swarmloc.agents.protocols import (
    Estimator,
    EstimatorOutput,
    LinkTrustPolicy,
    Measurements,
    PrivilegedInfo,
    TaskFacts,
    TrustInput,
    episode_keys,
)
from swarmloc.agents.registry import REGISTRY, LoadedMethod, load_method, method_names
from swarmloc.agents.estimators.trust_estimator import TrustEstimator
from swarmloc.bench.evaluation.runner import rollout
from swarmloc.envs.tasks.catalogue import get_spec
from swarmloc.envs.world.sim import World

FORBIDDEN = {"truth", "pos", "vel", "label", "labels", "injected", "schedule", "spec", "seeds", "seed"}
SEEDS = [1_000_000, 1_000_001, 1_000_002]


def _facts(task: str = "swarmloc/NLOS-v0") -> tuple[World, TaskFacts]:
    spec = get_spec(task, duration=2.0)
    world = World(spec, len(SEEDS))
    x0 = world.reset(SEEDS).copy()
    return world, TaskFacts.from_spec(spec, world.layout, x0, episode_keys(SEEDS))


@pytest.mark.parametrize("cls", [TaskFacts, Measurements, TrustInput, EstimatorOutput])
def test_method_inputs_have_no_truth_or_label_field(cls):
    names = {f.name for f in dataclasses.fields(cls)}
    assert not names & FORBIDDEN
    assert hasattr(cls, "__slots__")


def test_measurements_are_frozen_and_read_only():
    world, _ = _facts()
    buf = world.sense()
    meas = Measurements.capture(buf.imu, buf.z, buf.valid, 0.1, 1)
    with pytest.raises(AttributeError):
        meas.truth  # noqa: B018 - the point of the test
    # no slot for it (Python 3.11's frozen+slots dataclasses raise TypeError here, 3.12 AttributeError)
    with pytest.raises((AttributeError, TypeError)):
        meas.truth = buf.pos  # type: ignore[attr-defined]
    with pytest.raises(dataclasses.FrozenInstanceError):
        meas.z = buf.z  # type: ignore[misc]
    with pytest.raises(ValueError, match="read-only"):
        meas.z[0, 0, 0, 0] = 1.0
    # a snapshot: the world moving on does not change it
    z0 = meas.z.copy()
    world.sense()
    np.testing.assert_array_equal(meas.z, z0)


def test_facts_are_read_only():
    _, facts = _facts()
    with pytest.raises(ValueError, match="read-only"):
        facts.x0[0, 0, 0] = 0.0
    with pytest.raises(AttributeError):
        facts.schedule  # noqa: B018


class _TruthReader(DeadReckoning):
    """An estimator that tries to look at the truth."""

    def step(self, meas: Measurements) -> EstimatorOutput:
        return EstimatorOutput(positions=np.asarray(meas.truth))  # type: ignore[attr-defined]


def _loaded(method, track="B", privileged=False) -> LoadedMethod:
    return LoadedMethod(name=type(method).__name__, entry_point="test", track=track, privileged=privileged,
                        deterministic=True, method=method)


def test_an_estimator_reading_truth_fails():
    spec = get_spec("swarmloc/Ideal-v0", duration=1.0)
    with pytest.raises(AttributeError, match="truth"):
        rollout(_loaded(_TruthReader()), spec, SEEDS)


def test_protocols_runtime_checkable():
    assert isinstance(DeadReckoning(), Estimator)
    assert isinstance(load_method("huber").method, LinkTrustPolicy)
    assert isinstance(TrustEstimator(load_method("huber").method), Estimator)


class _InjectedFaultOracle:
    """A privileged policy on the world's injected-fault labels (``PrivilegedInfo.labels``), the same on
    both tracks: α_min on a labelled channel, else 1."""

    privileged = True
    flops_per_channel = 0.0

    def reset(self, batch_size, layout, keys):
        self._labels = None

    def observe_privileged(self, info: PrivilegedInfo) -> None:
        self._labels = np.asarray(info.labels, dtype=bool).copy()

    def act(self, inp):
        return np.where(self._labels, 0.01, 1.0)


def _injected_fault_oracle() -> LoadedMethod:
    return LoadedMethod(name="injected-fault-oracle", entry_point="test", track="A", privileged=True,
                        deterministic=True, method=_InjectedFaultOracle())


# ``oracle`` (error labels) differs between the tracks by design: on Track A its peer labels carry the
# neighbour's broadcast-estimate error, which only the core knows; on Track B it gets the world's
# error labels of the measurements' own errors (test_track_b_gets_the_world_labels)
@pytest.mark.parametrize("name", ["chi2-soft", "random", "huber+smooth", "injected-fault-oracle"])
def test_trust_estimator_equals_the_core(name):
    """A policy gives the same episode through LinkTrustCore (Track A) and TrustEstimator (Track B)."""
    spec = get_spec("swarmloc/NLOS-v0", duration=8.0)
    make = _injected_fault_oracle if name == "injected-fault-oracle" else lambda: load_method(name)
    core, _ = rollout(make(), spec, SEEDS)
    loaded = make()
    est = _loaded(TrustEstimator(loaded.method), privileged=loaded.privileged)
    track_b, _ = rollout(est, spec, SEEDS)
    for a, b in zip(core, track_b):
        for key in ("rmse", "max_error", "jitter", "weight_var", "anomaly_detection_rate", "delay_ms",
                    "team_return"):
            assert a[key] == pytest.approx(b[key], rel=1e-12, abs=1e-15), key


def test_privileged_info_only_for_privileged_methods():
    calls = []

    class Spy(DeadReckoning):
        def observe_privileged(self, info: PrivilegedInfo) -> None:
            calls.append(info)

    spec = get_spec("swarmloc/NLOS-v0", duration=0.5)
    rollout(_loaded(Spy(), privileged=False), spec, SEEDS)
    assert calls == []
    rollout(_loaded(Spy(), privileged=True), spec, SEEDS)
    assert len(calls) == spec.n_steps and calls[0].labels.shape == (len(SEEDS), spec.n_uav, spec.n_channels)


def test_track_b_gets_the_world_labels():
    """A privileged estimator gets the world's injected-fault and error labels of the very step it is given."""
    seen = []

    class Spy(DeadReckoning):
        def observe_privileged(self, info: PrivilegedInfo) -> None:
            seen.append((info.labels.copy(), info.error_labels.copy(), info.systematic_sigmas))

    spec = get_spec("swarmloc/NLOS-v0", duration=3.0)
    rollout(_loaded(Spy(), privileged=True), spec, SEEDS)
    world = World(spec, len(SEEDS))
    world.reset(SEEDS)
    for injected, error, sigmas in seen:
        buf = world.sense()
        assert np.array_equal(injected, buf.label) and np.array_equal(error, buf.error_label) and sigmas is None
    assert any(error.any() for _, error, _ in seen)


def test_registry_metadata_and_loading(tmp_path):
    assert method_names()[0] == "uniform"
    assert "oracle" not in method_names(include_privileged=False)
    for name in ("uniform", "fixed", "huber", "chi2-gate", "chi2-soft", "federated-coef", "random",
                 "dead-reckoning", "oracle"):
        loaded = load_method(name)
        entry = REGISTRY[name]
        assert (loaded.track, loaded.privileged, loaded.deterministic) == (entry.track, entry.privileged,
                                                                          entry.deterministic)
    with pytest.raises(KeyError, match="registered: uniform"):
        load_method("no-such-method")
    with pytest.raises(ValueError, match="Track A"):
        load_method("dead-reckoning+smooth")
    user = tmp_path / "my_method.py"
    user.write_text(
        "import numpy as np\n"
        "class Half:\n"
        "    privileged = False\n"
        "    flops_per_channel = 1.0\n"
        "    def reset(self, batch_size, layout, keys):\n"
        "        pass\n"
        "    def act(self, inp):\n"
        "        return np.full(inp.valid.shape, 0.5)\n"
        "def make(weights=None):\n"
        "    return Half()\n"
    )
    loaded = load_method(f"{user}:make")
    assert (loaded.name, loaded.track, loaded.privileged) == ("make", "A", False)
    with pytest.raises(AttributeError, match="nope"):
        load_method(f"{user}:nope")
    with pytest.raises(TypeError, match="takes no 'weights'"):
        load_method("uniform", weights=user)


def test_load_method_hands_the_benchmark_version_to_factories_that_take_it(tmp_path):
    """``version=`` reaches a factory with a named ``version`` parameter and is left out otherwise, also for a
    ``**overrides`` of settings (imm-arkf's would reject it)."""
    from swarmloc.agents.registry import shipped_for_version

    user = tmp_path / "versioned.py"
    user.write_text(
        "import numpy as np\n"
        "class Const:\n"
        "    privileged = False\n"
        "    def __init__(self, version):\n"
        "        self.version = version\n"
        "    def reset(self, batch_size, layout, keys):\n"
        "        pass\n"
        "    def act(self, inp):\n"
        "        return np.ones(inp.valid.shape)\n"
        "def with_version(weights=None, version=None):\n"
        "    return Const(version)\n"
        "def with_kwargs(**kwargs):\n"
        "    return Const(kwargs.get('version'))\n"
        "def plain():\n"
        "    return Const('none taken')\n"
    )
    assert load_method(f"{user}:with_version", version=1).method.version == 1
    assert load_method(f"{user}:with_version").method.version is None
    assert load_method(f"{user}:with_kwargs", version=0).method.version is None
    assert load_method("imm-arkf", version=1).track == "B"
    assert load_method(f"{user}:plain", version=1).method.version == "none taken"
    table = {0: tmp_path / "v0.pt", 1: tmp_path / "v1.pt"}
    assert shipped_for_version(table, None) == table[1]
    assert [shipped_for_version(table, v) for v in (0, 1, 7)] == [table[0], table[1], table[1]]
    for bad in (-1, True, 1.0, "1"):
        with pytest.raises(ValueError, match="version must be an int >= 0"):
            shipped_for_version(table, bad)
