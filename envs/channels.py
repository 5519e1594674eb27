"""Channel layout: which measurement each of a UAV's L channel slots carries.

Per UAV the slots are, in order: anchors, peers (every other UAV, in index order),
landmark slots (one per landmark), GPS. The layout is static per task; measurements that
are absent in a step (out of range, lost, outside the topology) are masked, never
dropped from the shape.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .specs import TaskSpec

ANCHOR, PEER, LANDMARK, GPS, PEER_REL = 0, 1, 2, 3, 4
KIND_NAMES = ("anchor", "peer", "landmark", "gps", "peer_rel")
N_KINDS = len(KIND_NAMES)
#: scalar rows a channel of each kind contributes to the joint update
KIND_DIM = np.array([1, 1, 3, 3, 3], dtype=np.int64)


@dataclass(frozen=True)
class ChannelLayout:
    """Static channel description of a task.

    Attributes:
        kind: ``(N, L)`` channel kind ids (ANCHOR, PEER, LANDMARK, GPS, PEER_REL).
        target: ``(N, L)`` anchor / UAV / landmark index the channel refers to (-1 for GPS).
        linked: ``(N, L)`` whether the topology connects the slot at all.
        sigma: ``(N, L)`` nominal noise std per scalar row [m].
    """

    kind: np.ndarray
    target: np.ndarray
    linked: np.ndarray
    sigma: np.ndarray

    @property
    def n_channels(self) -> int:
        return self.kind.shape[1]

    @property
    def r0(self) -> np.ndarray:
        """Nominal variance per channel ``(N, L)`` (R0 = σ²)."""
        return self.sigma**2


def _peer_linked(spec: TaskSpec, i: int, j: int) -> bool:
    topology = spec.sensors.peers.topology
    if topology == "all":
        return True
    if topology == "chain":
        return abs(i - j) == 1
    # leader topology: UAV 0 leads; every follower links to the leader only
    return i != 0 and j == 0


def build_layout(spec: TaskSpec) -> ChannelLayout:
    """Build the static channel layout of ``spec``."""
    n, n_l = spec.n_uav, spec.n_channels
    s = spec.sensors
    kind = np.zeros((n, n_l), dtype=np.int64)
    target = np.full((n, n_l), -1, dtype=np.int64)
    linked = np.ones((n, n_l), dtype=np.bool_)
    sigma = np.zeros((n, n_l))
    peer_kind = PEER if s.peers.kind == "range" else PEER_REL
    for i in range(n):
        col = 0
        for a in range(len(spec.anchors)):
            kind[i, col], target[i, col], sigma[i, col] = ANCHOR, a, s.anchor_sigma
            col += 1
        if spec.n_peer_channels:
            for j in range(n):
                if j == i:
                    continue
                kind[i, col], target[i, col], sigma[i, col] = peer_kind, j, s.peers.sigma
                linked[i, col] = _peer_linked(spec, i, j)
                col += 1
        for m in range(len(spec.landmarks)):
            kind[i, col], target[i, col], sigma[i, col] = LANDMARK, m, s.camera_sigma
            col += 1
        if s.gps_sigma:
            kind[i, col], target[i, col], sigma[i, col] = GPS, -1, s.gps_sigma[i]
            col += 1
    return ChannelLayout(kind=kind, target=target, linked=linked, sigma=sigma)
