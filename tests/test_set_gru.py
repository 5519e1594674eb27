"""mappo-set-gru (issue 16): the set + GRU actor's invariances and memory, its policy, recurrent PPO training."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from trust_helpers import obs_input

from swarmloc.agents.mappo.set_gru_policy import SetGruActor, SetGruPolicy, count_flops_per_channel, load_set_gru_actor
from swarmloc.envs.world.observation import N_FEATURES, VALID

REPO = Path(__file__).resolve().parents[1]


def _obs(rng: np.random.Generator, *shape: int) -> torch.Tensor:
    x = torch.tensor(rng.uniform(0.0, 1.0, (*shape, N_FEATURES)), dtype=torch.float32)
    x[..., VALID] = 1.0
    return x


def _actor(seed: int = 0) -> SetGruActor:
    torch.manual_seed(seed)
    actor = SetGruActor(embed=16, hidden=8)
    with torch.no_grad():  # a non-trivial head (the shipped init makes every output ≈ init_trust)
        actor.head[-1].weight.normal_(0.0, 1.0)
    return actor.eval()


def test_channel_permutation_permutes_logits_and_memory():
    """DeepSets over channels: permuting a UAV's channels permutes its logits and hidden states, step after step."""
    actor = _actor()
    rng = np.random.default_rng(1)
    obs = _obs(rng, 3, 7, 2, 5)  # (B, T, N, L)
    perm = torch.tensor([3, 0, 4, 1, 2])
    h, hp = actor.initial_state((3, 2, 5)), actor.initial_state((3, 2, 5))
    with torch.no_grad():
        for k in range(obs.shape[1]):
            mu, h = actor.step(obs[:, k], h)
            mu_p, hp = actor.step(obs[:, k][:, :, perm], hp)
            torch.testing.assert_close(mu_p, mu[:, :, perm], atol=1e-5, rtol=1e-5)
            torch.testing.assert_close(hp, h[:, :, perm], atol=1e-5, rtol=1e-5)
    assert mu.std() > 1e-3, "the actor's output is constant: the test would not see a wrong permutation"


def test_memory_changes_the_decision_and_an_absent_channel_keeps_its_state():
    actor = _actor()
    rng = np.random.default_rng(2)
    a, b = _obs(rng, 1, 1, 4), _obs(rng, 1, 1, 4)
    now = _obs(rng, 1, 1, 4)
    with torch.no_grad():
        _, ha = actor.step(a, actor.initial_state((1, 1, 4)))
        _, hb = actor.step(b, actor.initial_state((1, 1, 4)))
        mu_a, _ = actor.step(now, ha)
        mu_b, _ = actor.step(now, hb)
        assert (mu_a - mu_b).abs().max() > 1e-4, "same observation, different history: the logits must differ"
        gone = now.clone()
        gone[..., 2, :] = 0.0  # channel 2 absent at this step
        _, h_next = actor.step(gone, ha)
    torch.testing.assert_close(h_next[..., 2, :], ha[..., 2, :], rtol=0, atol=0)
    assert not torch.equal(h_next[..., 0, :], ha[..., 0, :])


def test_sequence_replays_the_step_by_step_rollout():
    actor = _actor()
    obs = _obs(np.random.default_rng(3), 2, 6, 3, 4)
    h0 = torch.randn(2, 3, 4, 8).abs()
    h, mus = h0, []
    with torch.no_grad():
        for k in range(6):
            mu, h = actor.step(obs[:, k], h)
            mus.append(mu)
        torch.testing.assert_close(actor.sequence(obs, h0), torch.stack(mus, 1), rtol=0, atol=0)


def test_policy_episodes_are_independent_and_reset_clears_memory():
    """Batched == single: each episode's trust depends on its own observations only; reset restarts memory."""
    from swarmloc.envs.tasks.channels import build_layout
    from swarmloc.envs.tasks.catalogue import get_spec
    layout = build_layout(get_spec("swarmloc/NLOS-v1"))
    n, n_l = layout.kind.shape
    rng = np.random.default_rng(4)
    steps = [_obs(rng, 3, n, n_l).numpy() for _ in range(5)]
    batched, single = SetGruPolicy(_actor()), SetGruPolicy(_actor())
    batched.reset(3, layout, np.arange(3))
    out_b = [batched.act(obs_input(o)) for o in steps]
    single.reset(1, layout, np.arange(1))
    out_s = [single.act(obs_input(o[1:2])) for o in steps]
    for ob, os_ in zip(out_b, out_s):
        np.testing.assert_allclose(ob[1:2], os_, rtol=1e-6, atol=1e-6)
    single.reset(1, layout, np.arange(1))
    np.testing.assert_allclose(single.act(obs_input(steps[0][1:2])), out_s[0], rtol=0, atol=0)
    assert np.all((out_b[-1] > 0) & (out_b[-1] <= 1))
    with pytest.raises(ValueError, match="batch and layout of reset"):
        batched.act(obs_input(steps[0][:2]))


