"""IMM family (imm-arkf): models, mixing, the ARKF pieces, and the estimators on the world."""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarmloc.agents.estimators.imm import (
    ImmConfig,
    ImmEstimator,
    ImmState,
    correntropy_gain,
    fading_factor,
    imm_step,
    polar_measurement,
    transition_matrices,
)
from swarmloc.agents.protocols import TaskFacts, episode_keys
from swarmloc.envs.tasks.catalogue import get_spec
from swarmloc.envs.world.sim import World

from track_b_helpers import play_blind

W = 2.0 * math.pi / 180.0


def circle_states(omega: float, speed: float, dt: float, n: int) -> np.ndarray:
    """(n, 6) exact states on a circle turning at ``omega`` (left for omega > 0)."""
    t = np.arange(n) * dt
    th = omega * t
    rad = speed / omega
    p = np.stack([rad * np.sin(th), rad * (1 - np.cos(th)), np.full(n, 3.0)], axis=1)
    v = np.stack([speed * np.cos(th), speed * np.sin(th), np.zeros(n)], axis=1)
    return np.concatenate([p, v], axis=1)


def test_ct_models_propagate_a_coordinated_turn_exactly():
    dt = 0.1
    F = transition_matrices(W, dt)
    left = circle_states(W, 2.0, dt, 50)
    right = circle_states(-W, 2.0, dt, 50)
    assert np.allclose(left[1:], left[:-1] @ F[1].T, atol=1e-12)  # CT+ = left turn
    assert np.allclose(right[1:], right[:-1] @ F[2].T, atol=1e-12)  # CT− = right turn
    cv = np.eye(6)
    cv[0, 3] = cv[1, 4] = cv[2, 5] = dt
    assert np.array_equal(F[0], cv)


