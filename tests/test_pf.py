"""Particle-filter family and PF-NN (issue 6): kernels vs reference, adaptive count, convergence,
no truth, determinism, FLOPs, the offline fit's seed policy, the oracle, reproduction smoke."""

from __future__ import annotations

import ast
import inspect
import json
from pathlib import Path

import numpy as np
import pytest

from swarmloc.agents.estimators.pf import (ADAPTIVE, FIXED_800, STANDARD, ParticleFilter, PFConfig, PFNNOnlineOracle, core,
                                           make_pfnn)
from swarmloc.agents.estimators.pf.pfnn import SHIPPED_WEIGHTS, PFNNWeights, load_weights, random_weights, shipped_weights
from swarmloc.agents.estimators.pf.reference import ReferenceParticleFilter, systematic_resample_reference, uniform_np
from swarmloc.agents.protocols import Measurements, TaskFacts, episode_keys
from swarmloc.envs.tasks.rng import Stream, uniform
from swarmloc.envs.tasks.catalogue import get_spec
from swarmloc.envs.world.sim import World

PF_DIR = Path(core.__file__).resolve().parent


class Episode:
    """B episodes of a task: facts and the per-step measurements and truth."""

    def __init__(self, seeds, duration=3.0, task="Indoor-v0", world_overrides=None):
        self.spec = get_spec(task, duration=duration)
        self.seeds = np.asarray(seeds, dtype=np.int64)
        # the world may simulate different sensors than the nominal ones the filter is told
        world = World(get_spec(task, duration=duration, **(world_overrides or {})), len(self.seeds))
        x0 = world.reset(self.seeds).copy()
        self.facts = TaskFacts.from_spec(self.spec, world.layout, x0, episode_keys(self.seeds))
        self.meas, self.truth = [], []
        for k in range(1, self.spec.n_steps + 1):
            buf = world.sense()
            self.meas.append(Measurements.capture(buf.imu, buf.z, buf.valid, k * self.spec.dt, k))
            self.truth.append(buf.pos.copy())

    def run(self, est) -> np.ndarray:
        """``(T, B, N, 3)`` estimates of a fresh run."""
        est.reset(self.facts, self.facts.x0)
        return np.array([est.step(m).positions for m in self.meas])


@pytest.fixture(scope="module")
def short() -> Episode:
    return Episode([2_000_000, 2_000_001], duration=3.0)


# --------------------------------------------------------------------------- resampling and ESS


def test_systematic_resampling_matches_searchsorted_reference_on_200_seeds():
    for seed in range(200):
        rng = np.random.default_rng(seed)
        m = int(rng.integers(1, 900))
        w = rng.gamma(rng.choice([0.05, 1.0, 5.0]), size=m)
        w[rng.random(m) < 0.3] = 0.0
        if seed % 17 == 0:
            w[:] = 0.0
            w[rng.integers(m)] = 1.0  # fully degenerate
        if w.sum() == 0.0:
            w[0] = 1.0
        w /= w.sum()
        n_out = int(rng.integers(1, 2 * m + 2))
        offset = float(rng.random())
        out = np.empty(n_out, dtype=np.int64)
        core.systematic_resample(w, n_out, offset, out)
        np.testing.assert_array_equal(out, systematic_resample_reference(w, n_out, offset), err_msg=f"seed {seed}")


def test_ess_of_uniform_weights_is_the_particle_count(short):
    # no channel valid and no network: weights stay uniform after the init, so ESS = M
    pf = ParticleFilter(STANDARD)
    pf.reset(short.facts, short.facts.x0)
    m = short.meas[0]
    blind = Measurements.capture(m.imu, m.z, np.zeros_like(m.valid), m.t, m.step)
    pf.step(blind)
    np.testing.assert_allclose(pf.ess, STANDARD.n_init, rtol=1e-12)
    assert not pf.resampled.any()


def test_numpy_rng_equals_envs_rng():
    idx = np.arange(0, 3_000_000, 9973)
    expected = np.array([uniform(987654321, 42, int(Stream.ESTIMATOR), int(i)) for i in idx])
    np.testing.assert_array_equal(uniform_np(987654321, 42, idx), expected)


# --------------------------------------------------------------------------- adaptive particle count


def _rule(ess, m, c: PFConfig):
    if ess < c.grow_below * m:
        return min(m + c.grow_step, c.n_max)
    if ess > c.shrink_above * m:
        return max(m - c.shrink_step, c.n_min)
    return m


