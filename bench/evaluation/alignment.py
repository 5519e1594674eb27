"""Rigid yaw + translation alignment for anchor-free tasks (dtvirm §3.8, Theorem 1).

With only inter-UAV ranges and on-board odometry, a swarm's absolute 3-D translation and
yaw are unobservable: an estimator works in a frame of its own (dtvirm's: node 0's first
position is the origin). A task with ``spec.scoring.align_first_seconds = s > 0`` is
therefore scored after the 4-DoF transform T(p) = R_z(ψ) p + t that best aligns, in the
least-squares sense, the estimates of every scored UAV over the first s seconds of the
scored interval (``scoring.start ≤ t < scoring.start + s``) with the truth. The same T
is applied to the whole episode, so drift after the alignment window counts in full
(evo's ``--n_to_align`` with a yaw-only rotation).

Closed form: with centred point sets a′ = a − ā, b′ = b − b̄ (horizontal components),
ψ = atan2(Σ a′ₓb′_y − a′_yb′ₓ, Σ a′ₓb′ₓ + a′_yb′_y), t = b̄ − R_z(ψ) ā.
"""

from __future__ import annotations

import numpy as np

from swarmloc.envs.tasks.specs import TaskSpec


def yaw_translation_fit(estimate: np.ndarray, truth: np.ndarray, weight: np.ndarray | None = None
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares R_z(ψ), t with R_z(ψ) a + t ≈ b over the points, batched over leading dims.

    Args:
        estimate: (..., M, 3) points a; truth: (..., M, 3) points b.
        weight: optional (..., M) non-negative point weights (e.g. a mask); default all 1.

    Returns:
        R: (..., 3, 3) rotations about z; t: (..., 3) translations.

    Raises:
        ValueError: shapes differ, or some batch element has no weighted point.
    """
    a = np.asarray(estimate, dtype=np.float64)
    b = np.asarray(truth, dtype=np.float64)
    if a.shape != b.shape or a.ndim < 2 or a.shape[-1] != 3:
        raise ValueError(f"estimate and truth must both have shape (..., M, 3); got {a.shape} and {b.shape}")
    w = np.ones(a.shape[:-1]) if weight is None else np.broadcast_to(np.asarray(weight, dtype=np.float64),
                                                                    a.shape[:-1])
    total = w.sum(axis=-1)
    if (total <= 0).any():
        raise ValueError("every batch element needs at least one point with positive weight to align")
    a_bar = np.einsum("...m,...md->...d", w, a) / total[..., None]
    b_bar = np.einsum("...m,...md->...d", w, b) / total[..., None]
    ac, bc = a - a_bar[..., None, :], b - b_bar[..., None, :]
    # ψ = atan2(Σ w (a′ₓ b′_y − a′_y b′ₓ), Σ w (a′ₓ b′ₓ + a′_y b′_y))
    s = np.sum(w * (ac[..., 0] * bc[..., 1] - ac[..., 1] * bc[..., 0]), axis=-1)
    c = np.sum(w * (ac[..., 0] * bc[..., 0] + ac[..., 1] * bc[..., 1]), axis=-1)
    psi = np.arctan2(s, c)
    R = np.zeros(psi.shape + (3, 3))
    R[..., 0, 0], R[..., 0, 1] = np.cos(psi), -np.sin(psi)
    R[..., 1, 0], R[..., 1, 1] = np.sin(psi), np.cos(psi)
    R[..., 2, 2] = 1.0
    # t = b̄ − R ā
    t = b_bar - np.einsum("...ij,...j->...i", R, a_bar)
    return R, t


def alignment_steps(spec: TaskSpec, times: np.ndarray) -> np.ndarray:
    """(T,) bool: the steps of ``times`` the alignment is fitted on (empty when the task has none)."""
    s = spec.scoring
    times = np.asarray(times, dtype=np.float64)
    if s.align_first_seconds <= 0:
        return np.zeros(times.shape, dtype=bool)
    eps = 1e-9  # k·dt == start stays inside despite rounding
    return (times >= s.start - eps) & (times < s.start + s.align_first_seconds - eps)


def align_estimates(spec: TaskSpec, times: np.ndarray, estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """The estimates after the task's scoring alignment (unchanged when it has none).

    Args:
        spec: the task (``scoring.align_first_seconds``, ``scoring.start``, scored nodes).
        times: (T,) step times [s].
        estimate: (T, B, N, 3) estimated positions; truth: (T, B, N, 3) true positions.

    Returns:
        (T, B, N, 3) aligned estimates, one transform per episode (axis B).
    """
    steps = alignment_steps(spec, times)
    estimate = np.asarray(estimate, dtype=np.float64)
    if not steps.any():
        return estimate
    nodes = list(spec.scored_nodes)
    n_t, n_b = int(steps.sum()), estimate.shape[1]
    # points: (B, T_align·N_scored, 3)
    a = np.moveaxis(estimate[steps][:, :, nodes], 1, 0).reshape(n_b, n_t * len(nodes), 3)
    b = np.moveaxis(np.asarray(truth)[steps][:, :, nodes], 1, 0).reshape(n_b, n_t * len(nodes), 3)
    R, t = yaw_translation_fit(a, b)
    return np.einsum("bij,tbnj->tbni", R, estimate) + t[None, :, None, :]
