"""MAPPO link trust (issue 5): training smoke test, shapes, invariances, shipped weights, seeds, determinism."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from trust_helpers import obs_input

from swarmloc.agents.mappo.policy import (
    WEIGHTS_DIR,
    ChannelActor,
    MappoPolicy,
    count_flops_per_channel,
    load_actor,
)
from swarmloc.agents.registry import load_method
from swarmloc.agents.trust.smoothing import MarkovSmoothing
from swarmloc.envs.world.observation import N_FEATURES, VALID

REPO = Path(__file__).resolve().parents[1]
SHIPPED = WEIGHTS_DIR / "mappo.pt"


def _random_obs(rng: np.random.Generator, b: int, n: int, n_l: int) -> np.ndarray:
    obs = rng.uniform(0.0, 1.0, (b, n, n_l, N_FEATURES)).astype(np.float32)
    obs[..., VALID] = 1.0
    return obs


def _tiny_config(tmp_path: Path, **kw):
    from swarmloc.agents.mappo.train import MappoConfig

    base = dict(tasks=("CascadedFault-v0",), frames=400, num_envs=4, rollout_steps=100, epochs=1, minibatches=2,
                run_dir=str(tmp_path), progress=False, eval_every=0, checkpoint_every=0)
    base.update(kw)
    return MappoConfig(**base)


def test_train_cli_smoke(tmp_path):
    """``swarmloc train mappo`` trains a few hundred frames and writes weights, provenance and logs."""
    out = tmp_path / "w" / "mappo.pt"
    cmd = [str(Path(sys.executable).parent / "swarmloc"), "train", "mappo", "--frames", "400", "--tasks", "CascadedFault-v0",
           "Scale2-v0", "--num-envs", "2", "--rollout-steps", "100", "--epochs", "1", "--minibatches", "2",
           "--eval-seeds", "1", "--run-dir", str(tmp_path / "run"), "--weights-out", str(out), "--no-progress"]
    proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=240)
    assert proc.returncode == 0, proc.stderr[-3000:]
    actor = load_actor(out)
    assert isinstance(actor, ChannelActor)
    meta = json.loads(out.with_suffix(".json").read_text())
    assert meta["frames"] == 400 and meta["command"].endswith(f"--weights-out {out} --no-progress")
    assert {"wall_time_s", "git_commit", "config", "dev_eval"} <= set(meta)
    assert meta["episode_seeds"]["max"] < 1_000_000
    assert any(k.endswith("/healthy_rmse") for k in meta["dev_eval"])
    assert list((tmp_path / "run").glob("events.out.tfevents.*")), "no TensorBoard log"
    assert (tmp_path / "run" / "checkpoint.pt").is_file()


@pytest.mark.parametrize("context", [True, False])
@pytest.mark.parametrize("n,n_l", [(2, 9), (4, 6), (8, 15), (32, 39)])
def test_policy_any_swarm_size_and_channel_count(n, n_l, context):
    """One shared per-channel actor serves any N and L; α ∈ (0, 1]; channels and UAVs are exchangeable."""
    torch.manual_seed(0)
    policy = MappoPolicy(ChannelActor(context=context))
    rng = np.random.default_rng(n)
    obs = _random_obs(rng, 3, n, n_l)
    alpha = policy.act(obs_input(obs))
    assert alpha.shape == (3, n, n_l) and alpha.dtype == np.float64
    assert np.all(alpha > 0.0) and np.all(alpha <= 1.0)
    ch, uav = rng.permutation(n_l), rng.permutation(n)
    permuted = policy.act(obs_input(np.ascontiguousarray(obs[:, uav][:, :, ch])))
    np.testing.assert_allclose(permuted, alpha[:, uav][:, :, ch], rtol=1e-6)
    moved = obs.copy()
    moved[0, 0, 0, :5] = 1.0 - moved[0, 0, 0, :5]  # change one channel of UAV 0 in episode 0
    again = policy.act(obs_input(moved))
    np.testing.assert_array_equal(again[1:], alpha[1:])  # other episodes
    np.testing.assert_array_equal(again[0, 1:], alpha[0, 1:])  # other UAVs: decentralized
    if not context:  # the paper's purely per-channel input: the UAV's other channels are unaffected too
        np.testing.assert_array_equal(again[0, 0, 1:], alpha[0, 0, 1:])
    absent = obs.copy()
    absent[..., 0, VALID] = 0.0
    assert np.all(policy.act(obs_input(absent))[..., 0] == 1.0)


def test_policy_runs_on_tasks_of_different_shapes():
    """The same weights run through the runner on Scale2 and Scale8 (short episodes)."""
    from swarmloc.agents.registry import LoadedMethod
    from swarmloc.bench.evaluation.runner import rollout
    from swarmloc.envs.tasks.catalogue import get_spec

    torch.manual_seed(0)
    for task in ("Scale2-v0", "Scale8-v0"):
        method = MarkovSmoothing(MappoPolicy(ChannelActor()))
        loaded = LoadedMethod("mappo", "test", "A", False, True, method)
        metrics, _ = rollout(loaded, get_spec(task, duration=1.0), [7, 8])
        assert len(metrics) == 2 and all(np.isfinite(m["rmse"]) for m in metrics)


def test_critic_permutation_invariant_over_uavs():
    """Permuting the UAVs (and every UAV's peer channels) permutes the per-UAV values; the swarm mean is unchanged."""
    from swarmloc.agents.mappo.nets import SwarmCritic

    torch.manual_seed(0)
    n, n_anchor = 5, 3
    n_l = n_anchor + n - 1
    critic = SwarmCritic(N_FEATURES, 32, privileged=True)
    rng = np.random.default_rng(1)
    obs = torch.from_numpy(_random_obs(rng, 2, n, n_l))
    filt = torch.from_numpy(rng.normal(size=(2, n, 7)).astype(np.float32)).abs()
    err = torch.from_numpy(rng.uniform(0, 3, (2, n, 1)).astype(np.float32))

    def state(o: torch.Tensor, f: torch.Tensor) -> torch.Tensor:
        # [obs, positions (3N), velocities (3N), std (N)] as in TrustEnvBatch.state
        return torch.cat([o.reshape(2, -1), f[..., :3].reshape(2, -1), f[..., 3:6].reshape(2, -1), f[..., 6]], -1)

    values = critic(obs, state(obs, filt), err)
    perm = [3, 0, 4, 1, 2]
    # UAV i's peer slot for UAV j (j ≠ i, index order) → the permuted layout's slot
    p_obs = torch.empty_like(obs)
    for new_i, old_i in enumerate(perm):
        peers_old = [j for j in range(n) if j != old_i]
        peers_new = [perm[j] for j in range(n) if j != new_i]
        cols = [n_anchor + peers_old.index(j) for j in peers_new]
        p_obs[:, new_i, :n_anchor] = obs[:, old_i, :n_anchor]
        p_obs[:, new_i, n_anchor:] = obs[:, old_i, cols]
    p_values = critic(p_obs, state(p_obs, filt[:, perm]), err[:, perm])
    torch.testing.assert_close(p_values, values[:, perm], rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(p_values.mean(1), values.mean(1), rtol=1e-5, atol=1e-6)
    # and it runs on another swarm size with the same weights
    assert critic(obs[:, :2, :4], state(obs[:, :2, :4], filt[:, :2]), err[:, :2]).shape == (2, 2, 1)


@pytest.mark.parametrize("context", [True, False])
def test_flops_counted_once_with_flop_counter(context):
    actor = ChannelActor(context=context)
    flops = count_flops_per_channel(actor)
    matmul = 2 * ((N_FEATURES + (2 if context else 0)) * 128 + 128 * 64 + 64 * 1)
    assert matmul <= flops < matmul + 1000
    assert MappoPolicy(actor).flops_per_channel == flops
    assert MappoPolicy(actor, isolation=False).flops_per_channel == 0.0


def test_weights_round_trip_keeps_the_input_layout(tmp_path):
    for context in (True, False):
        actor = ChannelActor(context=context)
        torch.save(actor.state_dict(), tmp_path / "w.pt")
        loaded = load_actor(tmp_path / "w.pt")
        assert bool(loaded.context) == context
        x = torch.rand(2, 5, N_FEATURES)
        torch.testing.assert_close(loaded(x), actor(x))


@pytest.mark.skipif(not SHIPPED.is_file(), reason="shipped weights not trained yet")
def test_shipped_weights_load_and_give_trust_in_unit_interval():
    """``mappo`` and its ablations load without training and output α in (0, 1] on a real task."""
    from swarmloc.agents.registry import get_entry
    from swarmloc.bench.evaluation.runner import rollout
    from swarmloc.envs.tasks.catalogue import get_spec

    meta = json.loads(SHIPPED.with_suffix(".json").read_text())
    assert {"command", "frames", "wall_time_s", "git_commit"} <= set(meta)
    state = torch.load(SHIPPED, weights_only=True)
    assert all(isinstance(v, torch.Tensor) for v in state.values())  # a plain state_dict
    assert SHIPPED.stat().st_size < 200_000
    names = ["mappo", "mappo-no-smoothing", "mappo-no-isolation"]
    if (WEIGHTS_DIR / "mappo_accuracy_only.pt").is_file():
        names.append("mappo-accuracy-only")
    for name in names:
        assert get_entry(name).track == "A"
        loaded = load_method(name)
        rng = np.random.default_rng(0)
        obs = _random_obs(rng, 2, 4, 11)
        loaded.method.reset(2, _layout(4, 11), np.arange(2))
        alpha = loaded.method.act(obs_input(obs))
        assert alpha.shape == (2, 4, 11) and np.all(alpha > 0.0) and np.all(alpha <= 1.0)
        if name == "mappo-no-isolation":
            assert np.all(alpha == 1.0)
    metrics, _ = rollout(load_method("mappo"), get_spec("CascadedFault-v0", duration=2.0), [3])
    assert np.isfinite(metrics[0]["rmse"]) and metrics[0]["delay_ms"] < 50.0


def _layout(n: int, n_l: int):
    from swarmloc.envs.tasks.channels import ChannelLayout

    zeros = np.zeros((n, n_l), dtype=np.int64)
    return ChannelLayout(kind=zeros, target=zeros, linked=np.ones((n, n_l), bool), sigma=np.ones((n, n_l)))


def test_missing_weights_give_a_clear_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="swarmloc train mappo"):
        load_method("mappo", weights=tmp_path / "nope.pt")


def test_training_refuses_test_and_dev_seeds(tmp_path):
    from swarmloc.agents.mappo.train import EpisodeSeeds, train
    from swarmloc.bench.evaluation.suites import check_training_seeds
    from swarmloc.bench.training.mappo import TrainMappoArgs, train_mappo

    for seed in (1_000_000, 1_000_031, 2_000_003):
        with pytest.raises(ValueError, match="training seed"):
            train_mappo(TrainMappoArgs(seed=seed, frames=400, run_dir=str(tmp_path)))
    seeder = EpisodeSeeds(3, 0, 16)
    check_training_seeds([seeder.next_base() + b for _ in range(200) for b in range(16)])

    def refuse(seeds: list[int]) -> None:
        raise ValueError(f"refused {seeds[:2]}")

    with pytest.raises(ValueError, match="refused"):  # the guard runs before any episode is played
        train(_tiny_config(tmp_path), check_seeds=refuse)


def test_training_is_deterministic_given_a_seed(tmp_path):
    from swarmloc.agents.mappo.train import train

    runs = [train(_tiny_config(tmp_path / str(i), seed=seed)) for i, seed in enumerate((5, 5, 6))]
    a, b, c = (r.actor_state for r in runs)
    assert a.keys() == b.keys()
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert runs[0].episode_seeds == runs[1].episode_seeds
    assert any(not torch.equal(a[k], c[k]) for k in a)


def test_reproduce_madrl_checks_its_arguments(tmp_path):
    from swarmloc.bench.reproduce.madrl import reproduce_madrl

    with pytest.raises(ValueError, match="seeds must be in"):
        reproduce_madrl(tmp_path, seeds=0)
    with pytest.raises(ValueError, match="traces must be in"):
        reproduce_madrl(tmp_path, seeds=2, traces=3)
    with pytest.raises(FileNotFoundError, match="swarmloc train mappo"):
        reproduce_madrl(tmp_path, seeds=1, traces=1, weights=tmp_path / "missing.pt")
    with pytest.raises(ValueError, match="version must be one of \\[0, 1\\], got 2"):
        reproduce_madrl(tmp_path, version=2)


def test_reproduce_madrl_names_the_tasks_of_its_version():
    from swarmloc.bench.reproduce.madrl import Runs

    v0, v1 = Runs(seeds=[1], weights={}, version=0), Runs(seeds=[1], weights={})
    assert v0.task("NLOSStep") == "swarmloc/NLOSStep-v0" and v1.task("NLOSStep") == "swarmloc/NLOSStep-v1"
    # the learned reference is measured beside mappo on v1 only
    assert v0.learned("uniform", "mappo") == ("uniform", "mappo")
    assert v1.learned("uniform", "mappo") == ("uniform", "mappo", "mappo-set-gru")


def test_cli_registers_train_mappo_and_reproduce_madrl():
    from swarmloc.cli import COMMANDS

    assert "mappo" in COMMANDS["train"] and "madrl" in COMMANDS["reproduce"]


def test_loop_smoother_equals_execution_smoothing():
    """The training-time smoother applies exactly ``smooth_step`` (madrl eq. 15–17), state per task."""
    from swarmloc.agents.mappo.nets import LoopSmoother
    from swarmloc.agents.trust.smoothing import smooth_step
    from swarmloc.envs.world.observation import INNOVATION, SCALE_INNOVATION, squash

    rng = np.random.default_rng(5)
    shape = (3, 4, 6)
    smoother = LoopSmoother(0.85, 2.0)
    alpha_ref, resid_ref = np.ones(shape), np.zeros(shape)
    other = None
    for k in range(30):
        resid = rng.exponential(0.5, shape)
        valid = rng.uniform(size=shape) > 0.2
        raw = rng.uniform(size=shape)
        obs = np.zeros((*shape, N_FEATURES), dtype=np.float32)
        obs[..., INNOVATION] = squash(resid, SCALE_INNOVATION)
        obs[..., VALID] = valid
        resid32 = SCALE_INNOVATION * obs[..., INNOVATION].astype(np.float64) / (1.0 - obs[..., INNOVATION])
        smoother.select(0, fresh=k == 0)
        out = smoother(torch.as_tensor(raw, dtype=torch.float32), torch.as_tensor(obs)).numpy()
        alpha_ref = smooth_step(alpha_ref, raw, resid_ref, resid32, valid, 0.85, 2.0)
        resid_ref = np.where(valid, resid32, resid_ref)
        np.testing.assert_allclose(out, alpha_ref, atol=1e-5)
        if k == 10:  # another task's batch in between leaves task 0's state alone
            smoother.select(1, fresh=True)
            other = smoother(torch.full((2, 2, 2), 0.3), torch.zeros((2, 2, 2, N_FEATURES))).numpy()
    assert np.all(other == 1.0)  # absent channels (valid = 0) keep α_eff(0) = 1
    smoother.select(0, fresh=True)  # a new episode restarts at α_eff = 1
    obs = np.zeros((*shape, N_FEATURES), dtype=np.float32)
    obs[..., VALID] = 1.0
    out = smoother(torch.zeros(shape), torch.as_tensor(obs)).numpy()
    np.testing.assert_allclose(out, 0.85, atol=1e-6)  # β = β_max (Δr = 0): 0.85·1 + 0.15·0


def test_smoothing_keeps_the_total_variation_of_a_step():
    """Why smoothing cannot cut the jitter of a clean switching policy: a first-order low-pass
    moves α_eff monotonically towards a held α_raw (a convex combination), so a step's
    Σ|Δα| is kept, only spread in time; only oscillation is removed."""
    from swarmloc.agents.trust.smoothing import smooth_step

    raw = np.r_[np.ones(20), np.full(60, 0.05), np.ones(60)]
    resid = np.r_[np.full(20, 0.1), np.full(60, 3.0), np.full(60, 0.1)]
    alpha, r_prev, path = np.ones(1), np.zeros(1), []
    for a, r in zip(raw, resid):
        alpha = smooth_step(alpha, np.array([a]), r_prev, np.array([r]), np.ones(1, bool), 0.85, 2.0)
        r_prev = np.array([r])
        path.append(alpha[0])
    tv_raw, tv_smooth = np.abs(np.diff(np.r_[1.0, raw])).sum(), np.abs(np.diff(np.r_[1.0, path])).sum()
    assert tv_smooth == pytest.approx(tv_raw, rel=1e-3)
    # an oscillating raw trust, on the other hand, is smoothed: |Δα| falls by ≥ 3×
    osc = np.where(np.arange(140) % 2, 0.3, 0.9)
    alpha, path = np.ones(1), []
    for a in osc:
        alpha = smooth_step(alpha, np.array([a]), np.zeros(1), np.zeros(1), np.ones(1, bool), 0.85, 2.0)
        path.append(alpha[0])
    assert np.abs(np.diff(path[20:])).mean() < np.abs(np.diff(osc[20:])).mean() / 3


def test_channel_kinds_outside_training_get_nominal_trust():
    """Channels of kinds the weights never saw in training (from their record) get α = 1."""
    from swarmloc.agents.mappo.policy import trained_kinds, weights_kinds
    from swarmloc.envs.tasks.channels import ANCHOR, GPS, N_KINDS, PEER, PEER_REL
    from swarmloc.envs.world.observation import KIND0

    np.testing.assert_array_equal(trained_kinds(["NLOS-v0", "Scale2-v0"]), np.eye(N_KINDS, dtype=bool)[[ANCHOR, PEER]].any(0))
    assert trained_kinds(["GradualFault-v0"])[[GPS, PEER_REL]].all()
    meta = json.loads(SHIPPED.with_suffix(".json").read_text())
    np.testing.assert_array_equal(weights_kinds(SHIPPED), trained_kinds(meta["config"]["tasks"]))
    assert weights_kinds(Path("/nonexistent/mappo.pt")) is None  # no record: every kind

    rng = np.random.default_rng(1)
    obs = _random_obs(rng, 2, 3, 5)
    obs[..., KIND0:KIND0 + N_KINDS] = 0.0
    for channel, kind in enumerate([ANCHOR, PEER, GPS, PEER_REL, ANCHOR]):
        obs[..., channel, KIND0 + kind] = 1.0
    actor = ChannelActor(N_FEATURES, (16, 8), init_trust=0.3)
    everything = MappoPolicy(actor)
    some = MappoPolicy(actor, kinds=trained_kinds(["NLOS-v0"]))
    for policy in (everything, some):
        policy.reset(2, _layout(3, 5), np.arange(2))
    a_all, a_some = everything.act(obs_input(obs)), some.act(obs_input(obs))
    np.testing.assert_array_equal(a_some[..., [0, 1, 4]], a_all[..., [0, 1, 4]])
    assert np.all(a_some[..., [2, 3]] == 1.0) and np.all(a_all < 1.0)
    with pytest.raises(ValueError, match="kinds"):
        MappoPolicy(actor, kinds=np.ones(3, bool))


@pytest.mark.parametrize("name", ["mappo", "mappo-no-smoothing", "mappo-no-isolation", "mappo-accuracy-only"])
def test_each_benchmark_version_gets_the_weights_trained_on_its_tasks(name):
    """v0 tasks run the frozen v0 weights, v1 tasks (and no version: the newest) the ones trained on v1."""
    from swarmloc.agents.mappo.policy import SHIPPED as SHIPPED_FILES
    from swarmloc.agents.mappo.policy import shipped_weights, weights_metadata

    family = "mappo-accuracy-only" if name == "mappo-accuracy-only" else "mappo"
    for version, file in SHIPPED_FILES[family].items():
        path = WEIGHTS_DIR / file
        assert shipped_weights(family, version) == path and path.is_file(), path
        tasks = weights_metadata(path)["config"]["tasks"]
        assert tasks and all(t.endswith(f"-v{version}") for t in tasks)  # trained on that version's tasks only
        if version >= 1:
            assert all("Random" in t for t in tasks)  # the randomized families' training seeds
        expected = load_actor(path).state_dict()
        for v in (version,) + ((None,) if version == max(SHIPPED_FILES[family]) else ()):
            method = load_method(name, version=v).method
            actor = (method.policy if isinstance(method, MarkovSmoothing) else method).actor
            got = actor.state_dict()
            assert got.keys() == expected.keys() and all(torch.equal(got[k], expected[k]) for k in got)