@pytest.mark.parametrize("config", [ADAPTIVE, PFConfig(n_init=300, n_min=100, n_max=800, shrink_above=0.3)])
def test_particle_count_stays_in_bounds_and_follows_the_rule(short, config):
    pf = ParticleFilter(config)
    pf.reset(short.facts, short.facts.x0)
    seen = set()
    for m in short.meas:
        pf.step(m)
        used, ess, nxt = pf.used, pf.ess, pf.counts
        assert ((nxt >= config.n_min) & (nxt <= config.n_max)).all()
        expected = np.vectorize(lambda e, u: _rule(e, u, config))(ess, used)
        np.testing.assert_array_equal(nxt, expected)
        np.testing.assert_array_equal(pf.resampled, ess < config.resample_below * used)
        seen.update(np.sign(nxt - used).ravel().tolist())
    assert 1 in seen  # grew at least once


def test_count_shrinks_to_the_minimum_when_weights_stay_flat(short):
    pf = ParticleFilter(ADAPTIVE)
    pf.reset(short.facts, short.facts.x0)
    m = short.meas[0]
    counts = []
    for k in range(1, 8):
        pf.step(Measurements.capture(m.imu, m.z, np.zeros_like(m.valid), k * 0.1, k))
        counts.append(int(pf.counts[0, 0]))
    assert counts == [250, 200, 150, 100, 100, 100, 100]


def test_fixed_configurations_keep_their_count(short):
    for config, n in ((STANDARD, 500), (FIXED_800, 800)):
        pf = ParticleFilter(config)
        pf.reset(short.facts, short.facts.x0)
        for m in short.meas[:10]:
            pf.step(m)
            assert (pf.used == n).all() and (pf.counts == n).all()


def test_bad_configurations_are_rejected_with_the_value():
    with pytest.raises(ValueError, match="n_min=900"):
        PFConfig(n_init=800, n_min=900, n_max=800)
    with pytest.raises(ValueError, match="resample_below=1.5"):
        PFConfig(resample_below=1.5)
    with pytest.raises(ValueError, match="correction range"):
        PFConfig(correction_base=0.2, correction_gain=0.6)


# --------------------------------------------------------------------------- accuracy


def test_converges_to_the_truth_without_noise_and_with_exact_landmarks():
    # the world's IMU, camera and UWB are (numerically) exact; the filter keeps its nominal model
    exact = {"sensors": {"imu_sigma": 0.0, "camera_sigma": 1e-9, "peers": {"sigma": 1e-9}}}
    ep = Episode([2_000_002], duration=10.0, world_overrides=exact)
    err = np.linalg.norm(ep.run(ParticleFilter(STANDARD)) - np.array(ep.truth), axis=-1)
    initial = np.linalg.norm(ep.facts.x0[..., :3] - ep.truth[0], axis=-1)
    assert initial.max() > 0.3  # it starts from the perturbed prior
    assert err[-20:].max() < 0.05, err[-20:].max()
    assert err[-20:].mean() < 0.02, err[-20:].mean()


def test_kernel_equals_the_numpy_reference(short):
    net = random_weights(7, 2)
    for config, network in ((ADAPTIVE, net), (PFConfig(n_init=300, n_min=100, n_max=800, shrink_above=0.3), None)):
        f = short.facts
        pf = ParticleFilter(config, network=network)
        pf.reset(f, f.x0)
        ref = ReferenceParticleFilter(f.keys, f.x0, f.kind, f.target, f.sigma, f.anchors, f.landmarks, f.dt,
                                      f.init_pos_sigma, f.init_vel_sigma, config.accel_inflation * f.imu_sigma,
                                      config, network)
        for m in short.meas[:20]:
            got = pf.step(m).positions
            want = ref.step(m.step, m.imu, m.z, m.valid)
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
            np.testing.assert_array_equal(pf.used, ref.used)
            np.testing.assert_allclose(pf.ess, ref.ess, rtol=1e-9)


# --------------------------------------------------------------------------- no truth, determinism


