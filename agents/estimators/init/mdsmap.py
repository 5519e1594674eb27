"""MDS-MAP swarm position initialization (dtvirm §3.3, Algorithm 2).

Frame. Anchor-free ranging leaves 4 directions unobservable (dtvirm Theorem 1: 3D
translation and yaw). dtvirm fixes them by decree and by one measurement: node 0 (the
paper's node 1) *is* the ENU origin, and node 0 then flies a short displacement ``ΔX``
known in ENU (VIO + compass), which fixes yaw. We return positions in that frame:
``x[..., 0, :] == 0`` and ENU axes.

2D plus altitude, not 3D. Every UAV knows its altitude (barometer / VIO), so we subtract
the vertical part of each range, ``h_ij² = d_ij² − (z_i − z_j)²``, and run MDS in the
horizontal plane, as dtvirm's Algorithm 2 does (it keeps two eigenvectors). Full 3D MDS
would have to recover the vertical axis from the third eigenvalue, which for a swarm at
similar altitudes is small and noise-dominated, and would still not fix the mirror.

Mirror. Ranges and one displacement leave a reflection of the horizontal layout across
the line of node 0's displacement: both images fit every range and the displacement
exactly (in 3D, distances + displacement leave a rotation about the displacement axis
plus this mirror; the known altitudes remove the rotation, never the mirror). We resolve
it by the first rule that applies:

1. node 0's track turns (K ≥ 2 moves whose horizontal displacements span the plane:
   second singular value ≥ ``min_turn`` × the first): the data decide, the orthogonal
   Procrustes fit of the track picks the reflection; ``side`` is not consulted;
2. otherwise the stated convention ``side`` (+1 or −1): the sign of the horizontal cross
   product ``ΔX₁ × x_ref``, i.e. +1 when node ``ref`` (default 1) lies to the left of node
   0's first displacement, −1 to the right;
3. otherwise ``ValueError``: the layout is ambiguous, pass ``side`` or a turning track.

Layout (``variant``). "algorithm2" follows dtvirm Algorithm 2: one MDS layout per
epoch (before the move, after each move), the post-move layouts aligned onto the
pre-move one on the non-moving nodes (line 17), node 0's displacement read off in that
frame, yaw from it (lines 19–24), node 0 to the origin. "joint" runs one MDS on the
augmented point set {N nodes before the moves, node 0 after each move}. Both share our
additions: a range between two non-moving nodes measured in several epochs and both
directions is averaged, and the average serves every epoch; K ≥ 1 moves, yaw (and, for a
turning track, the mirror) by orthogonal Procrustes over the track; the mirror rule
above; translation by §3.3 (node 0's start is the origin; line 26 as printed adds ΔX_abs
minus a relative displacement, which does not put node 1 there). Missing ranges (NaN)
are filled by shortest paths over the measured graph, as MDS-MAP (Shang et al.) does;
measured ranges are kept. ``swarmloc reproduce dtvirm`` measures both (its Table 1).

Batch shapes: leading dims ``...`` (typically B envs), N UAVs, K moves, M = N + K points.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True)
class InitProblem:
    """Validated initialization inputs, flattened to one batch axis B.

    Points 0..N−1 are the UAVs before the moves, points N..N+K−1 are node 0 after its
    1st..Kth move (M = N + K points in all).

    Attributes:
        R: (B, M, M) mean measured 3D range between points, NaN where unmeasured; pairs of
            node-0 track points hold the exact known distance.
        count: (B, M, M) number of measurements averaged into ``R`` (0 where NaN).
        z: (B, M) altitude of each point relative to node 0's start [m].
        track: (B, K+1, 2) known horizontal positions of node 0's track points, ``track[:, 0]
            == 0`` (cumulative sums of ``ΔX``).
        turns: (B,) whether the track spans the plane (then the data fix the mirror).
        side: (B,) the stated mirror convention ±1, 0 where not given.
        ref: index of the node whose side of the first displacement ``side`` states.
        lead: the caller's leading batch shape, restored on output.
    """

    R: FloatArray
    count: FloatArray
    z: FloatArray
    track: FloatArray
    turns: BoolArray
    side: npt.NDArray[np.int64]
    ref: int
    lead: tuple[int, ...]

    @property
    def n_nodes(self) -> int:
        """N, the number of UAVs."""
        return self.R.shape[-1] - self.n_moves

    @property
    def n_moves(self) -> int:
        """K, the number of node-0 moves."""
        return self.track.shape[-2] - 1

    def positions(self, x_h: FloatArray) -> FloatArray:
        """ENU positions ``(..., N, 3)`` [m] from horizontal ones ``(B, N, 2)``: the known altitudes
        appended, the caller's leading shape restored."""
        N = self.n_nodes
        return np.concatenate([x_h, self.z[:, :N, None]], axis=-1).reshape(self.lead + (N, 3))


