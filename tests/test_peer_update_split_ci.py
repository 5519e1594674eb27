"""The CEKF's split covariance intersection peer update (``FilterSettings.peer_update = "split_ci"``).

Kernel against the readable reference on every channel kind; closed forms (two static UAVs,
one anchor each, one peer range); the bound it promises (the reported covariance bounds the
true one for every correlation of the dependent parts); all peers of a step fused together
(the prior rescaled once, copies of one neighbour counted once); consistency (mean position
NEES of uniform trust on fault-free tasks with peers, dev seeds); the fused core step against
the batch kernels; no peer channel, no change against ``"point"``; the spec option.
"""

from __future__ import annotations

import numpy as np
import pydantic
import pytest

from swarmloc.envs.filter import cekf
from swarmloc.envs.filter.cekf_reference import PeerRows, split_ci_peer_update, split_ci_update_reference
from swarmloc.envs.tasks.catalogue import get_spec
from swarmloc.envs.tasks.channels import ANCHOR, PEER
from swarmloc.envs.tasks.seeds import DEV_SEED_START
from swarmloc.envs.tasks.specs import Faults
from swarmloc.envs.world import cost
from swarmloc.envs.world.core import LinkTrustCore

from envs_helpers import assert_kernel_matches_reference, batch_and_singles, record, sense

SPLIT = cekf.PEER_UPDATE_CODES["split_ci"]
FAULT_FREE = Faults().model_dump()
#: between them every channel kind: anchors and peer ranges; peer ranges, landmarks, anchors
#: and GPS; GPS and relative positions with anchors and landmarks; TDOA (no peers)
KIND_CASES = {
    "Scale4": ("swarmloc/Scale4-v1", 120, {}),
    "Indoor+anchors+gps": ("swarmloc/Indoor-v1", 80,
                           {"anchors": [[0, 0, 3], [20, 0, 3], [20, 20, 3], [0, 20, 3]],
                            "sensors": {"gps_sigma": [1.0] * 6, "anchor_max_range": 14.0}}),
    "GradualFault+anchors+landmarks": ("swarmloc/GradualFault-v1", 150,
                                       {"anchors": [[0, 0, 3], [20, 0, 3], [20, 20, 3]],
                                        "landmarks": [[5, 5, 0], [10, 3, 1]]}),
    "HybridNoise10": ("swarmloc/HybridNoise10-v1", 40, {}),
    "TDOA": ("swarmloc/TDOA-v1", 60, {}),
}


@pytest.mark.parametrize("case", sorted(KIND_CASES))
def test_kernel_matches_reference(case):
    """``cekf_run`` == ``run_reference`` within 1e-9 under random trust (skipping, inflation, faults on)."""
    task_id, n_steps, over = KIND_CASES[case]
    spec, world, x0, imu, z, valid = record(task_id, n_steps, seeds=(5, 6), filter={"peer_update": "split_ci"},
                                            **over)
    alpha = np.random.default_rng(3).uniform(0.0, 1.0, size=valid.shape)
    assert_kernel_matches_reference(spec, world, x0, imu, z, valid, alpha, peer_update="split_ci")


# --------------------------------------------------------------------------- closed forms

#: channels of both UAVs: anchor 0, anchor 1, the peer; UAV 0 ranges anchor 0, UAV 1 anchor 1
KIND = np.array([[ANCHOR, ANCHOR, PEER], [ANCHOR, ANCHOR, PEER]])
TARGET = np.array([[0, 1, 1], [0, 1, 0]])
ANCHORS = np.array([[-4.0, 0.0, 0.0], [7.0, 0.0, 0.0]])
VALID = np.array([[[True, False, True], [False, True, True]]])


