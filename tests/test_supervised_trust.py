"""supervised-trust: feature assembly, trust range and determinism, the training command, the shipped weights."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from swarmloc.agents.protocols import LinkTrustPolicy, TrustInput
from swarmloc.agents.trust.supervised import (
    FEATURE_NAMES,
    HISTORY,
    WEIGHTS_PATH,
    ChannelHistory,
    ClassifierWeights,
    SupervisedTrust,
    supervised_trust,
)
from swarmloc.envs.tasks.catalogue import get_spec
from swarmloc.envs.world.core import LinkTrustCore
from swarmloc.envs.world.observation import N_FEATURES as N_OBS
from swarmloc.envs.world.observation import NIS, VALID, build_observation, kind_one_hot

REPO = Path(__file__).resolve().parents[1]
PREV = FEATURE_NAMES.index("nis_prev1")
PRESENT = FEATURE_NAMES.index("present_prev1")


def _obs(nis: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """``(B, N, L, 11)`` observation with the given squashed NIS and validity (other columns 0)."""
    obs = np.zeros((*nis.shape, N_OBS), np.float32)
    obs[..., NIS] = nis * valid
    obs[..., VALID] = valid
    return obs


def test_nis_history_shifts_newest_first_and_marks_absent_steps():
    hist = ChannelHistory(HISTORY)
    hist.reset(1, 1, 2)
    steps = [(0.1, True), (0.2, False), (0.3, True), (0.4, True), (0.5, True), (0.6, True)]
    for k, (value, present) in enumerate(steps):
        x = hist.features(_obs(np.full((1, 1, 2), value, np.float32), np.array([[[present, True]]])))
        before = steps[:k][::-1][:HISTORY]  # newest first
        expect_nis = [v if p else 0.0 for v, p in before] + [0.0] * (HISTORY - len(before))
        expect_present = [float(p) for _, p in before] + [0.0] * (HISTORY - len(before))
        np.testing.assert_allclose(x[0, 0, 0, PREV:PREV + HISTORY], expect_nis, rtol=1e-6)
        np.testing.assert_array_equal(x[0, 0, 0, PRESENT:PRESENT + HISTORY], expect_present)
        # the other channel was present every step
        assert x[0, 0, 1, PRESENT:PRESENT + HISTORY].sum() == min(k, HISTORY)


def test_reset_empties_the_history():
    hist = ChannelHistory(HISTORY)
    hist.reset(2, 1, 1)
    for _ in range(3):
        hist.features(_obs(np.full((2, 1, 1), 0.7, np.float32), np.ones((2, 1, 1), bool)))
    hist.reset(2, 1, 1)
    x = hist.features(_obs(np.full((2, 1, 1), 0.7, np.float32), np.ones((2, 1, 1), bool)))
    assert not x[..., PREV:].any()


def test_feature_names_match_the_assembly():
    hist = ChannelHistory(HISTORY)
    hist.reset(1, 2, 3)
    assert hist.features(np.zeros((1, 2, 3, N_OBS), np.float32)).shape == (1, 2, 3, len(FEATURE_NAMES))


def _rollout(policy, task: str, seeds: list[int], steps: int) -> np.ndarray:
    """Closed-loop trust of ``policy`` on ``task`` for ``steps`` steps: ``(T, B, N, L)``."""
    spec = get_spec(task)
    core = LinkTrustCore(spec, len(seeds))
    one_hot = kind_one_hot(core.layout.kind)
    policy.reset(len(seeds), core.layout, np.arange(len(seeds)))
    step = core.reset(np.array(seeds))
    out = []
    for k in range(1, steps + 1):
        obs = build_observation(step, one_hot)
        inp = TrustInput.view(obs, step.resid, step.pred, step.nis, step.applied, step.jerk, step.valid,
                              k * spec.dt, k)
        alpha = policy.act(inp)
        out.append(alpha.copy())
        step = core.step(alpha)
    return np.array(out)


@pytest.fixture(scope="module")
def shipped() -> SupervisedTrust:
    return supervised_trust()


def test_shipped_weights_load_and_run_a_short_episode(shipped):
    assert isinstance(shipped, LinkTrustPolicy) and not shipped.privileged
    assert shipped.flops_per_channel > 0
    alpha = _rollout(shipped, "swarmloc/ScaleRandom-v2", [7], 40)
    assert alpha.shape[:3] == (40, 1, 8)
    assert np.isfinite(alpha).all() and (alpha >= 0).all() and (alpha <= 1).all()
    assert (alpha < 0.99).any(), "the classifier never lowered a trust in 40 steps"
    record = json.loads(WEIGHTS_PATH.with_suffix(".json").read_text())
    assert record["method"] == "supervised-trust" and record["command"].startswith("swarmloc train supervised-trust")
    assert max(hi for _, hi in record["fit"]["training_seeds"].values()) < 1_000_000
    assert record["heldout"]["all"]["roc_auc"] > 0.5


def test_trust_is_deterministic_and_batched_equals_single(shipped):
    task = "swarmloc/AnchorNLOSRandom-v2"
    batched = _rollout(shipped, task, [3, 11], 30)
    again = _rollout(supervised_trust(), task, [3, 11], 30)
    np.testing.assert_array_equal(batched, again)
    for b, seed in enumerate([3, 11]):
        np.testing.assert_array_equal(batched[:, b], _rollout(shipped, task, [seed], 30)[:, 0])


def test_untrained_kinds_and_absent_channels_get_full_trust(shipped):
    from tests.trust_helpers import trust_layout

    layout = trust_layout([0, 2])  # an anchor and a landmark (never in the training tasks)
    shipped.reset(1, layout, np.zeros(1, np.int64))
    obs = _obs(np.full((1, 1, 2), 0.99, np.float32), np.array([[[False, True]]]))
    obs[..., 5:10] = kind_one_hot(layout.kind)
    inp = TrustInput.view(obs, np.zeros((1, 1, 2)), np.zeros((1, 1, 2)), np.zeros((1, 1, 2)), np.ones((1, 1, 2)),
                          np.zeros((1, 1)), obs[..., VALID] > 0.5, 0.1, 1)
    np.testing.assert_array_equal(shipped.act(inp), 1.0)


def test_weights_round_trip(tmp_path, shipped):
    path = tmp_path / "w.npz"
    shipped.weights.save(path)
    loaded = ClassifierWeights.load(path)
    x = np.random.default_rng(0).random((5, len(FEATURE_NAMES)))
    np.testing.assert_array_equal(loaded.logit(x), shipped.weights.logit(x))


def test_training_refuses_test_and_dev_seeds(tmp_path):
    from swarmloc.bench.training.supervised_trust import TrainSupervisedTrustArgs, train_supervised_trust

    for start in (1_000_000, 2_000_000):
        with pytest.raises(ValueError, match="training seeds must be in"):
            train_supervised_trust(TrainSupervisedTrustArgs(seed_start=start, episodes=1, weights_out=tmp_path / "w.npz"))
    assert not (tmp_path / "w.npz").exists()


def test_train_cli_smoke(tmp_path):
    """``swarmloc train supervised-trust`` on a few hundred frames writes loadable weights and their record."""
    out = tmp_path / "st.npz"
    cmd = [str(Path(sys.executable).parent / "swarmloc"), "train", "supervised-trust", "--episodes", "1",
           "--heldout-episodes", "1", "--steps", "10", "--epochs", "1", "--hidden", "4", "--weights-out", str(out)]
    proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=240, check=False)
    assert proc.returncode == 0, proc.stderr[-3000:] + proc.stdout[-2000:]
    record = json.loads(out.with_suffix(".json").read_text())
    assert record["data"]["all"]["frames"] < 2000
    assert set(record["heldout"]) == {"swarmloc/ScaleRandom-v2", "swarmloc/AnchorNLOSRandom-v2", "all"}
    assert "--episodes 1" in record["command"]
    policy = supervised_trust(weights=out)
    assert _rollout(policy, "swarmloc/AnchorNLOSRandom-v2", [0], 5).shape == (5, 1, 1, 8)