def _check_ranges(name: str, D: FloatArray) -> None:
    bad = ~(np.isnan(D) | (np.isfinite(D) & (D >= 0.0)))
    bad &= ~np.eye(D.shape[-1], dtype=bool)  # the diagonal is never read
    if bad.any():
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        raise ValueError(
            f"{name} entries must be non-negative finite ranges [m] or NaN (missing); "
            f"got {float(D[idx])} at index {idx}"
        )


def prepare_init_problem(
    D_pre: npt.ArrayLike,
    D_post: npt.ArrayLike,
    dX: npt.ArrayLike,
    z: npt.ArrayLike,
    *,
    side: int | npt.ArrayLike | None = None,
    ref: int = 1,
    min_turn: float = 0.1,
) -> InitProblem:
    """Validate initializer inputs and assemble the augmented range matrix.

    Shared by ``mdsmap_init`` and ``nls_init`` so both see the same data. Ranges between
    non-moving nodes measured in several epochs (before and after each move, both
    directions i→j and j→i) are averaged; ``count`` records how many were.

    Args:
        D_pre: (..., N, N) ranges before node 0 moves [m], NaN = missing; diagonal ignored.
        D_post: (..., K, N, N) ranges after each of node 0's K moves [m], NaN = missing.
        dX: (..., K, 3) node 0's ENU displacement in each move [m] (move k from the end
            of move k−1).
        z: (..., N) altitudes before the moves [m], any common datum.
        side: mirror convention (module docstring), scalar or broadcastable to ``...``,
            values ±1; None when not stated.
        ref: node whose side of the first displacement ``side`` states, 1 ≤ ref < N.
        min_turn: track counts as turning when its horizontal displacement matrix has
            singular-value ratio σ₂/σ₁ ≥ min_turn, in (0, 1].

    Returns:
        The validated ``InitProblem``.

    Raises:
        ValueError: bad shapes, NaN/inf or negative values, a track with no horizontal
            extent, a bad ``side``/``ref``/``min_turn``, or an ambiguous mirror (track
            does not turn and ``side`` is None).
    """
    D_pre = np.asarray(D_pre, dtype=np.float64)
    D_post = np.asarray(D_post, dtype=np.float64)
    dX = np.asarray(dX, dtype=np.float64)
    z = np.asarray(z, dtype=np.float64)
    if D_pre.ndim < 2 or D_pre.shape[-1] != D_pre.shape[-2] or D_pre.shape[-1] < 3:
        raise ValueError(f"D_pre must have shape (..., N, N) with N >= 3; got {D_pre.shape}")
    N = D_pre.shape[-1]
    lead = D_pre.shape[:-2]
    if D_post.ndim != D_pre.ndim + 1 or D_post.shape[:-3] != lead or D_post.shape[-2:] != (N, N):
        raise ValueError(
            f"D_post must have shape (..., K, N, N) = {lead + ('K', N, N)} with K >= 1; "
            f"got {D_post.shape}"
        )
    K = D_post.shape[-3]
    if K < 1:
        raise ValueError(f"D_post must hold K >= 1 moves; got K = {K}")
    if dX.shape != lead + (K, 3):
        raise ValueError(f"dX must have shape (..., K, 3) = {lead + (K, 3)}; got {dX.shape}")
    if z.shape != lead + (N,):
        raise ValueError(f"z must have shape (..., N) = {lead + (N,)}; got {z.shape}")
    _check_ranges("D_pre", D_pre)
    _check_ranges("D_post", D_post)
    for name, v in (("dX", dX), ("z", z)):
        if not np.isfinite(v).all():
            idx = tuple(int(i) for i in np.argwhere(~np.isfinite(v))[0])
            raise ValueError(f"{name} must be finite; got {float(v[idx])} at index {idx}")
    if not 1 <= ref < N:
        raise ValueError(f"ref must be a node index in [1, {N - 1}]; got {ref}")
    if not 0.0 < min_turn <= 1.0:
        raise ValueError(f"min_turn must be in (0, 1]; got {min_turn}")

    B = int(np.prod(lead, dtype=np.int64))
    M = N + K
    D_pre = D_pre.reshape(B, N, N)
    D_post = D_post.reshape(B, K, N, N)
    dX = dX.reshape(B, K, 3)
    z = z.reshape(B, N)

    # Track of node 0: t_0 = 0, t_k = Σ_{l≤k} ΔX_l.
    t = np.concatenate([np.zeros((B, 1, 3)), np.cumsum(dX, axis=1)], axis=1)
    track = t[:, :, :2]
    sv = np.linalg.svd(track[:, 1:], compute_uv=False)  # (B, min(K, 2))
    if (sv[:, 0] <= 1e-9).any():
        b = int(np.argmax(sv[:, 0] <= 1e-9))
        raise ValueError(
            f"node 0's track must move horizontally to fix yaw; batch element {b} has "
            f"horizontal displacements {track[b, 1:].tolist()} m"
        )
    turns = sv[:, -1] >= min_turn * sv[:, 0] if K >= 2 else np.zeros(B, dtype=bool)

    if side is None:
        side_b = np.zeros(B, dtype=np.int64)
    else:
        s = np.asarray(side)
        try:
            s = np.broadcast_to(s, lead).reshape(B)
        except ValueError:
            raise ValueError(f"side must be ±1 broadcastable to {lead}; got shape {s.shape}") from None
        if not np.isin(s, (-1, 1)).all():
            raise ValueError(f"side must be +1 or -1 (or None); got values {np.unique(s).tolist()}")
        side_b = s.astype(np.int64)
    ambiguous = ~turns & (side_b == 0)
    if ambiguous.any():
        raise ValueError(
            "mirror ambiguous: node 0's track does not turn (collinear moves) and side is None "
            f"for batch elements {np.flatnonzero(ambiguous)[:10].tolist()}; pass side=±1 "
            "(+1: node ref left of the first displacement) or a second, non-collinear move"
        )

    # Average every measurement of a pair over epochs and directions (i→j, j→i).
    R_sum = np.zeros((B, M, M))
    count = np.zeros((B, M, M))
    epochs = np.concatenate([D_pre[:, None], D_post], axis=1)  # (B, K+1, N, N)
    off_diag = ~np.eye(N, dtype=bool)
    for e in range(K + 1):
        idx = np.arange(N)
        # Node 0's row in epoch e ranges from the track point it stood on then.
        idx[0] = 0 if e == 0 else N + e - 1
        E = epochs[:, e]
        seen = (np.isfinite(E) & off_diag).astype(np.float64)
        E = np.where(seen > 0, E, 0.0)
        R_sum[:, idx[:, None], idx[None, :]] += E + E.swapaxes(1, 2)
        count[:, idx[:, None], idx[None, :]] += seen + seen.swapaxes(1, 2)
    with np.errstate(invalid="ignore", divide="ignore"):
        R = np.where(count > 0, R_sum / count, np.nan)
    # Pairs of node-0 track points: distances known exactly from ΔX.
    tk = np.concatenate([[0], np.arange(N, M)])
    R[:, tk[:, None], tk[None, :]] = np.linalg.norm(t[:, :, None, :] - t[:, None, :, :], axis=-1)
    count[:, tk[:, None], tk[None, :]] = 0.0
    R[:, np.arange(M), np.arange(M)] = 0.0

    z_rel = z - z[:, :1]
    z_aug = np.concatenate([z_rel, t[:, 1:, 2]], axis=1)
    return InitProblem(R=R, count=count, z=z_aug, track=track, turns=turns, side=side_b, ref=ref, lead=lead)


