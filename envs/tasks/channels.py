"""Channel layout: which measurement each of a UAV's L channel slots carries.

Per UAV the slots are, in order: anchors (one range per anchor, or one range difference
per TDOA pair), peers (every other UAV, in index order), landmark slots (one per
landmark), GPS. The layout is static per task; measurements that are absent in a step
(out of range, lost, outside the topology) are masked, never dropped from the shape. A UAV
without a GNSS receiver (``Sensors.gps_nodes``) keeps its GPS slot, never linked.

A TDOA channel refers to two anchors: its ``target`` is the pair code ``i·A + j`` (A the
number of anchors) of the pair (i, j) it measures, z = ‖p − a_j‖ − ‖p − a_i‖
(``tdoa_pair`` decodes it), so every kernel keeps one target index per channel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmloc.envs.tasks.specs import TaskSpec

ANCHOR, PEER, LANDMARK, GPS, PEER_REL, TDOA = 0, 1, 2, 3, 4, 5
KIND_NAMES = ("anchor", "peer", "landmark", "gps", "peer_rel", "tdoa")
#: columns of the observation's kind one-hot (anchor, peer, landmark, gps, peer_rel): a TDOA
#: channel shares the anchor column (an anchor-referenced scalar, ``OBS_KIND_COLUMN``), so the
#: observation keeps its 11 features and every trained policy runs on TDOA tasks unchanged
N_KINDS = 5
#: one-hot column of each kind id
OBS_KIND_COLUMN = np.array([0, 1, 2, 3, 4, 0], dtype=np.int64)
#: scalar rows a channel of each kind contributes to the joint update
KIND_DIM = np.array([1, 1, 3, 3, 3, 1], dtype=np.int64)


def tdoa_code(i: int, j: int, n_anchors: int) -> int:
    """Target code of the TDOA pair (i, j): ``i·A + j``."""
    return i * n_anchors + j


def tdoa_pair(code: int, n_anchors: int) -> tuple[int, int]:
    """The anchor pair (i, j) of a TDOA target code (z = ‖p − a_j‖ − ‖p − a_i‖)."""
    return code // n_anchors, code % n_anchors


@dataclass(frozen=True)
class ChannelLayout:
    """Static channel description of a task.

    Attributes:
        kind: ``(N, L)`` channel kind ids (ANCHOR, PEER, LANDMARK, GPS, PEER_REL, TDOA).
        target: ``(N, L)`` anchor / UAV / landmark index the channel refers to (-1 for GPS;
            the pair code ``i·A + j`` for TDOA).
        linked: ``(N, L)`` whether the topology connects the slot at all (a GPS slot: whether
            the UAV has a receiver).
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
    """Whether UAV i measures UAV j (i ≠ j) under the task's peer topology."""
    topology = spec.sensors.peers.topology
    if topology == "all":
        return True
    if topology == "chain":
        return abs(i - j) == 1
    # leader topology: a follower links to every leader, a leader to the other leaders; so
    # i measures j exactly when j leads (with the one leader (0,): followers to UAV 0 only)
    return j in spec.sensors.peers.leaders


def _has_receiver(spec: TaskSpec, i: int) -> bool:
    """Whether UAV i carries a GNSS receiver (``Sensors.gps_nodes``; empty: every UAV)."""
    return not spec.sensors.gps_nodes or i in spec.sensors.gps_nodes


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
        if s.tdoa is None:
            for a in range(len(spec.anchors)):
                kind[i, col], target[i, col], sigma[i, col] = ANCHOR, a, s.anchor_sigma
                col += 1
        else:
            for a, b in s.tdoa.pairs:
                kind[i, col], target[i, col], sigma[i, col] = TDOA, tdoa_code(a, b, len(spec.anchors)), s.tdoa.sigma
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
            linked[i, col] = _has_receiver(spec, i)
            col += 1
    return ChannelLayout(kind=kind, target=target, linked=linked, sigma=sigma)
