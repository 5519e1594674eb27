"""The CEKF's covariance-intersection peer update (``FilterSettings.peer_update = "ci"``).

Against the readable reference (``cekf_reference.ci_peer_update``), against the closed form of
what covariance intersection promises (no correlation between the UAV's and the neighbour's
errors makes the reported covariance optimistic), and the spec option's contract (the
registered tasks' canonical JSON, hence every suite hash, is what it was before the option).
Also the anchor ranging radius (``Sensors.anchor_max_range``), the other option such a study
needs: with every anchor in range, peers add little to a consistent filter.
"""

from __future__ import annotations

import numpy as np
import pydantic
import pytest

from swarmloc.envs.filter import cekf
from swarmloc.envs.filter.cekf_reference import ci_peer_update
from swarmloc.envs.world.core import LinkTrustCore
from swarmloc.envs.tasks.catalogue import CATALOGUE, get_spec
from swarmloc.envs.world.worlds import make_world

from envs_helpers import assert_kernel_matches_reference, record


@pytest.mark.parametrize("task_id, n_steps", [("swarmloc/HybridNoise10-v1", 25), ("swarmloc/GradualFault-v1", 150),
                                              ("swarmloc/Scale4-v1", 100)])
def test_kernel_matches_reference(task_id, n_steps):
    """Peer ranges (HybridNoise, Scale) and relative positions (GradualFault), random trust."""
    spec, world, x0, imu, z, valid = record(task_id, n_steps, seeds=(5,), filter={"peer_update": "ci"})
    alpha = np.random.default_rng(3).uniform(0.0, 1.0, size=valid.shape)
    P0, args, P_ref = assert_kernel_matches_reference(spec, world, x0, imu, z, valid, alpha, peer_update="ci")
    # and the point update is a different filter on the same data
    x_pt, P_pt = x0.copy(), P0.copy()
    cekf.cekf_run(x_pt, P_pt, *args, np.zeros((len(imu), *x0.shape[:2], 3)))
    assert np.abs(P_pt - P_ref).max() > 1e-3


def _random_problem(rng, m: int):
    """A prior P (6×6), a neighbour covariance B (3×3), a Jacobian H (m×6) and J = ∂h/∂p_j."""
    L = rng.normal(size=(6, 6))
    P = L @ L.T / 6 + 0.05 * np.eye(6)
    M = rng.normal(size=(3, 3))
    B = M @ M.T / 3 * rng.uniform(0.1, 4.0) + 0.01 * np.eye(3)
    if m == 1:
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        H = np.zeros((1, 6))
        H[0, :3] = u
        J = -u[None, :]  # a range: ∂‖p_i − p_j‖/∂p_j = −u
    else:
        H = np.zeros((3, 6))
        H[:, :3] = -np.eye(3)
        J = np.eye(3)  # a relative position z = p_j − p_i
    return P, B, H, J


def _psd_sqrt(A):
    w, V = np.linalg.eigh(A)
    return V @ np.diag(np.sqrt(np.clip(w, 0.0, None))) @ V.T


@pytest.mark.parametrize("m", [1, 3])
def test_ci_covariance_bounds_every_correlation(m):
    """For any cross-covariance X with [[P, X], [Xᵀ, B]] ⪰ 0, the true error covariance of the
    CI estimate, (I − KH) P (I − KH)ᵀ + K (J B Jᵀ + r I) Kᵀ − (I − KH) X Jᵀ Kᵀ − K J Xᵀ (I − KH)ᵀ,
    lies below the P⁺ it reports; the point update with the neighbour as a known point does not."""
    rng = np.random.default_rng(7 + m)
    worst_ci, worst_point = np.inf, np.inf
    for _ in range(60):
        P, B, H, J = _random_problem(rng, m)
        r = rng.uniform(0.01, 1.0)
        x = np.zeros(6)
        # the gain, column by column: x⁺ = K y is linear in y
        K = np.column_stack([ci_peer_update(x, P, e, H, B, r)[0] for e in np.eye(m)])
        _, P_ci, w = ci_peer_update(x, P, np.ones(m), H, B, r)
        S_pt = H @ P @ H.T + r * np.eye(m)
        K_pt = np.linalg.solve(S_pt, H @ P).T
        P_pt = (np.eye(6) - K_pt @ H) @ P
        for _ in range(10):
            C = rng.normal(size=(6, 3))
            C *= rng.uniform(0.0, 1.0) / np.linalg.norm(C, 2)  # ‖C‖₂ ≤ 1: a valid joint covariance
            X = _psd_sqrt(P) @ C @ _psd_sqrt(B)
            for gain, reported, name in ((K, P_ci, "ci"), (K_pt, P_pt, "point")):
                I_KH = np.eye(6) - gain @ H
                true = (I_KH @ P @ I_KH.T + gain @ (J @ B @ J.T + r * np.eye(m)) @ gain.T
                        - I_KH @ X @ J.T @ gain.T - gain @ J @ X.T @ I_KH.T)
                low = np.linalg.eigvalsh(reported - true).min()
                if name == "ci":
                    worst_ci = min(worst_ci, low)
                else:
                    worst_point = min(worst_point, low)
    assert worst_ci >= -1e-10, f"the CI covariance is optimistic by {worst_ci}"
    assert worst_point < -1e-3  # the known-point update is optimistic for some correlations