def complete_distances(H: npt.ArrayLike) -> FloatArray:
    """Fill missing distances by shortest paths over the measured graph (Floyd–Warshall).

    MDS-MAP's first step: a missing distance is replaced by the length of the shortest
    chain of measured links, an over-estimate that is exact for collinear chains.
    Measured entries are kept as measured: with noise, a two-hop chain across a nearly
    straight triple is often shorter than the direct range, and letting it win biases
    long ranges low (in our benchmark that raised the mean error by about a quarter).
    Vectorized over the batch; O(M³) per element, fine for swarm sizes.

    Args:
        H: (..., M, M) symmetric non-negative distances, NaN or inf where unmeasured.

    Returns:
        (..., M, M) completed distances, zero diagonal.

    Raises:
        ValueError: if the measured graph is disconnected (some pair has no path).
    """
    H = np.asarray(H, dtype=np.float64)
    if H.ndim < 2 or H.shape[-1] != H.shape[-2]:
        raise ValueError(f"H must have shape (..., M, M); got {H.shape}")
    M = H.shape[-1]
    G = np.where(np.isnan(H), np.inf, H)
    G[..., np.arange(M), np.arange(M)] = 0.0
    for k in range(M):
        # g_ij = min(g_ij, g_ik + g_kj)
        G = np.minimum(G, G[..., :, k : k + 1] + G[..., k : k + 1, :])
    if np.isinf(G).any():
        idx = tuple(int(i) for i in np.argwhere(np.isinf(G))[0])
        raise ValueError(
            f"range graph is disconnected: no chain of measured links between points "
            f"{idx[-2]} and {idx[-1]} (batch index {idx[:-2]}); MDS-MAP needs a connected graph"
        )
    out = np.where(np.isfinite(H), H, G)
    out[..., np.arange(M), np.arange(M)] = 0.0
    return out


