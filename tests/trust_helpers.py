"""Hand-made Track A inputs shared by the tests of the classical trust methods."""

from __future__ import annotations

import numpy as np

from swarmloc.agents.protocols import TrustInput
from swarmloc.envs.tasks.channels import ChannelLayout


def trust_layout(kinds: list[int]) -> ChannelLayout:
    """A one-UAV layout with channels of the given kinds (unit σ, every slot linked)."""
    kind = np.array([kinds])
    return ChannelLayout(kind=kind, target=np.zeros_like(kind), linked=np.ones(kind.shape, bool),
                         sigma=np.ones(kind.shape))


def trust_input(nis: np.ndarray, valid: np.ndarray | None = None, step: int = 1) -> TrustInput:
    """A ``TrustInput`` whose channels have normalized innovation squared ``nis`` (shape (B, N, L))."""
    shape = nis.shape
    valid = np.ones(shape, dtype=bool) if valid is None else valid
    zeros = np.zeros(shape)
    return TrustInput.view(np.zeros((*shape, 11), np.float32), np.sqrt(nis), zeros, nis, np.ones(shape),
                           np.zeros(shape[:2]), valid, 0.1 * step, step)


def obs_input(obs: np.ndarray) -> TrustInput:
    """A ``TrustInput`` carrying the observation ``obs`` (B, N, L, F) (raw fields zero, trust 1, valid from obs)."""
    from swarmloc.envs.world.observation import VALID

    b, n, n_l, _ = obs.shape
    z = np.zeros((b, n, n_l))
    return TrustInput.view(obs, z, z, z, np.ones((b, n, n_l)), np.zeros((b, n)), obs[..., VALID] > 0.5, 0.1, 1)