def test_weights_round_trip_and_errors(tmp_path):
    actor = _actor()
    path = tmp_path / "sg.pt"
    torch.save(actor.state_dict(), path)
    loaded = load_set_gru_actor(path)
    assert (loaded.embed, loaded.hidden) == (16, 8)
    x = _obs(np.random.default_rng(5), 2, 3)
    h = actor.initial_state((2, 3))
    torch.testing.assert_close(loaded.step(x, h)[0], actor.step(x, h)[0])
    with pytest.raises(FileNotFoundError, match="swarmloc train mappo-set-gru"):
        load_set_gru_actor(tmp_path / "nope.pt")
    torch.save({"body.0.weight": torch.zeros(2, 2)}, tmp_path / "other.pt")
    with pytest.raises(ValueError, match="not a SetGruActor"):
        load_set_gru_actor(tmp_path / "other.pt")


def test_flops_grow_with_the_widths():
    small, big = SetGruActor(embed=16, hidden=8), SetGruActor(embed=32, hidden=16)
    f_small, f_big = count_flops_per_channel(small), count_flops_per_channel(big)
    # the products: encoder F·E + E², GRU 3·(3E·H + H²), head (2H + 3E)·E + E, each 2 FLOPs per multiply-add
    e, h, f = 16, 8, N_FEATURES
    products = 2 * (f * e + e * e + 3 * (3 * e * h + h * h) + (2 * h + 3 * e) * e + e)
    assert products <= f_small <= products * 1.5
    assert f_big > 3 * f_small


def test_config_refuses_what_recurrent_training_cannot_do(tmp_path):
    from swarmloc.agents.mappo.config import SetGruConfig

    with pytest.raises(ValueError, match="divisible by minibatches"):
        SetGruConfig(num_envs=6, minibatches=4, run_dir=str(tmp_path))
    with pytest.raises(ValueError, match="collectors=0"):
        SetGruConfig(num_envs=4, minibatches=2, collectors=2, label_coef=0.0, run_dir=str(tmp_path))
    with pytest.raises(ValueError, match="0 with collectors >= 1"):
        SetGruConfig(num_envs=4, minibatches=2, collectors=2, run_dir=str(tmp_path))


def test_label_loss_weight_anneals_linearly_to_its_final_value(tmp_path):
    """``label_coef_final``: the weight goes linearly from ``label_coef`` at the first iteration to the final value
    at the end (as the learning rate anneals); without it the weight stays ``label_coef``."""
    from swarmloc.agents.mappo.config import MappoConfig, SetGruConfig

    cfg = SetGruConfig(label_coef=1.0, label_coef_final=0.0, run_dir=str(tmp_path))
    assert [cfg.label_weight(it, 8) for it in (0, 2, 4, 6)] == [1.0, 0.75, 0.5, 0.25]
    assert SetGruConfig(label_coef=2.0, label_coef_final=1.0, run_dir=str(tmp_path)).label_weight(5, 10) == 1.5
    assert SetGruConfig(label_coef=0.7, run_dir=str(tmp_path)).label_weight(9, 10) == 0.7
    with pytest.raises(ValueError, match=r"label_coef_final=-0.5 must be >= 0"):
        SetGruConfig(label_coef_final=-0.5, run_dir=str(tmp_path))
    with pytest.raises(ValueError, match=r"needs label_coef > 0 \(got label_coef=0.0\)"):
        MappoConfig(label_coef=0.0, label_coef_final=0.5, run_dir=str(tmp_path))