def _two_static_uavs(P0, N0, P1, N1, r_anchor, r_peer, peer_trust=1.0):
    """Two static UAVs on the x axis at their priors (0, 0, 0) and (3, 0, 0), one anchor each (at −4 and 7 on
    the x axis), one peer range each way. Returns the kernel's and the reference's (x⁺, P⁺, N⁺) of UAV 0 and
    the inputs."""
    x = np.zeros((1, 2, 6))
    x[0, 1, 0] = 3.0
    P = np.stack([P0, P1])[None].copy()
    N = np.stack([N0, N1])[None].copy()
    z = np.zeros((1, 2, 3, 3))
    z[0, 0, 0, 0], z[0, 0, 2, 0] = 4.3, 2.8  # UAV 0: anchor 0 (prior range 4), the peer (prior range 3)
    z[0, 1, 1, 0], z[0, 1, 2, 0] = 3.9, 2.8
    alpha = np.ones((1, 2, 3))
    alpha[0, :, 2] = peer_trust
    r0 = np.array([[r_anchor, r_anchor, r_peer]] * 2)
    prior_pos = x[:, :, :3].copy()
    ref = split_ci_update_reference(x[0, 0], P[0, 0], N[0, 0], z[0, 0], VALID[0, 0], alpha[0, 0], KIND[0],
                                    TARGET[0], r0[0], ANCHORS, np.zeros((0, 3)), prior_pos[0], P[0], N[0], 0.05, 0.01)
    active, flops = np.zeros((1, 2, 3), dtype=bool), np.zeros((1, 2))
    cekf.cekf_update(x, P, z, VALID, alpha, KIND, TARGET, r0, ANCHORS, np.zeros((0, 3)), prior_pos, 0.05, 0.01,
                     active, flops, SPLIT, N)
    assert active[0, 0].tolist() == [True, False, True]
    return (x[0, 0], P[0, 0], N[0, 0]), ref[:3]


def _hand_split_ci(p, n_x, d_yz, n_yz, q, m, pj, nj, r_a, r_p, w, z_a=4.3, z_p=2.8):
    """UAV 0 of ``_two_static_uavs`` derived by hand on the axes (everything decouples: every row is along x).

    UAV 0: P = diag(p, d_yz + n_yz, d_yz + n_yz, q, q, q), N = diag(n_x, n_yz, n_yz, m, m, m); the
    neighbour's x variance pj of which nj independent; ω_0 = w. Returns (x⁺_x, P⁺ diagonal, N⁺_xx, tr P⁺).
    """
    # the anchor along +x: k = p / (p + r_a); N_old = (1 − k)² n_x, N_new = k² r_a, D' = (1 − k)² (p − n_x)
    k = p / (p + r_a)
    x_abs = k * (z_a - 4.0)
    n_new, n_ind = k * k * r_a, (1 - k) ** 2 * n_x + k * k * r_a
    d_abs = (1 - k) ** 2 * (p - n_x)
    # one peer: ω_1 = 1 − ω_0, R = r_p + nj + (pj − nj)/(1 − ω_0); P1_xx = D'/ω_0 + N'; y and z only rescaled
    a_x = d_abs / w + n_ind
    r = r_p + nj + (pj - nj) / (1.0 - w)
    g = a_x / (a_x + r)
    p_yz = d_yz / w + n_yz
    # u = −e_x, y = z − 3 − u·(x' − x⁻) = z − 3 + x'_x; x⁺ = x' + K y with K_x = −g
    x_post = x_abs - g * (z_p - 3.0 + x_abs)
    diag = [a_x * (1 - g), p_yz, p_yz] + [(q - m) / w + m] * 3
    return x_post, diag, (1 - g) ** 2 * n_new + g * g * r_p, float(np.sum(diag))