def classical_mds(D2: npt.ArrayLike, dim: int = 2) -> FloatArray:
    """Classical (Torgerson) MDS: coordinates whose distances best match ``D2``.

    Double-centres the squared distances into a Gram matrix and keeps its ``dim`` largest
    eigenpairs (dtvirm Algorithm 2, lines 6–9). Coordinates are centred on the point
    centroid and defined up to an orthogonal transform (rotation and reflection).

    Args:
        D2: (..., M, M) squared distances [m²].
        dim: number of coordinates to keep, 1 ≤ dim ≤ M.

    Returns:
        (..., M, dim) coordinates [m].
    """
    D2 = np.asarray(D2, dtype=np.float64)
    M = D2.shape[-1]
    if not 1 <= dim <= M:
        raise ValueError(f"dim must be in [1, {M}]; got {dim}")
    # G = −½ J D² J,  J = I − 11ᵀ/M (double centring, written with means)
    G = -0.5 * (
        D2 - D2.mean(axis=-1, keepdims=True) - D2.mean(axis=-2, keepdims=True) + D2.mean(axis=(-2, -1), keepdims=True)
    )
    lam, V = np.linalg.eigh(G)  # ascending
    lam = lam[..., ::-1][..., :dim]
    V = V[..., ::-1][..., :dim]
    # X = V Λ^{1/2}, negative eigenvalues (noise) clipped to 0
    return V * np.sqrt(np.maximum(lam, 0.0))[..., None, :]


def horizontal_side(x_h: FloatArray, track: FloatArray, ref: int) -> FloatArray:
    """Sign of ΔX₁ × x_ref (horizontal cross product): +1 when node ``ref`` is left of the first move.

    Args:
        x_h: (B, ≥N, 2) horizontal positions with node 0 at the origin.
        track: (B, K+1, 2) node 0's track.
        ref: node index.

    Returns:
        (B,) signs in {−1, 0, +1}.
    """
    a = track[:, 1]
    p = x_h[:, ref]
    return np.sign(a[:, 0] * p[:, 1] - a[:, 1] * p[:, 0])


def _layout_algorithm2(H: FloatArray, N: int, K: int) -> tuple[FloatArray, FloatArray]:
    """dtvirm Algorithm 2, steps 1–2: one MDS layout per epoch, aligned on the non-moving nodes.

    Args:
        H: (B, M, M) horizontal distances over the augmented points, NaN = missing.
        N: number of UAVs.
        K: number of moves.

    Returns:
        Y: (B, N, 2) the pre-move layout; T: (B, K+1, 2) node 0's track in that layout.
    """
    # One layout per epoch e (node 0 at track point e, nodes 1..N−1 where they were):
    # shortest-path completion and classical MDS (lines 6–12).
    idx = np.tile(np.arange(N), (K + 1, 1))
    idx[:, 0] = np.concatenate([[0], np.arange(N, N + K)])
    H_e = H[:, idx[:, :, None], idx[:, None, :]]  # (B, K+1, N, N)
    X = classical_mds(complete_distances(H_e) ** 2, dim=2)  # (B, K+1, N, 2)
    # Align each epoch onto the first on the non-moving nodes (line 17):
    # R_e = U Vᵀ with (A_0 − c_0)ᵀ (A_e − c_e) = U Σ Vᵀ. A reflection is allowed, since two
    # epochs' MDS frames may differ by one.
    A = X[:, :, 1:]
    c = A.mean(axis=-2, keepdims=True)
    U, _, Vt = np.linalg.svd((A[:, :1] - c[:, :1]).swapaxes(-1, -2) @ (A - c))
    R = U @ Vt
    # T_e = R_e (x_e,0 − c_e) + c_0 (line 18)
    T = ((X[:, :, :1] - c) @ R.swapaxes(-1, -2) + c[:, :1])[:, :, 0]
    T[:, 0] = X[:, 0, 0]
    return X[:, 0], T