def test_estimators_never_receive_truth(short):
    truth_names = {"pos", "vel", "truth", "true_pos", "label", "labels", "injected", "schedule"}
    allowed_meas = set(Measurements.__slots__)
    assert not truth_names & allowed_meas and not truth_names & set(TaskFacts.__slots__)
    for cls in (ParticleFilter,):
        assert list(inspect.signature(cls.step).parameters) == ["self", "meas"]
        assert list(inspect.signature(cls.reset).parameters) == ["self", "facts", "x0"]
        assert not hasattr(cls, "observe_privileged") and cls.privileged is False
    assert PFNNOnlineOracle.privileged is True

    accessed = set()

    class Spy:
        def __init__(self, m):
            self._m = m

        def __getattr__(self, name):
            accessed.add(name)
            return getattr(self._m, name)

    pf = make_pfnn()
    pf.reset(short.facts, short.facts.x0)
    for m in short.meas[:3]:
        pf.step(Spy(m))
    assert accessed <= allowed_meas
    # the estimator modules do not import the world (where the truth lives)
    for name in ("core.py", "filters.py", "pfnn.py", "reference.py"):
        tree = ast.parse((PF_DIR / name).read_text())
        mods = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
        mods |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        assert not any("world" in mod or mod.startswith("swarmloc.bench") for mod in mods), (name, mods)


def test_deterministic_and_batched_equals_single():
    seeds = [2_000_003, 2_000_004, 2_000_005]
    batched = Episode(seeds, duration=2.0)
    a = batched.run(make_pfnn())
    b = batched.run(make_pfnn())
    np.testing.assert_array_equal(a, b)
    for parallel in (True, False):
        pf = make_pfnn()
        pf.parallel = parallel
        np.testing.assert_array_equal(batched.run(pf), a)
    for j, seed in enumerate(seeds):
        single = Episode([seed], duration=2.0).run(make_pfnn())
        np.testing.assert_array_equal(single[:, 0], a[:, j])


# --------------------------------------------------------------------------- FLOPs


def test_flops_follow_the_particle_count(short):
    def first_step_flops(est):
        est.reset(short.facts, short.facts.x0)
        return est.step(short.meas[0]).flops

    f500 = first_step_flops(ParticleFilter(STANDARD))
    f800 = first_step_flops(ParticleFilter(FIXED_800))
    f300 = first_step_flops(ParticleFilter(ADAPTIVE))
    fnn = first_step_flops(ParticleFilter(ADAPTIVE, network=random_weights(0, 0)))
    assert f500.shape == (2, 6) and (f500 > 0).all()
    assert (f800 > f500).all() and (f500 > f300).all() and (fnn > f300).all()
    # per used particle, the network adds its declared cost
    per = (fnn - f300) / 300
    np.testing.assert_allclose(per, core.nn_particle_flops(12))


# --------------------------------------------------------------------------- PF-NN network and training


def test_network_output_and_correction_range():
    w = random_weights(3, 1)
    y = w.forward(np.random.default_rng(0).normal(size=(1000, 6)) * 5)
    assert ((y > 0) & (y < 1)).all()
    c = 0.7 + 0.6 * (y - 0.5)
    assert c.min() >= 0.4 and c.max() <= 1.0
    with pytest.raises(ValueError, match="W1 must have shape"):
        PFNNWeights(W1=np.zeros((12, 5)), b1=np.zeros(12), W2=np.zeros(12), b2=0.0)


def test_training_refuses_test_and_dev_seeds(tmp_path):
    from swarmloc.bench.training.pfnn import TrainPfnnArgs, train_pfnn

    for start in (1_000_000, 2_000_000):
        with pytest.raises(ValueError, match="training seeds must be in"):
            train_pfnn(TrainPfnnArgs(seed_start=start, seeds=2, weights_out=tmp_path / "w.npz"))
    assert not (tmp_path / "w.npz").exists()


def test_fit_writes_weights_with_provenance(tmp_path):
    from swarmloc.bench.training.pfnn import TrainPfnnArgs, train_pfnn

    out = tmp_path / "pfnn.npz"
    args = TrainPfnnArgs(seeds=2, seed_start=10, duration=2.0, rounds=1, epochs=1, weights_out=out)
    path = train_pfnn(args, log=lambda *_: None)
    w = load_weights(path)
    assert w.hidden == 12 and np.isfinite(w.W1).all()
    record = json.loads(path.with_suffix(".json").read_text())
    assert record["command"].startswith("swarmloc train pfnn") and "--seed-start 10" in record["command"]
    assert record["fit"]["seeds"] == [10, 11]
    assert "git_commit" in record["provenance"]