@pytest.mark.parametrize("peer_trust", [1.0, 0.5])
def test_closed_form_two_static_uavs(peer_trust):
    """Two static UAVs, one anchor each, one peer range: mean, covariance and independent part by hand at the
    weight the update chose, and that weight minimises the hand-derived tr P⁺.

    Trust α scales the peer's R to R0/α, so α = 0.5 is the same hand formula with r_p doubled."""
    p, n_x, d_yz, n_yz, q, m = 1.0, 0.2, 0.1, 0.9, 0.5, 0.1
    P0 = np.diag([p, d_yz + n_yz, d_yz + n_yz, q, q, q])
    N0 = np.diag([n_x, n_yz, n_yz, m, m, m])
    P1, N1 = np.diag([0.05] * 3 + [0.5] * 3), np.diag([0.01] * 3 + [0.1] * 3)
    (x, P, N), (x_ref, P_ref, N_ref) = _two_static_uavs(P0, N0, P1, N1, r_anchor=1.0, r_peer=0.01,
                                                         peer_trust=peer_trust)
    hand = dict(p=p, n_x=n_x, d_yz=d_yz, n_yz=n_yz, q=q, m=m, pj=0.05, nj=0.01, r_a=1.0, r_p=0.01 / peer_trust)
    # the velocity block is only rescaled: P⁺_vv = D_vv/ω_0 + N_vv
    w = (q - m) / (P[3, 3] - m)
    assert 0.0 < w < 1.0
    x_hand, diag, n_hand, _ = _hand_split_ci(**hand, w=w)
    for xx, PP, NN in ((x, P, N), (x_ref, P_ref, N_ref)):
        assert xx[0] == pytest.approx(x_hand, abs=1e-12)
        assert np.abs(xx[1:]).max() < 1e-12
        assert np.abs(PP - np.diag(diag)).max() < 1e-12
        assert NN[0, 0] == pytest.approx(n_hand, abs=1e-12)
        assert np.abs(NN - np.diag(np.diag(NN))).max() < 1e-12 and np.abs(np.diag(NN)[1:]).max() < 1e-12
    scan = min(_hand_split_ci(**hand, w=v)[3] for v in np.linspace(1e-4, 1 - 1e-4, 100_001))
    chosen = _hand_split_ci(**hand, w=w)[3]
    assert scan - 1e-9 <= chosen <= scan * (1 + 1e-4)
    k = p / (p + 1.0)
    assert chosen < (1 - k) * p + 2 * (d_yz + n_yz) + 3 * q  # and it beats no update


def test_closed_form_all_independent_is_the_kalman_update():
    """At reset every error is independent (N = P): the peer is fused as an independent estimate, exactly
    the Kalman update with R = r + hᵀ P_j h, whatever ω."""
    p, q, pj, r_a, r_p = 0.8, 0.3, 0.2, 0.5, 0.04
    P0, P1 = np.diag([p] * 3 + [q] * 3), np.diag([pj] * 3 + [q] * 3)
    (x, P, N), (x_ref, P_ref, _) = _two_static_uavs(P0, P0, P1, P1, r_a, r_p)
    k = p / (p + r_a)
    x_abs, p_abs = k * 0.3, p * r_a / (p + r_a)
    r = r_p + pj
    g = p_abs / (p_abs + r)
    for xx, PP in ((x, P), (x_ref, P_ref)):
        assert xx[0] == pytest.approx(x_abs - g * (2.8 - 3.0 + x_abs), abs=1e-9)
        assert np.abs(PP - np.diag([p_abs * r / (p_abs + r), p, p, q, q, q])).max() < 1e-9
    # what stays independent: the anchor's and the peer range's own noise
    assert N[0, 0] == pytest.approx((1 - g) ** 2 * k * k * r_a + g * g * r_p, abs=1e-12)


# --------------------------------------------------------------------------- all peers together


