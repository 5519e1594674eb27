"""Nonlinear least-squares swarm initialization, the baseline of dtvirm Table 1.

The "commonly used" initializer of dtvirm §3.3: minimize Σ_ij (d_ij − ‖p_i − p_j‖)² over
the unknown positions, here with ``scipy.optimize.least_squares`` (Levenberg–Marquardt,
analytic Jacobian) where the paper used GTSAM. It takes the same inputs and returns the
same frame as ``mdsmap_init`` (see ``swarmloc.agents.estimators.init.mdsmap``): node 0's start and
its known track are fixed, altitudes are known, the unknowns are the horizontal positions
of nodes 1..N−1. The cost is non-convex; started from a random layout (the default) it
can stop in a local minimum, which is the weakness dtvirm's algebraic MDS-MAP avoids.

Residuals are 3D ranges weighted by √(number of measurements averaged), the maximum
likelihood weighting for i.i.d. range noise. Missing ranges are simply absent (no
shortest-path completion; NLS does not need a complete matrix). The mirror rule is the
same: a turning track lets the residuals decide; otherwise the solution is reflected
across node 0's first displacement line when it disagrees with ``side`` (that reflection
leaves every residual unchanged when the track is collinear).

Batch shapes: leading dims ``...`` (looped in Python: one solve per element), N UAVs.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares

from swarmloc.agents.estimators.init.mdsmap import FloatArray, InitProblem, horizontal_side, prepare_init_problem


def _solve_one(
    R: FloatArray, count: FloatArray, z: FloatArray, track: FloatArray, N: int, u0: FloatArray
) -> FloatArray:
    """Solve one problem; returns (N, 2) horizontal positions (node 0 at the origin)."""
    M = R.shape[0]
    i, j = np.triu_indices(M, k=1)
    # Keep measured pairs that involve at least one unknown node (1..N−1).
    unknown = np.zeros(M, dtype=bool)
    unknown[1:N] = True
    keep = np.isfinite(R[i, j]) & (count[i, j] > 0) & (unknown[i] | unknown[j])
    i, j = i[keep], j[keep]
    d = R[i, j]
    w = np.sqrt(count[i, j])
    dz = z[i] - z[j]
    E = i.size
    n_u = 2 * (N - 1)
    if E < n_u:
        raise ValueError(
            f"NLS needs at least as many measured ranges as unknowns; got {E} ranges for "
            f"{n_u} unknown coordinates (N = {N})"
        )
    # Column of each endpoint's x coordinate in the unknown vector, −1 for fixed points.
    col = np.full(M, -1)
    col[1:N] = 2 * np.arange(N - 1)
    ci, cj = col[i], col[j]
    rows = np.arange(E)
    fixed = np.zeros((M, 2))
    fixed[N:] = track[1:]

    def positions(u: FloatArray) -> FloatArray:
        p = fixed.copy()
        p[1:N] = u.reshape(N - 1, 2)
        return p

    def residual(u: FloatArray) -> FloatArray:
        p = positions(u)
        diff = p[i] - p[j]
        # r_e = w_e (‖p_i − p_j‖ − d_ij),  ‖·‖ in 3D with the known Δz
        rho = np.sqrt(np.einsum("ek,ek->e", diff, diff) + dz**2)
        return w * (rho - d)

    def jacobian(u: FloatArray) -> FloatArray:
        p = positions(u)
        diff = p[i] - p[j]
        rho = np.maximum(np.sqrt(np.einsum("ek,ek->e", diff, diff) + dz**2), 1e-12)
        # ∂r_e/∂p_i = w_e (p_i − p_j)_h / ρ_e = −∂r_e/∂p_j
        g = (w / rho)[:, None] * diff
        J = np.zeros((E, n_u))
        for c, sign in ((ci, 1.0), (cj, -1.0)):
            m = c >= 0
            J[rows[m], c[m]] = sign * g[m, 0]
            J[rows[m], c[m] + 1] = sign * g[m, 1]
        return J

    sol = least_squares(residual, u0, jac=jacobian, method="lm")
    return positions(sol.x)[:N]


def nls_init(
    D_pre: npt.ArrayLike,
    D_post: npt.ArrayLike,
    dX: npt.ArrayLike,
    z: npt.ArrayLike,
    *,
    side: int | npt.ArrayLike | None = None,
    ref: int = 1,
    min_turn: float = 0.1,
    x0: npt.ArrayLike | None = None,
    seed: int = 0,
) -> FloatArray:
    """Nonlinear least-squares swarm ENU positions, same inputs and frame as ``mdsmap_init``.

    Minimizes the weighted range residuals over the horizontal positions of nodes
    1..N−1 with node 0's start at the origin, its track fixed from ``dX`` and altitudes
    fixed from ``z``; then applies the mirror rule (see module docstring). With ``x0``
    None the start is a random layout, uniform in a square of half-side the largest
    measured range, drawn from ``numpy.random.default_rng(seed)``.

    Args:
        D_pre: (..., N, N) ranges before node 0 moves [m], NaN = missing.
        D_post: (..., K, N, N) ranges after each of node 0's K moves [m], NaN = missing.
        dX: (..., K, 3) node 0's ENU displacement in each move [m].
        z: (..., N) altitudes before the moves [m], any common datum.
        side: mirror convention ±1 (used only when the track does not turn), or None.
        ref: node whose side ``side`` states, 1 ≤ ref < N.
        min_turn: singular-value ratio from which a track counts as turning, in (0, 1].
        x0: (..., N, 2) optional horizontal starting layout relative to node 0 [m] (row 0
            ignored), finite.
        seed: seed of the random starting layout when ``x0`` is None.

    Returns:
        (..., N, 3) ENU positions [m], ``x[..., 0, :] == 0``.

    Raises:
        ValueError: see ``prepare_init_problem``; also a bad ``x0`` or fewer measured
            ranges than unknowns.
    """
    pb: InitProblem = prepare_init_problem(D_pre, D_post, dX, z, side=side, ref=ref, min_turn=min_turn)
    N = pb.n_nodes
    B = pb.R.shape[0]
    if x0 is None:
        rng = np.random.default_rng(seed)
        scale = np.nanmax(np.where(pb.count > 0, pb.R, np.nan).reshape(B, -1), axis=1)
        start = rng.uniform(-1.0, 1.0, size=(B, N, 2)) * scale[:, None, None]
    else:
        start = np.asarray(x0, dtype=np.float64)
        if start.shape != pb.lead + (N, 2):
            raise ValueError(f"x0 must have shape (..., N, 2) = {pb.lead + (N, 2)}; got {start.shape}")
        if not np.isfinite(start).all():
            raise ValueError("x0 must be finite; got NaN/inf")
        start = start.reshape(B, N, 2)

    X_h = np.stack(
        [_solve_one(pb.R[b], pb.count[b], pb.z[b], pb.track[b], N, start[b, 1:].ravel()) for b in range(B)]
    )
    # Mirror by convention where the track is collinear: reflect across the first move's line,
    # x' = 2 (u·x) u − x with u the unit first displacement.
    flip = ~pb.turns & (horizontal_side(X_h, pb.track, pb.ref) != pb.side)
    u = pb.track[:, 1] / np.linalg.norm(pb.track[:, 1], axis=-1, keepdims=True)
    X_flip = 2.0 * np.einsum("bnk,bk->bn", X_h, u)[..., None] * u[:, None, :] - X_h
    return pb.positions(np.where(flip[:, None, None], X_flip, X_h))