def _layout_joint(H: FloatArray, N: int, K: int) -> tuple[FloatArray, FloatArray]:
    """One MDS layout of the augmented points (the N nodes and node 0's K track points).

    Arguments and returns as ``_layout_algorithm2``.
    """
    Z = classical_mds(complete_distances(H) ** 2, dim=2)  # (B, M, 2)
    return Z[:, :N], Z[:, np.concatenate([[0], np.arange(N, N + K)])]


def mdsmap_init(
    D_pre: npt.ArrayLike,
    D_post: npt.ArrayLike,
    dX: npt.ArrayLike,
    z: npt.ArrayLike,
    *,
    side: int | npt.ArrayLike | None = None,
    ref: int = 1,
    min_turn: float = 0.1,
    variant: Literal["algorithm2", "joint"] = "algorithm2",
) -> FloatArray:
    """MDS-MAP: swarm ENU positions from ranges, node 0's known moves and altitudes.

    Horizontal ranges ``h² = d² − Δz²``, shortest-path completion of missing ones and
    classical MDS in the plane give a layout with node 0's track in it (``variant``, see
    the module docstring); the orthogonal Procrustes fit of that track onto the known ENU
    track, about node 0's start, fixes yaw, and the mirror rule fixes the reflection.
    Node 0's start is the origin; altitudes are relative to it. Fully vectorized over the
    leading dims.

    Args:
        D_pre: (..., N, N) ranges before node 0 moves [m], NaN = missing.
        D_post: (..., K, N, N) ranges after each of node 0's K moves [m], NaN = missing.
        dX: (..., K, 3) node 0's ENU displacement in each move [m].
        z: (..., N) altitudes before the moves [m], any common datum.
        side: mirror convention ±1 (used only when the track does not turn), or None.
        ref: node whose side ``side`` states, 1 ≤ ref < N.
        min_turn: singular-value ratio from which a track counts as turning, in (0, 1].
        variant: "algorithm2" (per-epoch layouts aligned on the non-moving nodes, as
            dtvirm) or "joint" (one layout of nodes and track points).

    Returns:
        (..., N, 3) ENU positions [m], ``x[..., 0, :] == 0``.

    Raises:
        ValueError: see ``prepare_init_problem``; also a disconnected range graph or an
            unknown ``variant``.
    """
    layouts = {"algorithm2": _layout_algorithm2, "joint": _layout_joint}
    if variant not in layouts:
        raise ValueError(f"variant must be one of {sorted(layouts)}; got {variant!r}")
    pb = prepare_init_problem(D_pre, D_post, dX, z, side=side, ref=ref, min_turn=min_turn)
    N = pb.n_nodes
    dz = pb.z[:, :, None] - pb.z[:, None, :]
    # h_ij² = d_ij² − (z_i − z_j)², clipped at 0 where noise makes it negative
    H = np.sqrt(np.maximum(pb.R**2 - dz**2, 0.0))
    H = np.where(np.isnan(pb.R), np.nan, H)
    Y, T = layouts[variant](H, N, pb.n_moves)
    Y = Y - T[:, :1]  # node 0's start at the origin

    # Yaw (Algorithm 2 lines 19–24, generalized to K moves): Q minimizing Σ_k ‖Q a_k − b_k‖²,
    # a_k the track in the layout, b_k the known ENU track, both about node 0's start.
    a = T[:, 1:] - T[:, :1]
    b = pb.track[:, 1:]
    C = np.einsum("bki,bkj->bij", b, a)  # C = Σ_k b_k a_kᵀ = U S Vᵀ
    U, _, Vt = np.linalg.svd(C)
    s = np.linalg.det(U) * np.linalg.det(Vt)
    # Q = U diag(1, d) Vᵀ: d = s gives det Q = +1 (rotation), d = −s the reflection.
    Q_rot = U * np.stack([np.ones_like(s), s], axis=-1)[:, None, :] @ Vt
    Q_ref = U * np.stack([np.ones_like(s), -s], axis=-1)[:, None, :] @ Vt
    Q_free = U @ Vt  # unconstrained best fit: the data choose the reflection
    X_rot = Y @ Q_rot.swapaxes(1, 2)
    X_ref = Y @ Q_ref.swapaxes(1, 2)
    X_free = Y @ Q_free.swapaxes(1, 2)
    rot_matches = horizontal_side(X_rot, pb.track, pb.ref) == pb.side
    X_conv = np.where(rot_matches[:, None, None], X_rot, X_ref)
    return pb.positions(np.where(pb.turns[:, None, None], X_free, X_conv))