@pytest.mark.parametrize("version", sorted(SHIPPED_WEIGHTS))
def test_shipped_weights_are_small_and_documented(version):
    path = SHIPPED_WEIGHTS[version]
    assert path.stat().st_size < 10_000
    w = load_weights(path)
    assert w.W1.shape == (12, 6)
    record = json.loads(path.with_suffix(".json").read_text())
    assert record["command"].startswith("swarmloc train pfnn")
    # each version's fit comes from its own Indoor task, on training seeds only
    assert record["fit"]["task"] == f"swarmloc/Indoor-v{version}"
    assert all(s < 1_000_000 for s in record["fit"]["seeds"])
    assert record["provenance"]["git_commit"]


def test_pfnn_runs_the_fit_of_the_task_version():
    assert shipped_weights("swarmloc/Indoor-v0") == SHIPPED_WEIGHTS[0]
    assert shipped_weights("swarmloc/Indoor-v1") == shipped_weights("swarmloc/NLOS-v1") == SHIPPED_WEIGHTS[1]
    with pytest.raises(ValueError, match="'swarmloc/Indoor' has no version"):
        shipped_weights("swarmloc/Indoor")
    w0, w1 = load_weights(SHIPPED_WEIGHTS[0]), load_weights(SHIPPED_WEIGHTS[1])
    assert not np.array_equal(w0.W1, w1.W1)
    pf = make_pfnn()
    for task, w in (("Indoor-v0", w0), ("Indoor-v1", w1), ("Indoor-v0", w0)):
        ep = Episode([2_000_000], duration=0.3, task=task)
        pf.reset(ep.facts, ep.facts.x0)
        np.testing.assert_array_equal(pf.network.W1, w.W1)
        # and it is the fixed-network filter with that fit, step for step
        fixed = ParticleFilter(ADAPTIVE, network=w, name="pf-nn")
        np.testing.assert_array_equal(ep.run(pf), ep.run(fixed))


def test_online_oracle_is_privileged_and_learns_from_truth(short):
    oracle = PFNNOnlineOracle(train_every=2)
    oracle.reset(short.facts, short.facts.x0)
    w0 = oracle._s.W1.copy()

    class Info:
        def __init__(self, pos):
            self.labels = None
            self.pos = pos

    with pytest.raises(ValueError, match="true positions"):
        oracle.step(short.meas[0])
        oracle.step(short.meas[1])
    oracle.reset(short.facts, short.facts.x0)
    for m, truth in zip(short.meas[:6], short.truth[:6]):
        oracle.observe_privileged(Info(truth))
        oracle.step(m)
    assert not np.array_equal(oracle._s.W1, w0)
    # each (episode, UAV) has its own network
    assert not np.array_equal(oracle._s.W1[0, 0], oracle._s.W1[0, 1])


# --------------------------------------------------------------------------- bench glue


def test_speed_rows_have_the_contract():
    from swarmloc.bench.speed import estimators as se

    rec = se.record(1, 4)
    t, particles = se.time_estimator(lambda: ParticleFilter(STANDARD), rec, 1)
    row = se._row("pf", 1, 6, t, particles=particles)
    assert {"impl", "B", "env_steps_per_s", "uav_steps_per_s", "ms_per_step"} <= set(row)
    assert row["ms_per_step"] > 0 and particles == 500


def test_reproduce_smoke(tmp_path):
    from swarmloc.bench.reproduce.pfnn import reproduce_pfnn

    path = reproduce_pfnn(tmp_path, seeds=2, duration=1.0, timing_steps=3)
    text = path.read_text()
    for needle in ("Table 4", "Table 5", "adaptive-pf", "pf-nn-online-oracle", "cekf-uniform", "0.437"):
        assert needle in text
    raw = json.loads(path.with_suffix(".json").read_text())
    assert raw["seeds"] == [1_000_000, 1_000_001]
    assert raw["task"] == "swarmloc/Indoor-v1" and "on swarmloc/Indoor-v1" in text
    with pytest.raises(ValueError, match="version must be 0 or 1, got 2"):
        reproduce_pfnn(tmp_path, seeds=2, version=2)


def test_cli_groups_register_train_and_reproduce_pfnn():
    from swarmloc import cli
    assert cli.main(["train", "pfnn", "--seed-start", "1000000", "--seeds", "1"]) == 2