def _single_filter_run(z_seq: np.ndarray, variant: str, cfg: ImmConfig, x0: np.ndarray, dt: float
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Feed fixes (T, 3) to one IMM filter; returns μ (T, M) and states (T, M, 6)."""
    F = transition_matrices(cfg.turn_rate, dt)
    st = ImmState(x=np.tile(x0, (1, 1, 3, 1)), P=np.tile(np.eye(6) * 0.01, (1, 1, 3, 1, 1)),
                  mu=np.array(cfg.mu0, dtype=float).reshape(1, 1, 3))
    R = np.eye(3)[None, None] * (cfg.r or 1.0)
    mus, xs = [], []
    for z in z_seq:
        st, _ = imm_step(st, z.reshape(1, 1, 3), np.ones((1, 1), bool), R, variant, cfg, F, cfg.q * np.eye(6))
        mus.append(st.mu[0, 0].copy())
        xs.append(st.x[0, 0].copy())
    return np.array(mus), np.array(xs)


@pytest.mark.parametrize("variant", ["kf", "ekf", "arkf"])
def test_mode_probabilities_sum_to_one_and_favour_the_turn_direction(variant):
    dt = 0.1
    cfg = ImmConfig(r=1e-4, q=1e-6)
    for omega, favoured in ((W, 1), (-W, 2)):
        truth = circle_states(omega, 2.0, dt, 200)
        mu, _ = _single_filter_run(truth[1:, :3], variant, cfg, truth[0].reshape(1, 1, 1, 6), dt)
        assert np.allclose(mu.sum(axis=1), 1.0)
        assert (mu >= 0).all()
        late = mu[100:].mean(axis=0)
        others = [m for m in range(3) if m != favoured]
        assert late[favoured] > late[others].max(), (omega, late)


def test_arkf_reduces_to_kf_with_wide_kernels_and_unit_fading():
    rng = np.random.default_rng(3)
    dt = 0.1
    truth = circle_states(0.2, 2.0, dt, 80)
    z = truth[1:, :3] + rng.normal(0, 0.7, (79, 3)) + (rng.uniform(size=(79, 1)) < 0.1) * 6.0
    x0 = truth[0].reshape(1, 1, 1, 6)
    wide = ImmConfig(sigma1=1e7, sigma2=1e7, fading=False)
    mu_kf, x_kf = _single_filter_run(z, "kf", wide, x0, dt)
    mu_ar, x_ar = _single_filter_run(z, "arkf", wide, x0, dt)
    assert np.allclose(x_ar, x_kf, atol=1e-9) and np.allclose(mu_ar, mu_kf, atol=1e-9)
    # the paper's kernels do change the answer on the same outlier-laden data
    _, x_rob = _single_filter_run(z, "arkf", ImmConfig(), x0, dt)
    assert not np.allclose(x_rob, x_kf, atol=1e-3)


def test_correntropy_gain_is_identity_at_zero_residual_and_only_downweights():
    rng = np.random.default_rng(0)
    e = rng.normal(0, 3, (200, 3))
    G = correntropy_gain(e, 0.15, 2.0, 8.0)
    assert np.allclose(correntropy_gain(np.zeros((1, 3)), 0.15, 2.0, 8.0), np.eye(3))
    eig = np.linalg.eigvalsh(np.eye(3) - G)
    assert eig.min() > -1e-12  # Γ̃ ⪯ I: R̄ ⪰ R
    assert np.linalg.eigvalsh(G).min() > 0
    raw0 = correntropy_gain(np.zeros(2), 0.15, 2.0, 8.0, normalize=False)
    a, b = 0.15 / 4.0, 2 * 0.85 / 64.0
    assert np.allclose(raw0, a * np.eye(2) + b * np.array([[1.0, -1.0], [-1.0, 1.0]]))


def test_fading_factor_brings_the_statistic_to_the_gate():
    rng = np.random.default_rng(1)
    A = rng.normal(size=(50, 6, 6))
    P_f = A @ np.swapaxes(A, -1, -2) * 0.01 + 0.01 * np.eye(6)
    H = np.hstack([np.eye(3), np.zeros((3, 3))])
    Q = 0.01 * np.eye(6)
    R = np.broadcast_to(np.eye(3), (50, 3, 3))
    r = rng.normal(0, 3.0, (50, 3))
    lam = fading_factor(r, H, P_f, Q, R, 7.81, 50)
    S = lam[:, None, None] * (H @ P_f @ H.T) + H @ Q @ H.T + R
    d2 = np.einsum("bi,bij,bj->b", r, np.linalg.inv(S), r)
    d2_unit = np.einsum("bi,bij,bj->b", r, np.linalg.inv(H @ P_f @ H.T + H @ Q @ H.T + R), r)
    assert (lam >= 1.0).all()
    assert np.allclose(lam[d2_unit <= 7.81], 1.0)
    assert np.all(d2[d2_unit > 7.81] <= 7.81 + 1e-6)


def test_a_lost_fix_leaves_the_arkf_as_a_plain_prediction():
    """A fix that did not arrive (valid = False) carries no evidence: its residual must neither update the
    state nor inflate the prediction through the fading factor."""
    dt, cfg = 0.1, ImmConfig()
    F, Q = transition_matrices(cfg.turn_rate, dt), cfg.q * np.eye(6)
    st = ImmState(x=np.zeros((1, 1, 3, 6)), P=np.tile(np.eye(6) * 0.1, (1, 1, 3, 1, 1)),
                  mu=np.array(cfg.mu0).reshape(1, 1, 3))
    R = np.eye(3)[None, None]
    far = np.array([[[6.0, 0.0, 0.0]]])  # a 6σ residual: past the χ² gate even with the robust R̄
    lost, info = imm_step(st, far, np.zeros((1, 1), bool), R, "arkf", cfg, F, Q)
    kf, _ = imm_step(st, far, np.zeros((1, 1), bool), R, "kf", cfg, F, Q)
    assert np.allclose(info.fading, 1.0) and np.allclose(info.trust, 0.0)
    assert np.allclose(lost.x, kf.x) and np.allclose(lost.P, kf.P) and np.allclose(lost.mu, kf.mu)
    _, seen = imm_step(st, far, np.ones((1, 1), bool), R, "arkf", cfg, F, Q)
    assert (seen.fading > 1.0).all()


def test_polar_jacobian_matches_finite_differences():
    p = np.array([[3.0, 5.0, 2.0], [-7.0, 1.5, 0.0]])
    st = np.array([0.0, -40.0])
    _, H = polar_measurement(p, st)
    eps = 1e-6
    for d in range(3):
        dp = np.zeros(3)
        dp[d] = eps
        num = (polar_measurement(p + dp, st)[0] - polar_measurement(p - dp, st)[0]) / (2 * eps)
        assert np.allclose(H[:, :, d], num, atol=1e-7)


def _episode(variant: str, seeds: list[int], poison_truth: bool = False, duration: float = 4.0):
    def modes_sum_to_one(est: ImmEstimator, _) -> None:
        assert np.allclose(est.mode_probabilities.sum(axis=-1), 1.0)

    spec = get_spec("HybridNoise30-v0", duration=duration)
    return play_blind(ImmEstimator(variant), spec, seeds, poison_truth, check=modes_sum_to_one).positions


@pytest.mark.parametrize("variant", ["kf", "ekf", "arkf"])
def test_estimators_are_deterministic_batched_and_blind_to_truth(variant):
    batched = _episode(variant, [4, 9])
    assert np.isfinite(batched).all()
    assert np.array_equal(batched, _episode(variant, [4, 9], poison_truth=True))
    assert np.array_equal(batched[:, 1:], _episode(variant, [9]))


def test_config_rejects_bad_values():
    with pytest.raises(ValueError, match="row-stochastic"):
        ImmConfig(transition=((0.5, 0.5, 0.5),) * 3)
    with pytest.raises(ValueError, match="mu0"):
        ImmConfig(mu0=(0.5, 0.5, 0.5))
    with pytest.raises(ValueError, match="variant"):
        ImmEstimator("ukf")  # type: ignore[arg-type]
    spec = get_spec("Ideal-v0")
    world = World(spec, 1)
    facts = TaskFacts.from_spec(spec, world.layout, world.reset([0]), episode_keys([0]))
    with pytest.raises(ValueError, match="GPS"):
        ImmEstimator("kf").reset(facts, facts.x0)


def test_cross_kernel_leaves_a_gross_outlier_much_of_its_weight_off_the_common_direction():
    """What the v1 reproduction's reading says of Γ̃ (h = 0.15, σ₁ = 2, σ₂ = 8, eq. 22–27)."""
    G = correntropy_gain(np.array([20.0, 15.0, 10.0]), 0.15, 2.0, 8.0)
    w, V = np.linalg.eigh(G)
    np.testing.assert_allclose(w, [0.0, 0.394, 0.559], atol=1e-3)
    # the suppressed direction is the common one (all axes off together)
    assert abs(V[:, 0] @ np.ones(3)) / math.sqrt(3) > 0.99


@pytest.mark.parametrize("version", [0, 1])
def test_reproduce_immarkf_runs_each_version(tmp_path, version):
    import json

    from swarmloc.bench.reproduce.immarkf import reproduce_immarkf

    path = reproduce_immarkf(tmp_path, seeds=2, duration=2.0, version=version)
    text = path.read_text()
    assert f"HybridNoise{{10,30,50}}-v{version}" in text and "### Reading" in text
    raw = json.loads(path.with_suffix(".json").read_text())
    assert raw["version"] == version and len(raw["rmse"]["imm-arkf|30|nominal"]) == 2
    with pytest.raises(ValueError, match="version must be one of"):
        reproduce_immarkf(tmp_path, seeds=2, version=3)
