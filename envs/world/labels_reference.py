"""Readable numpy version of the error labels (``labels.py``), the oracle of the kernels' tests.

One episode-step at a time, dense linear algebra, no shortcuts: for channel l of UAV i

* own error (anchor range, GPS): e = the world's systematic error, S = σ² (I for GPS);
* peer range: e = b + ‖p_i − p_j‖ − ‖p_i − p̂_j‖, S = σ² + uᵀ P_j,pp u, u = (p_i − p̂_j) / ‖p_i − p̂_j‖;
* relative position: e = p_j − p̂_j, S = σ² I + P_j,pp;
* landmark: e = 0;

``sigmas = sqrt(eᵀ S⁻¹ e)`` and ``label = valid and sigmas > threshold`` (``labels.label_thresholds``:
k for scalar ranges, a Mahalanobis radius for 3-vector channels).
"""

from __future__ import annotations

import numpy as np

from swarmloc.envs.tasks.channels import ANCHOR, GPS, LANDMARK, PEER, PEER_REL, TDOA


def systematic_sigmas_reference(kind: np.ndarray, target: np.ndarray, sigma: np.ndarray, systematic: np.ndarray,
                                pos: np.ndarray, prior_pos: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Every channel's systematic error in units of σ_eff, for one episode-step.

    Args:
        kind, target, sigma: ``(N, L)`` the channel layout.
        systematic: ``(N, L, 3)`` the world's own systematic error (ranges in component 0) [m].
        pos: ``(N, 3)`` true positions; prior_pos ``(N, 3)`` the broadcast priors [m].
        P: ``(N, 6, 6)`` prior covariances.

    Returns:
        ``(N, L)`` sqrt(eᵀ S⁻¹ e).
    """
    n, n_l = kind.shape
    out = np.zeros((n, n_l))
    for i in range(n):
        for l in range(n_l):
            ch, j, sg = kind[i, l], target[i, l], sigma[i, l]
            if ch == ANCHOR or ch == TDOA:
                e, S = systematic[i, l, :1], np.array([[sg**2]])
            elif ch == GPS:
                e, S = systematic[i, l], sg**2 * np.eye(3)
            elif ch == PEER:
                used = pos[i] - prior_pos[j]
                u = used / np.linalg.norm(used)
                e = np.array([systematic[i, l, 0] + np.linalg.norm(pos[i] - pos[j]) - np.linalg.norm(used)])
                S = np.array([[sg**2 + u @ P[j, :3, :3] @ u]])
            elif ch == PEER_REL:
                e, S = pos[j] - prior_pos[j], sg**2 * np.eye(3) + P[j, :3, :3]
            else:
                assert ch == LANDMARK, ch
                continue
            out[i, l] = np.sqrt(e @ np.linalg.solve(S, e))
    return out


def error_labels_reference(kind: np.ndarray, target: np.ndarray, sigma: np.ndarray, systematic: np.ndarray,
                        valid: np.ndarray, pos: np.ndarray, prior_pos: np.ndarray, P: np.ndarray,
                        threshold: np.ndarray) -> np.ndarray:
    """Labels v1 ``(N, L)`` of one episode-step: present and ``systematic_sigmas > threshold``.

    Args:
        valid: ``(N, L)`` measurement present; threshold ``(N, L)`` (``labels.label_thresholds``);
            the rest as in ``systematic_sigmas_reference``.
    """
    return valid & (systematic_sigmas_reference(kind, target, sigma, systematic, pos, prior_pos, P) > threshold)


def own_error_labels_reference(kind: np.ndarray, sigma: np.ndarray, systematic: np.ndarray, valid: np.ndarray,
                            threshold: np.ndarray) -> np.ndarray:
    """The world's error labels ``(..., N, L)``: the measurement's own error only (no neighbour part).

    Args:
        kind, sigma, threshold: ``(N, L)``; systematic ``(..., N, L, 3)``; valid ``(..., N, L)``.
    """
    scalar = (kind == ANCHOR) | (kind == PEER) | (kind == TDOA)
    size = np.where(scalar, np.abs(systematic[..., 0]), np.where(kind == GPS, np.linalg.norm(systematic, axis=-1), 0.0))
    return valid & (size / sigma > threshold)