def _star(n_peers, r_peer):
    """UAV 0 at the origin with one anchor at (−4, 0, 0) and ``n_peers`` neighbours all at (3, 0, 0) with the same
    broadcast covariance (all dependent), each ranged with variance ``r_peer``. Returns UAV 0's (x⁺, P⁺)."""
    n = n_peers + 1
    kind = np.array([[ANCHOR] + [PEER] * n_peers] * n)
    target = np.array([[0] + [j for j in range(n) if j != i] for i in range(n)])
    x = np.zeros((1, n, 6))
    x[0, 1:, 0] = 3.0
    P = np.broadcast_to(np.diag([1.0, 0.6, 0.6, 0.5, 0.5, 0.5]), (1, n, 6, 6)).copy()
    P[0, 1:] = np.diag([0.05] * 3 + [0.5] * 3)
    N = np.zeros_like(P)
    N[0, 0] = np.diag([0.2, 0.5, 0.5, 0.1, 0.1, 0.1])
    z = np.zeros((1, n, n, 3))
    z[0, 0, 0, 0], z[0, 0, 1:, 0] = 4.3, 2.8
    valid = np.zeros((1, n, n), dtype=bool)
    valid[0, 0] = True
    r0 = np.full((n, n), r_peer)
    r0[:, 0] = 1.0
    active, flops = np.zeros((1, n, n), dtype=bool), np.zeros((1, n))
    cekf.cekf_update(x, P, z, valid, np.ones((1, n, n)), kind, target, r0, np.array([[-4.0, 0.0, 0.0]]),
                     np.zeros((0, 3)), x[:, :, :3].copy(), 0.05, 0.01, active, flops, SPLIT, N)
    return x[0, 0], P[0, 0]


def test_copies_of_one_neighbour_count_once():
    """K neighbours whose dependent errors may be one and the same, each ranged with K·r, inform UAV 0 exactly as
    one neighbour ranged with r: their shares split 1 − ω_0, so together they weigh what one weighs (sequential CI
    rescales the UAV's prior once per peer instead)."""
    x1, P1 = _star(1, 0.01)
    for k in (2, 5):
        xk, Pk = _star(k, 0.01 * k)
        assert np.abs(xk - x1).max() < 1e-12 and np.abs(Pk - P1).max() < 1e-12


def test_the_prior_is_rescaled_once_whatever_the_peers():
    """With five peers the UAV's dependent part is divided by one ω_0 (its velocity block, which position rows do
    not touch here, is D_vv/ω_0 + N_vv), the same ω_0 as with one peer ranged five times as precisely; "ci"
    divides it once per peer."""
    _, P5 = _star(5, 0.05)
    _, P1 = _star(1, 0.01)
    assert 0.1 + 0.4 < P5[3, 3] == pytest.approx(P1[3, 3], abs=1e-12)


# --------------------------------------------------------------------------- the bound


def _random_peers(rng, m, rel):
    peers = []
    for _ in range(m):
        M = rng.normal(size=(3, 3))
        D = M @ M.T / 3 * rng.uniform(0.05, 2.0)
        Nj = np.diag(rng.uniform(0.0, 0.3, 3))
        if rel:
            H = np.zeros((3, 6))
            H[:, :3] = -np.eye(3)
        else:
            u = rng.normal(size=3)
            H = np.zeros((1, 6))
            H[0, :3] = u / np.linalg.norm(u)
        peers.append(PeerRows(y=np.zeros(len(H)), H=H, J=-H[:, :3], D=D, N=Nj, r=rng.uniform(0.01, 0.5)))
    return peers


def _sqrt_psd(A):
    w, V = np.linalg.eigh(A)
    return V @ np.diag(np.sqrt(np.clip(w, 0.0, None))) @ V.T