def test_ci_skips_a_peer_that_adds_nothing():
    """ω = 1 (no update) when the neighbour is far less certain than the UAV."""
    P = np.diag([0.01] * 3 + [0.1] * 3)
    B = np.eye(3) * 100.0
    H = np.zeros((1, 6))
    H[0, 0] = 1.0
    x_post, P_post, w = ci_peer_update(np.zeros(6), P, np.array([0.5]), H, B, 0.04)
    assert w == 1.0 and np.array_equal(P_post, P) and not x_post.any()


def test_point_is_left_out_of_the_canonical_json():
    """Every v0 and v1 task keeps its spec JSON (and suite hashes) as before the option; v2 tasks name split CI."""
    for task_id in CATALOGUE:
        spec = get_spec(task_id)
        if spec.version >= 2:
            assert '"peer_update":"split_ci"' in spec.model_dump_json()
            continue
        assert spec.filter.peer_update == "point"
        assert "peer_update" not in spec.model_dump_json()
    ci = get_spec("swarmloc/NLOS-v1", filter={"peer_update": "ci"})
    assert '"peer_update":"ci"' in ci.model_dump_json()
    assert type(ci).model_validate_json(ci.model_dump_json()) == ci


def test_unknown_peer_update_is_refused():
    with pytest.raises(pydantic.ValidationError, match="'point' or 'ci'"):
        get_spec("swarmloc/NLOS-v1", filter={"peer_update": "exact"})


def test_core_runs_ci_and_keeps_covariances_healthy():
    spec = get_spec("swarmloc/HybridNoise30-v1", filter={"peer_update": "ci"}, duration=20.0)
    core = LinkTrustCore(spec, 2)
    core.reset([1, 2])
    for _ in range(spec.n_steps):
        core.step(np.ones((2, spec.n_uav, spec.n_channels)))
        assert np.array_equal(core.P, np.swapaxes(core.P, -1, -2))
        assert np.linalg.eigvalsh(core.P).min() > 0.0


def test_every_adapter_takes_the_option():
    gymnasium = pytest.importorskip("gymnasium")
    import swarmloc.envs as envs

    env = gymnasium.make("swarmloc/Scale4-v1", filter={"peer_update": "ci"})
    assert env.unwrapped.task_spec.filter.peer_update == "ci"
    assert envs.parallel_env("swarmloc/Scale4-v1", filter={"peer_update": "ci"}).task_spec.filter.peer_update == "ci"


def test_anchor_max_range_drops_exactly_the_far_anchors():
    """An anchor range is valid iff the true distance is within ``anchor_max_range`` (Scale has no other dropout)."""
    spec = get_spec("swarmloc/Scale4-v1", sensors={"anchor_max_range": 11.0}, duration=20.0)
    assert "anchor_max_range" in spec.model_dump_json()
    assert "anchor_max_range" not in get_spec("swarmloc/Scale4-v1").model_dump_json()
    world = make_world(spec, 2)
    world.reset([1, 2])
    anchors = np.asarray(spec.anchors)
    seen_far = seen_near = 0
    for _ in range(spec.n_steps):
        buf = world.sense()
        dist = np.linalg.norm(buf.pos[:, :, None, :] - anchors[None, None], axis=-1)  # (B, N, A)
        valid = buf.valid[:, :, : len(anchors)]
        assert np.array_equal(valid, dist <= 11.0)
        seen_far += int((dist > 11.0).sum())
        seen_near += int((dist <= 11.0).sum())
    assert seen_far > 0 and seen_near > 0


def test_ci_is_the_same_batched_or_single():
    """Determinism: each episode's CI filter sees only its own broadcast covariances."""
    spec = get_spec("swarmloc/HybridNoise10-v1", filter={"peer_update": "ci"}, duration=5.0)
    seeds = [4, 5, 6]
    trust = np.random.default_rng(2).uniform(0.0, 1.0, size=(spec.n_steps, len(seeds), spec.n_uav, spec.n_channels))
    batched = LinkTrustCore(spec, len(seeds))
    batched.reset(seeds)
    for k in range(spec.n_steps):
        batched.step(trust[k])
    for b, seed in enumerate(seeds):
        single = LinkTrustCore(spec, 1)
        single.reset([seed])
        for k in range(spec.n_steps):
            single.step(trust[k, b:b + 1])
        assert np.array_equal(single.x[0], batched.x[b]) and np.array_equal(single.P[0], batched.P[b])


def test_without_peer_links_both_updates_are_one_filter():
    """HybridNoise with the peer links removed: "point" and "ci" give the same filter, bit for bit."""
    out = {}
    for update in ("point", "ci"):
        spec = get_spec("swarmloc/HybridNoise30-v1", sensors={"peers": {"kind": "none"}},
                        filter={"peer_update": update}, duration=5.0)
        core = LinkTrustCore(spec, 2)
        core.reset([1, 2])
        for _ in range(spec.n_steps):
            core.step(np.ones((2, spec.n_uav, spec.n_channels)))
        out[update] = (core.x.copy(), core.P.copy())
    assert np.array_equal(out["point"][0], out["ci"][0]) and np.array_equal(out["point"][1], out["ci"][1])
