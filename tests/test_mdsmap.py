"""MDS-MAP and NLS swarm initialization (dtvirm §3.3, Algorithm 2): frame, mirror, oracles."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse.csgraph import shortest_path

from swarmloc.agents.estimators.init import classical_mds, complete_distances, mdsmap_init, nls_init

VARIANTS = ["algorithm2", "joint"]


def _ranges(p: np.ndarray) -> np.ndarray:
    return np.linalg.norm(p[..., :, None, :] - p[..., None, :, :], axis=-1)


def _swarm(rng: np.random.Generator, B: int, N: int, moves: np.ndarray) -> dict[str, np.ndarray]:
    """Noise-free swarm: truth x (B, N, 3) with node 0 at the origin, and initializer inputs.

    moves: (K, 3) node 0's displacements in a frame where it is rotated per swarm by a
    random heading (so every swarm has its own yaw).
    """
    x = np.concatenate([rng.uniform(-15, 15, (B, N, 2)), rng.uniform(0, 3, (B, N, 1))], axis=-1)
    x = x - x[:, :1]
    th = rng.uniform(0, 2 * np.pi, B)
    c, s = np.cos(th), np.sin(th)
    Rz = np.zeros((B, 3, 3))
    Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = c, -s, s, c, 1.0
    dX = np.einsum("bij,kj->bki", Rz, moves)
    t = np.cumsum(dX, axis=1)
    D_post = []
    for k in range(moves.shape[0]):
        p = x.copy()
        p[:, 0] = t[:, k]
        D_post.append(_ranges(p))
    a = dX[:, 0, :2]
    side = np.sign(a[:, 0] * x[:, 1, 1] - a[:, 1] * x[:, 1, 0]).astype(int)
    z = x[:, :, 2] + 100.0  # any datum
    return {"x": x, "D_pre": _ranges(x), "D_post": np.stack(D_post, 1), "dX": dX, "z": z, "side": side}


def _mirror(x: np.ndarray, dX: np.ndarray) -> np.ndarray:
    """Reflect horizontal positions across the line of the first displacement (through node 0)."""
    u = dX[:, 0, :2] / np.linalg.norm(dX[:, 0, :2], axis=-1, keepdims=True)
    h = x[..., :2]
    m = 2.0 * np.einsum("bnk,bk->bn", h, u)[..., None] * u[:, None, :] - h
    return np.concatenate([m, x[..., 2:]], axis=-1)


STEP = np.array([[4.0, 0.0, 0.5]])
TURN = np.array([[4.0, 0.0, 0.0], [0.0, 3.0, -0.2]])


@pytest.mark.parametrize("variant", VARIANTS)
def test_noise_free_recovery_with_side_convention(variant: str) -> None:
    sw = _swarm(np.random.default_rng(0), 16, 12, STEP)
    x = mdsmap_init(sw["D_pre"], sw["D_post"], sw["dX"], sw["z"], side=sw["side"], variant=variant)
    assert x.shape == (16, 12, 3)
    np.testing.assert_array_equal(x[:, 0], 0.0)
    np.testing.assert_allclose(x, sw["x"], atol=1e-9, rtol=0)


@pytest.mark.parametrize("variant", VARIANTS)
def test_wrong_side_gives_the_mirror_image(variant: str) -> None:
    sw = _swarm(np.random.default_rng(1), 8, 7, STEP)
    x = mdsmap_init(sw["D_pre"], sw["D_post"], sw["dX"], sw["z"], side=-sw["side"], variant=variant)
    np.testing.assert_allclose(x, _mirror(sw["x"], sw["dX"]), atol=1e-9, rtol=0)
    # both images fit every range: the mirror is a genuine ambiguity, not an error
    np.testing.assert_allclose(_ranges(x), sw["D_pre"], atol=1e-9)


def test_side_is_required_when_track_does_not_turn() -> None:
    sw = _swarm(np.random.default_rng(2), 2, 6, STEP)
    with pytest.raises(ValueError, match="mirror ambiguous"):
        mdsmap_init(sw["D_pre"], sw["D_post"], sw["dX"], sw["z"])
    collinear = np.array([[3.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    sw = _swarm(np.random.default_rng(2), 2, 6, collinear)
    with pytest.raises(ValueError, match="side"):
        nls_init(sw["D_pre"], sw["D_post"], sw["dX"], sw["z"])
    x = mdsmap_init(sw["D_pre"], sw["D_post"], sw["dX"], sw["z"], side=sw["side"])
    np.testing.assert_allclose(x, sw["x"], atol=1e-9, rtol=0)


@pytest.mark.parametrize("variant", VARIANTS)
def test_turning_track_resolves_the_mirror_from_data(variant: str) -> None:
    sw = _swarm(np.random.default_rng(3), 10, 9, TURN)
    x = mdsmap_init(sw["D_pre"], sw["D_post"], sw["dX"], sw["z"], variant=variant)
    np.testing.assert_allclose(x, sw["x"], atol=1e-9, rtol=0)
    # a turning track outranks the convention: a wrong side is not consulted
    x = mdsmap_init(sw["D_pre"], sw["D_post"], sw["dX"], sw["z"], side=-sw["side"], variant=variant)
    np.testing.assert_allclose(x, sw["x"], atol=1e-9, rtol=0)


def test_batched_equals_single_and_leading_dims() -> None:
    sw = _swarm(np.random.default_rng(4), 6, 8, STEP)
    noise = np.random.default_rng(5).normal(0, 0.3, sw["D_pre"].shape)
    D_pre = sw["D_pre"] + noise + noise.swapaxes(1, 2)
    args = (np.abs(D_pre), sw["D_post"], sw["dX"], sw["z"])
    batched = mdsmap_init(*args, side=sw["side"])
    single = np.stack([mdsmap_init(*(a[b] for a in args), side=int(sw["side"][b])) for b in range(6)])
    np.testing.assert_allclose(batched, single, atol=1e-12, rtol=0)
    lead = mdsmap_init(*(a.reshape((2, 3) + a.shape[1:]) for a in args), side=sw["side"].reshape(2, 3))
    np.testing.assert_allclose(lead.reshape(batched.shape), batched, atol=1e-12, rtol=0)


def test_missing_ranges_completed_by_shortest_path() -> None:
    # Node 3 sits on the horizontal segment between nodes 1 and 2 (same altitude), so the
    # completed 1–2 distance through node 3 is exact and recovery stays exact.
    sw = _swarm(np.random.default_rng(6), 4, 8, STEP)
    x = sw["x"].copy()
    x[:, 3] = 0.5 * (x[:, 1] + x[:, 2])
    x[:, 1, 2] = x[:, 2, 2] = x[:, 3, 2]
    moved = x.copy()
    moved[:, 0] += sw["dX"][:, 0]
    D_pre, D_post = _ranges(x), _ranges(moved)[:, None]
    for D in (D_pre, D_post[:, 0]):
        D[:, 1, 2] = D[:, 2, 1] = np.nan
    side = np.sign(sw["dX"][:, 0, 0] * x[:, 1, 1] - sw["dX"][:, 0, 1] * x[:, 1, 0]).astype(int)
    out = mdsmap_init(D_pre, D_post, sw["dX"], x[:, :, 2], side=side)
    np.testing.assert_allclose(out, x, atol=1e-9, rtol=0)


def test_complete_distances_matches_scipy_shortest_path_on_missing_entries() -> None:
    rng = np.random.default_rng(7)
    H = _ranges(rng.uniform(0, 10, (5, 9, 2)))
    drop = np.triu(rng.random((5, 9, 9)) < 0.4, 1)
    drop = drop | drop.swapaxes(1, 2)
    H[drop] = np.nan
    G = complete_distances(H)
    for b in range(5):
        ref = shortest_path(np.where(np.isnan(H[b]), 0.0, H[b]), method="FW", directed=False)
        np.testing.assert_allclose(G[b][drop[b]], ref[drop[b]], rtol=1e-12)
        keep = ~drop[b]
        np.testing.assert_array_equal(G[b][keep], H[b][keep])


def test_disconnected_graph_raises() -> None:
    sw = _swarm(np.random.default_rng(8), 1, 5, STEP)
    D_pre, D_post = sw["D_pre"].copy(), sw["D_post"].copy()
    for D in (D_pre[0], D_post[0, 0]):
        D[4, :] = np.nan
        D[:, 4] = np.nan
    with pytest.raises(ValueError, match="disconnected"):
        mdsmap_init(D_pre, D_post, sw["dX"], sw["z"], side=sw["side"])


def test_classical_mds_preserves_distances() -> None:
    p = np.random.default_rng(9).normal(size=(3, 7, 2))
    Y = classical_mds(_ranges(p) ** 2, dim=2)
    np.testing.assert_allclose(_ranges(Y), _ranges(p), atol=1e-10)


def test_bad_inputs_name_the_value() -> None:
    sw = _swarm(np.random.default_rng(10), 2, 5, STEP)
    args = [sw["D_pre"], sw["D_post"], sw["dX"], sw["z"]]
    with pytest.raises(ValueError, match=r"D_post must have shape"):
        mdsmap_init(args[0], args[1][:, 0], args[2], args[3], side=1)
    with pytest.raises(ValueError, match=r"z must have shape"):
        mdsmap_init(*args[:3], args[3][:, :4], side=1)
    bad = args[2].copy()
    bad[1, 0, 1] = np.nan
    with pytest.raises(ValueError, match=r"dX must be finite; got nan"):
        mdsmap_init(*args[:2], bad, args[3], side=1)
    neg = args[0].copy()
    neg[0, 1, 2] = -1.0
    with pytest.raises(ValueError, match=r"D_pre entries must be non-negative.*-1.0"):
        mdsmap_init(neg, *args[1:], side=1)
    with pytest.raises(ValueError, match=r"side must be \+1 or -1"):
        mdsmap_init(*args, side=2)
    with pytest.raises(ValueError, match=r"ref must be a node index in \[1, 4\]; got 5"):
        mdsmap_init(*args, side=1, ref=5)
    still = args[2].copy()
    still[..., :2] = 0.0
    with pytest.raises(ValueError, match="move horizontally"):
        mdsmap_init(*args[:2], still, args[3], side=1)
    with pytest.raises(ValueError, match="variant"):
        mdsmap_init(*args, side=1, variant="3d")  # type: ignore[arg-type]


def test_nls_recovers_truth_and_applies_the_convention() -> None:
    rng = np.random.default_rng(11)
    sw = _swarm(rng, 4, 8, STEP)
    args = (sw["D_pre"], sw["D_post"], sw["dX"], sw["z"])
    x0 = sw["x"][..., :2] + rng.normal(0, 0.5, (4, 8, 2))
    x = nls_init(*args, side=sw["side"], x0=x0)
    np.testing.assert_array_equal(x[:, 0], 0.0)
    np.testing.assert_allclose(x, sw["x"], atol=1e-6, rtol=0)
    # started in the mirror basin, the convention reflects the solution back
    x = nls_init(*args, side=sw["side"], x0=_mirror(sw["x"], sw["dX"])[..., :2])
    np.testing.assert_allclose(x, sw["x"], atol=1e-6, rtol=0)
    # and a turning track lets the residuals decide
    sw = _swarm(rng, 3, 7, TURN)
    x0 = sw["x"][..., :2] + rng.normal(0, 0.3, (3, 7, 2))
    x = nls_init(sw["D_pre"], sw["D_post"], sw["dX"], sw["z"], x0=x0)
    np.testing.assert_allclose(x, sw["x"], atol=1e-6, rtol=0)


def test_nls_refinement_of_mdsmap_is_no_worse_on_noisy_ranges() -> None:
    rng = np.random.default_rng(12)
    sw = _swarm(rng, 40, 10, np.array([[6.0, 0.0, 0.0]]))
    e = rng.normal(0, 0.3, sw["D_pre"].shape)
    D_pre = np.abs(sw["D_pre"] + np.triu(e, 1) + np.triu(e, 1).swapaxes(1, 2))
    D_post = np.abs(sw["D_post"] + rng.normal(0, 0.3, sw["D_post"].shape))
    args = (D_pre, D_post, sw["dX"], sw["z"])
    x_mds = mdsmap_init(*args, side=sw["side"])
    x_ref = nls_init(*args, side=sw["side"], x0=x_mds[..., :2])
    err = lambda x: np.linalg.norm(x - sw["x"], axis=-1)[:, 1:].mean()  # noqa: E731
    assert err(x_mds) < 3.0
    assert err(x_ref) <= err(x_mds) + 1e-9