@pytest.mark.parametrize("rel", [False, True])
def test_split_ci_bounds_every_correlation_of_the_dependent_parts(rel):
    """The reported P⁺ bounds the true error covariance for every joint covariance of the dependent errors
    (d_i, d_1, …, d_m) with Cov(d_k) ⪯ D_k, the independent parts independent of everything.

    The error after the update is e⁺ = M_0 e_i + Σ_k M_k e_k + K v with M_0 = I − K H, M_k = −K J_k. Along a
    direction a its variance is largest when the d_k are perfectly correlated, each along √D_k M_kᵀ a:
    (Σ_k ‖√D_k M_kᵀ a‖)² + aᵀ (Σ_k M_k N_k M_kᵀ + K R Kᵀ) a, which must stay below aᵀ P⁺ a for every a."""
    rng = np.random.default_rng(11 + rel)
    worst, updated = np.inf, 0
    for _ in range(60):
        m = int(rng.integers(1, 5))
        L = rng.normal(size=(6, 6))
        D_i = L @ L.T / 6 * rng.uniform(0.1, 2.0)
        N_old, N_new = np.diag(rng.uniform(0.0, 0.3, 6)), np.diag(rng.uniform(0.0, 0.2, 6))
        P = D_i + N_old + N_new
        peers = _random_peers(rng, m, rel)
        x = np.zeros(6)
        _, P_post, N_post, w = split_ci_peer_update(x, P, N_old, N_new, peers)
        updated += w[0] < 1.0
        # the gain block of each peer, column by column (x⁺ = K y is linear in y; ω does not depend on y)
        K = []
        for k, p in enumerate(peers):
            for e in np.eye(len(p.y)):
                unit = [q._replace(y=e if q is p else np.zeros(len(q.y))) for q in peers]
                K.append(split_ci_peer_update(x, P, N_old, N_new, unit)[0])
        K = np.column_stack(K)
        H = np.vstack([p.H for p in peers])
        sizes = np.cumsum([0] + [len(p.y) for p in peers])
        blocks = [(np.eye(6) - K @ H, _sqrt_psd(D_i), N_old + N_new)]
        blocks += [(-K[:, sizes[k]:sizes[k + 1]] @ p.J, _sqrt_psd(p.D), p.N) for k, p in enumerate(peers)]
        R = np.diag(np.concatenate([np.full(len(p.y), p.r) for p in peers]))
        independent = sum(Mk @ Nk @ Mk.T for Mk, _, Nk in blocks) + K @ R @ K.T
        directions = np.vstack([rng.normal(size=(200, 6)), np.linalg.eigh(P_post)[1].T])
        for a in directions / np.linalg.norm(directions, axis=1, keepdims=True):
            dependent = sum(np.linalg.norm(Sk @ Mk.T @ a) for Mk, Sk, _ in blocks) ** 2
            worst = min(worst, a @ P_post @ a - dependent - a @ independent @ a)
        # the independent part is exactly the own noise carried through
        I_KH = np.eye(6) - K @ H
        assert np.abs(N_post - (I_KH @ N_new @ I_KH.T + K @ R @ K.T)).max() < 1e-10
    assert updated > 20
    assert worst >= -1e-10, f"the split-CI covariance is optimistic by {worst}"


# --------------------------------------------------------------------------- the filter in the world


def _mean_nees(task_id, seeds, update, **overrides):
    """Mean prior position NEES eᵀ P_pp⁻¹ e of uniform trust over every UAV, step and seed."""
    spec = get_spec(task_id, filter={"peer_update": update}, **overrides)
    core = LinkTrustCore(spec, len(seeds))
    core.reset(seeds)
    trust = np.ones((len(seeds), spec.n_uav, spec.n_channels))
    nees = []
    while True:
        e = core.x[..., :3] - core.world.buffers.pos
        nees.append(np.einsum("bni,bnij,bnj->bn", e, np.linalg.inv(core.P[..., :3, :3]), e))
        if core.step(trust).done.all():
            return float(np.mean(nees))


@pytest.mark.parametrize("sensors, point_above", [({}, 3.5), ({"anchor_max_range": 11.0}, 10.0)])
def test_uniform_trust_is_consistent_on_fault_free_scale8(sensors, point_above):
    """Scale8-v1 with its faults removed, 4 dev seeds: mean position NEES near 3 (measured 3.03; 2.28 with the
    anchors ranged within 11 m, where the peers carry information), against 3.88 and 13.85 for ``point``."""
    seeds = list(range(DEV_SEED_START, DEV_SEED_START + 4))
    nees = _mean_nees("swarmloc/Scale8-v1", seeds, "split_ci", faults=FAULT_FREE, sensors=sensors)
    assert 1.5 <= nees <= 4.5
    assert _mean_nees("swarmloc/Scale8-v1", seeds, "point", faults=FAULT_FREE, sensors=sensors) > point_above


