"""Covariance intersection, χ² tests and the federated filter pieces against closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from swarmloc.agents.estimators.fusion import (
    adapted_noise,
    allocation_coefficients,
    chi2_fault_test,
    chi2_soft_weight,
    chi2_threshold,
    ci_fuse,
    federated_fuse,
    independent_fuse,
    normalized_innovation_squared,
    residual_ratio,
    share_information,
)

inv = np.linalg.inv


def _spd(rng: np.random.Generator, shape: tuple[int, ...], D: int) -> np.ndarray:
    """Random SPD matrices with condition numbers up to ~1e3."""
    Q, _ = np.linalg.qr(rng.normal(size=shape + (D, D)))
    lam = 10.0 ** rng.uniform(-1.5, 1.5, shape + (D,))
    return (Q * lam[..., None, :]) @ np.swapaxes(Q, -1, -2)


# --------------------------------------------------------------------------- CI


def test_ci_with_identical_inputs_returns_them() -> None:
    rng = np.random.default_rng(0)
    P = _spd(rng, (4, 3), 6)
    x = rng.normal(size=(4, 3, 6))
    xf, Pf, w = ci_fuse(x, P, x, P)
    np.testing.assert_allclose(xf, x, atol=1e-12)
    np.testing.assert_allclose(Pf, P, atol=1e-12 * np.abs(P).max())
    np.testing.assert_allclose(w, 0.5)  # flat objective: the symmetric weight


def test_ci_matches_the_direct_formula_and_minimizes_the_trace() -> None:
    rng = np.random.default_rng(1)
    D = 3
    Pa, Pb = _spd(rng, (20,), D), _spd(rng, (20,), D)
    xa, xb = rng.normal(size=(20, D)), rng.normal(size=(20, D))
    x, P, w = ci_fuse(xa, Pa, xb, Pb)
    grid = np.linspace(0.0, 1.0, 401)
    for k in range(20):
        # slow readable reference: P⁻¹ = ω Pa⁻¹ + (1−ω) Pb⁻¹, x = P (ω Pa⁻¹ xa + (1−ω) Pb⁻¹ xb)
        P_ref = inv(w[k] * inv(Pa[k]) + (1 - w[k]) * inv(Pb[k]))
        x_ref = P_ref @ (w[k] * inv(Pa[k]) @ xa[k] + (1 - w[k]) * inv(Pb[k]) @ xb[k])
        np.testing.assert_allclose(P[k], P_ref, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(x[k], x_ref, rtol=1e-9, atol=1e-10)
        tr = [np.trace(inv(o * inv(Pa[k]) + (1 - o) * inv(Pb[k]))) for o in grid]
        assert np.trace(P[k]) <= min(tr) * (1 + 1e-12)


def test_ci_is_never_tighter_than_independent_fusion() -> None:
    rng = np.random.default_rng(2)
    for D in (2, 3, 6):
        Pa, Pb = _spd(rng, (300,), D), _spd(rng, (300,), D)
        xa, xb = rng.normal(size=(300, D)), rng.normal(size=(300, D))
        _, P_ci, _ = ci_fuse(xa, Pa, xb, Pb)
        _, P_opt = independent_fuse(xa, Pa, xb, Pb)
        assert np.linalg.eigvalsh(P_ci - P_opt).min() >= -1e-12
        # and never looser than the better input
        tr = lambda P: np.trace(P, axis1=-2, axis2=-1)  # noqa: E731
        assert (tr(P_ci) <= np.minimum(tr(Pa), tr(Pb)) * (1 + 1e-12)).all()


def test_ci_picks_the_dominant_estimate() -> None:
    P_small, P_big = 0.01 * np.eye(3), 100.0 * np.eye(3)
    x, P, w = ci_fuse(np.ones(3), P_small, np.zeros(3), P_big)
    assert w == pytest.approx(1.0)
    np.testing.assert_allclose(x, np.ones(3), atol=1e-9)
    np.testing.assert_allclose(P, P_small, atol=1e-12)


def test_ci_broadcasts_a_shared_covariance() -> None:
    rng = np.random.default_rng(3)
    xa, xb = rng.normal(size=(5, 4, 3)), rng.normal(size=(5, 4, 3))
    Pa, Pb = _spd(rng, (5, 4), 3), _spd(rng, (), 3)
    x, P, w = ci_fuse(xa, Pa, xb, Pb)
    assert x.shape == (5, 4, 3) and P.shape == (5, 4, 3, 3) and w.shape == (5, 4)
    x1, P1, w1 = ci_fuse(xa[2, 1], Pa[2, 1], xb[2, 1], Pb)
    np.testing.assert_allclose(x[2, 1], x1, atol=1e-12)
    np.testing.assert_allclose(P[2, 1], P1, atol=1e-12)


def test_independent_fuse_matches_the_information_form() -> None:
    rng = np.random.default_rng(4)
    Pa, Pb = _spd(rng, (10,), 4), _spd(rng, (10,), 4)
    xa, xb = rng.normal(size=(10, 4)), rng.normal(size=(10, 4))
    x, P = independent_fuse(xa, Pa, xb, Pb)
    P_ref = inv(inv(Pa) + inv(Pb))
    x_ref = (P_ref @ (inv(Pa) @ xa[..., None] + inv(Pb) @ xb[..., None]))[..., 0]
    np.testing.assert_allclose(P, P_ref, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(x, x_ref, rtol=1e-9, atol=1e-10)


def test_fusion_errors_name_the_bad_value() -> None:
    x, P = np.zeros(3), np.eye(3)
    with pytest.raises(ValueError, match=r"P_b must have shape \(\.\.\., 3, 3\)"):
        ci_fuse(x, P, x, np.eye(2))
    with pytest.raises(ValueError, match="x_a must be finite; got nan"):
        ci_fuse(np.array([0.0, np.nan, 0.0]), P, x, P)
    with pytest.raises(ValueError, match="P_a must be symmetric positive definite"):
        ci_fuse(x, -P, x, P)


# --------------------------------------------------------------------------- χ² tests


def test_chi2_thresholds_from_the_papers() -> None:
    assert chi2_threshold(0.01, 3) == pytest.approx(11.34, abs=0.01)  # federated T_D
    assert chi2_threshold(0.05, 6) == pytest.approx(12.59, abs=0.01)  # dtvirm §3.7
    with pytest.raises(ValueError, match="p_false_alarm must be in"):
        chi2_threshold(0.0, 3)


def test_chi2_soft_weight_is_one_inside_the_gate_and_decreasing_beyond() -> None:
    gate = chi2_threshold(0.05, 1)
    inside = np.linspace(0.0, gate - 1e-9, 50)
    np.testing.assert_array_equal(chi2_soft_weight(inside), 1.0)
    beyond = np.linspace(gate, gate + 20.0, 200)
    w = chi2_soft_weight(beyond)
    assert w[0] == pytest.approx(1.0)  # continuous at the gate
    assert (np.diff(w) < 0).all() and (w > 0).all()
    # dof and softness: the 6-dof gate is 12.59; a larger σ fades more slowly
    assert chi2_soft_weight(12.5, dof=6) == 1.0 and chi2_soft_weight(13.0, dof=6) < 1.0
    assert chi2_soft_weight(10.0, sigma=2.0) > chi2_soft_weight(10.0, sigma=1.0)
    with pytest.raises(ValueError, match="nis must be >= 0"):
        chi2_soft_weight(np.array([1.0, np.nan]))


def test_fault_test_false_alarm_rate_and_detection() -> None:
    rng = np.random.default_rng(5)
    S = _spd(rng, (), 3)
    r = rng.multivariate_normal(np.zeros(3), S, size=40000)
    lam, fault = chi2_fault_test(r, S, p_false_alarm=0.01)
    np.testing.assert_allclose(lam[:5], np.einsum("ni,ij,nj->n", r[:5], inv(S), r[:5]), rtol=1e-10)
    # binomial(40000, 0.01): sd ≈ 0.0005
    assert abs(fault.mean() - 0.01) < 0.0025
    big = 10.0 * np.sqrt(np.diag(S))
    assert chi2_fault_test(big, S)[1]


def test_normalized_innovation_squared_broadcasts() -> None:
    rng = np.random.default_rng(6)
    S = _spd(rng, (4,), 2)
    r = rng.normal(size=(7, 4, 2))
    lam = normalized_innovation_squared(r, S)
    assert lam.shape == (7, 4)
    np.testing.assert_allclose(lam, np.einsum("bni,nij,bnj->bn", r, inv(S), r), rtol=1e-10)


# --------------------------------------------------------------------------- federated


def test_allocation_coefficients_eq17_20() -> None:
    rng = np.random.default_rng(7)
    dv = np.abs(rng.normal(0, 2.0, (100, 2)))
    beta = allocation_coefficients(dv)
    np.testing.assert_allclose(beta.sum(-1), 1.0, rtol=1e-15)
    assert ((beta > 0) & (beta <= 1)).all()
    # both consistent: equal shares; one faulty: β = d/|ΔV| before normalization
    np.testing.assert_allclose(allocation_coefficients([0.5, 0.2]), [0.5, 0.5])
    np.testing.assert_allclose(allocation_coefficients([0.5, 1.7], d=0.85), [2 / 3, 1 / 3])
    np.testing.assert_allclose(allocation_coefficients(np.full((3, 4), 9.0)).sum(-1), 1.0)


def test_residual_ratio_eq19() -> None:
    r = np.array([1.0, 2.0, 2.0])
    S = np.diag([1.0, 2.0, 6.0])
    assert residual_ratio(r, S) == pytest.approx(9.0 / 9.0)


def test_adapted_noise_eq21() -> None:
    R = np.diag([1.0, 4.0, 9.0])
    np.testing.assert_allclose(adapted_noise(R, 0.5), R)  # equal share: R unchanged
    np.testing.assert_allclose(adapted_noise(R, 0.25), 1.5 * R)  # R + 2(0.5 − 0.25) R
    np.testing.assert_allclose(adapted_noise(R, 0.75), 0.5 * R)
    np.testing.assert_allclose(adapted_noise(np.stack([R, R]), np.array([0.25, 0.75]))[1], 0.5 * R)
    with pytest.raises(ValueError, match="beta_t must be in"):
        adapted_noise(R, 1.0)


def test_federated_fuse_of_identical_subfilters_returns_their_state() -> None:
    rng = np.random.default_rng(8)
    x = rng.normal(size=(6, 15))
    P = _spd(rng, (6,), 15)
    xg, Pg = federated_fuse(np.stack([x, x], 1), np.stack([P, P], 1))
    np.testing.assert_allclose(xg, x, atol=1e-9)
    np.testing.assert_allclose(Pg, P / 2, rtol=1e-9, atol=1e-12)


def test_federated_fuse_eq31_and_isolation() -> None:
    rng = np.random.default_rng(9)
    x = rng.normal(size=(5, 3, 4))
    P = _spd(rng, (5, 3), 4)
    xg, Pg = federated_fuse(x, P)
    Y = inv(P)
    P_ref = inv(Y.sum(1))
    x_ref = (P_ref @ (Y @ x[..., None]).sum(1))[..., 0]
    np.testing.assert_allclose(Pg, P_ref, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(xg, x_ref, rtol=1e-9, atol=1e-10)
    # two sub-filters = independent fusion
    x2, P2 = federated_fuse(x[:, :2], P[:, :2])
    xi, Pi = independent_fuse(x[:, 0], P[:, 0], x[:, 1], P[:, 1])
    np.testing.assert_allclose(x2, xi, atol=1e-9)
    np.testing.assert_allclose(P2, Pi, atol=1e-9)
    # an isolated (faulty) sub-filter does not take part
    valid = np.array([True, False, False])
    xv, Pv = federated_fuse(x, P, valid)
    np.testing.assert_allclose(xv, x[:, 0], atol=1e-9)
    np.testing.assert_allclose(Pv, P[:, 0], rtol=1e-9, atol=1e-12)
    with pytest.raises(ValueError, match="every sub-filter is isolated"):
        federated_fuse(x, P, np.zeros(3, dtype=bool))


def test_share_information_conserves_the_global_information() -> None:
    rng = np.random.default_rng(10)
    xg, Pg, Q = rng.normal(size=(4, 6)), _spd(rng, (4,), 6), _spd(rng, (4,), 6)
    beta = allocation_coefficients(np.abs(rng.normal(0, 2.0, (4, 2))))
    xi, Pi, Qi = share_information(xg, Pg, Q, beta)
    assert xi.shape == (4, 2, 6) and Pi.shape == (4, 2, 6, 6)
    np.testing.assert_allclose(Pi[:, 1], Pg / beta[:, 1, None, None])
    np.testing.assert_allclose(Qi[:, 0], Q / beta[:, 0, None, None])
    # Σ_i (P_g / β_i)⁻¹ = P_g⁻¹ since Σ β_i = 1: fusing the shares gives back the global estimate
    x_back, P_back = federated_fuse(xi, Pi)
    np.testing.assert_allclose(x_back, xg, atol=1e-9)
    np.testing.assert_allclose(P_back, Pg, rtol=1e-8, atol=1e-10)