def test_train_cli_smoke_replays_the_collected_log_probabilities(tmp_path):
    """``swarmloc train mappo-set-gru`` on a few hundred frames: weights, provenance, logs; the first epoch's
    replay from the batch's start state gives back the collected log-probabilities (ratio 1)."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    out = tmp_path / "w" / "sg.pt"
    cmd = [str(Path(sys.executable).parent / "swarmloc"), "train", "mappo-set-gru", "--frames", "400", "--tasks",
           "CascadedFaultRandom-v1", "--num-envs", "2", "--rollout-steps", "100", "--epochs", "1",
           "--minibatches", "2", "--embed", "8", "--gru-hidden", "4", "--eval-seeds", "1",
           "--run-dir", str(tmp_path / "run"), "--weights-out", str(out), "--no-progress"]
    proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=300, check=False)
    assert proc.returncode == 0, proc.stderr[-3000:] + proc.stdout[-2000:]
    actor = load_set_gru_actor(out)
    assert (actor.embed, actor.hidden) == (8, 4)
    meta = json.loads(out.with_suffix(".json").read_text())
    assert meta["method"] == "mappo-set-gru" and meta["frames"] == 400
    assert meta["episode_seeds"]["max"] < 1_000_000
    assert any(k.endswith("/healthy_rmse") for k in meta["dev_eval"])
    ea = EventAccumulator(str(tmp_path / "run"))
    ea.Reload()
    replay = [s.value for s in ea.Scalars("losses/replay_log_ratio_max")]
    assert len(replay) == 2 and max(replay) < 1e-5


def test_training_is_deterministic_given_a_seed(tmp_path):
    from swarmloc.agents.mappo.config import SetGruConfig
    from swarmloc.agents.mappo.set_gru import train

    def cfg(i: int, seed: int) -> SetGruConfig:
        return SetGruConfig(tasks=("Scale2-v1",), frames=400, num_envs=2, rollout_steps=100, epochs=1, minibatches=2,
                            embed=8, gru_hidden=4, seed=seed, run_dir=str(tmp_path / str(i)), progress=False,
                            eval_every=0, checkpoint_every=0)

    a, b, c = (train(cfg(i, s)).actor_state for i, s in enumerate((5, 5, 6)))
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert any(not torch.equal(a[k], c[k]) for k in a)


def test_training_gives_the_same_weights_on_one_or_two_threads(tmp_path):
    """``--threads 2`` (the world's kernels on both cores) changes no number, at the shipped widths (E = H = 64),
    where a threaded BLAS would split the update's matrix products: torch stays on one thread, so this holds
    on any x86-64 CPU (MKL on AVX-512 Xeons reduces in a thread-dependent order)."""
    from swarmloc.agents.mappo.config import SetGruConfig
    from swarmloc.agents.mappo.set_gru import train

    def cfg(threads: int) -> SetGruConfig:
        return SetGruConfig(tasks=("ScaleRandom-v1",), frames=800, num_envs=4, rollout_steps=100, epochs=1,
                            minibatches=2, threads=threads, seed=3, run_dir=str(tmp_path / str(threads)),
                            progress=False, eval_every=0, checkpoint_every=0)

    torch.set_num_threads(2)  # what a caller may have set: training pins torch to one thread regardless
    one, two = (train(cfg(n)).actor_state for n in (1, 2))
    assert torch.get_num_threads() == 1
    assert all(torch.equal(one[k], two[k]) for k in one)


def test_training_batches_carry_the_pending_fault_labels_of_what_the_policy_saw():
    """The auxiliary loss's labels: on NLOSStep-v1 (anchors 0, 2, 4 biased from 20 s, ramping over 5 s) no anchor
    channel is labelled before the window and, inside it, only those anchors' are. (Labels v1 of Track A also
    mark peer links whose neighbour's broadcast estimate is off: the swarm's first steps, and inside the window.)"""
    from swarmloc.agents.mappo.collect import Collection
    from swarmloc.agents.mappo.config import SetGruConfig
    from swarmloc.agents.mappo.set_gru import PendingLabels, build_policy
    from swarmloc.envs.tasks.channels import ANCHOR, build_layout
    from swarmloc.envs.tasks.catalogue import get_spec

    cfg = SetGruConfig(tasks=("NLOSStep-v1",), num_envs=2, minibatches=2, frames=400, run_dir="unused")
    envs: list = []
    labels = PendingLabels(envs)
    policy, recurrent = build_policy(_actor(), cfg, labels)
    collection = Collection(cfg.tasks, 2, 100, 1, policy, [{}])
    envs.extend(collection.envs)
    layout = build_layout(get_spec("swarmloc/NLOSStep-v1"))
    anchor = layout.kind == ANCHOR
    biased = anchor & np.isin(layout.target, [0, 2, 4])
    seen = []
    for k in range(3):  # steps 1-100, 101-200, 201-300 (dt 0.1 s)
        recurrent.select(0, fresh=k == 0)
        batch = collection.collect(0)
        seen.append(batch[("uav", "fault_label")].numpy())  # (B, T, N, L)
    collection.shutdown()
    assert not seen[0][..., anchor].any() and not seen[1][:, :-1][..., anchor].any()
    assert seen[2][..., biased].any() and not seen[2][..., anchor & ~biased].any()