def test_core_step_equals_the_batch_kernels():
    """The fused step (``core_kernel``) updates as ``cekf_update`` does from the same priors, independent parts
    included, and predicts P_ind as ``cekf_predict`` does. Not bit for bit: LLVM optimises the two kernels'
    weight search differently, which changes the last bits of the grid's traces, and where the grid is nearly
    flat its argmin, the start of the multiplicative steps (up to 1e-9 m here). Each kernel is deterministic,
    batched == single."""
    spec = get_spec("swarmloc/HybridNoise10-v1", filter={"peer_update": "split_ci"}, duration=6.0)
    seeds = [4, 5]
    core = LinkTrustCore(spec, len(seeds))
    core.reset(seeds)
    world, _, imu, z, valid, _ = sense(spec, spec.n_steps, seeds)
    lay = world.layout
    trust = np.random.default_rng(1).uniform(0.0, 1.0, size=valid.shape)
    active, flops = np.zeros(valid.shape[1:], dtype=bool), np.zeros((len(seeds), spec.n_uav))
    for k in range(spec.n_steps - 1):
        x, P, N, prior = core.x.copy(), core.P.copy(), core.P_ind.copy(), core.x[..., :3].copy()
        W = core.split_w.copy()
        cekf.cekf_update(x, P, z[k], valid[k], trust[k], lay.kind, lay.target, lay.r0, world.anchors,
                         world.landmarks, prior, spec.filter.alpha_th, spec.filter.alpha_min, active, flops, SPLIT, N,
                         W)
        out = core.step(trust[k])
        assert np.abs(out.estimate - x[..., :3]).max() < 1e-7, k
        assert np.abs(core.split_w - W).max() < 1e-6, k
        assert np.array_equal(out.flops, flops) and np.array_equal(out.active, active), k
        cekf.cekf_predict(x, P, imu[k + 1], spec.dt, spec.sensors.imu_sigma, prior, N)
        assert np.abs(core.P - P).max() < 1e-7 and np.abs(core.P_ind - N).max() < 1e-7, k


def test_batched_equals_single_and_covariances_stay_healthy():
    """Determinism (each episode reads only its own broadcasts) and 0 ⪯ N ⪯ P, P symmetric positive definite."""
    spec = get_spec("swarmloc/GradualFault-v1", filter={"peer_update": "split_ci"}, duration=60.0)
    seeds = [4, 5, 6]
    batch, singles = batch_and_singles(spec, seeds)
    trust = np.random.default_rng(2).uniform(0.0, 1.0, size=(spec.n_steps, len(seeds), spec.n_uav,
                                                             spec.n_channels))
    for k in range(spec.n_steps):
        batch.step(trust[k])
        for b, core in enumerate(singles):
            core.step(trust[k, b:b + 1])
        assert np.array_equal(batch.P, np.swapaxes(batch.P, -1, -2))
        assert np.linalg.eigvalsh(batch.P).min() > 0.0
        assert np.linalg.eigvalsh(batch.P_ind).min() > -1e-12
        assert np.linalg.eigvalsh(batch.P - batch.P_ind).min() > -1e-9
    for b, core in enumerate(singles):
        assert np.array_equal(core.x[0], batch.x[b]) and np.array_equal(core.P_ind[0], batch.P_ind[b])


@pytest.mark.parametrize("task_id, over", [("swarmloc/HybridNoise30-v1", {"sensors": {"peers": {"kind": "none"}}}),
                                           ("swarmloc/TDOA-v1", {})])
def test_without_peer_links_it_is_the_point_filter(task_id, over):
    """No peer channel: "split_ci" gives the "point" filter's x and P bit for bit (N is bookkeeping beside them)."""
    out = {}
    for update in ("point", "split_ci"):
        spec = get_spec(task_id, filter={"peer_update": update}, duration=5.0, **over)
        core = LinkTrustCore(spec, 2)
        core.reset([1, 2])
        for _ in range(spec.n_steps):
            core.step(np.full((2, spec.n_uav, spec.n_channels), 0.8))
        out[update] = (core.x.copy(), core.P.copy())
    assert np.array_equal(out["point"][0], out["split_ci"][0]) and np.array_equal(out["point"][1], out["split_ci"][1])


def test_flops_count_what_runs():
    """Scale4 at full trust: prediction of P and N, every anchor row and its bookkeeping, the peers' fusion (a
    cold weight search at the first update with peers, warm after it)."""
    spec = get_spec("swarmloc/Scale4-v1", filter={"peer_update": "split_ci"}, faults=FAULT_FREE, duration=3.0)
    core = LinkTrustCore(spec, 1)
    core.reset([7])
    kind = core.layout.kind
    warm_seen = False
    for _ in range(spec.n_steps):
        warm = core.split_w[0, :, 0] > 0.0
        out = core.step(np.ones((1, spec.n_uav, spec.n_channels)))
        n_anchor = (out.active[0] & (kind == ANCHOR)).sum(axis=-1)
        n_peer = (out.active[0] & (kind == PEER)).sum(axis=-1)
        search = np.where(warm, cost.SPLIT_CI_WARM_FLOPS, cost.SPLIT_CI_FLOPS)
        per_peer = np.where(warm, cost.SPLIT_CI_WARM_RANGE_FLOPS, cost.SPLIT_CI_RANGE_FLOPS)
        expected = (cost.PREDICT_FLOPS + cost.SPLIT_PREDICT_FLOPS
                    + n_anchor * (cost.RANGE_ROW_FLOPS + cost.SPLIT_TRACK_ROW_FLOPS)
                    + np.where(n_peer > 0, search, 0) + n_peer * per_peer)
        assert np.array_equal(out.flops[0], expected)
        assert n_peer.min() > 0
        warm_seen |= warm.any()
    assert warm_seen


def test_world_md_quotes_the_costs():
    """docs/world.md quotes the FLOPs of the code."""
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "docs" / "world.md").read_text(encoding="utf-8")
    for value in (cost.SPLIT_PREDICT_FLOPS, cost.SPLIT_TRACK_ROW_FLOPS, cost.SPLIT_CI_FLOPS, cost.SPLIT_CI_RANGE_FLOPS,
                  cost.SPLIT_CI_REL_FLOPS, cost.SPLIT_CI_WARM_FLOPS, cost.SPLIT_CI_WARM_RANGE_FLOPS,
                  cost.SPLIT_CI_WARM_REL_FLOPS):
        assert f"{value:,}" in text, value


def test_the_spec_option():
    """Selectable by override, in the canonical JSON when chosen; no registered task's default changes."""
    spec = get_spec("swarmloc/Scale8-v1", filter={"peer_update": "split_ci"})
    assert spec.filter.peer_update == "split_ci" and '"peer_update":"split_ci"' in spec.model_dump_json()
    assert type(spec).model_validate_json(spec.model_dump_json()) == spec
    assert get_spec("swarmloc/Scale8-v1").filter.peer_update == "point"
    with pytest.raises(pydantic.ValidationError, match="'split_ci', 'point' or 'ci'"):
        get_spec("swarmloc/Scale8-v1", filter={"peer_update": "exact"})
    with pytest.raises(ValueError, match="needs P_ind"):
        n = spec.n_uav
        cekf.cekf_update(np.zeros((1, n, 6)), np.zeros((1, n, 6, 6)), np.zeros((1, n, 1, 3)),
                         np.zeros((1, n, 1), dtype=bool), np.ones((1, n, 1)), np.zeros((n, 1), dtype=np.int64),
                         np.zeros((n, 1), dtype=np.int64), np.ones((n, 1)), np.zeros((1, 3)), np.zeros((0, 3)),
                         np.zeros((1, n, 3)), 0.05, 0.01, np.zeros((1, n, 1), dtype=bool), np.zeros((1, n)), SPLIT)
