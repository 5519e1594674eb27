"""A composite link trust: sequential detection on the absolute channels, covariance-aware gating on the peers.

``cusum-chi2`` gives each channel kind the rule that fits its faults:

| channels | rule | why |
|---|---|---|
| absolute (anchor, TDOA, landmark, GPS) | ``cusum``: Page's CUSUM on the NIS, readmitted by a reverse CUSUM | their faults persist (an NLOS bias, a drifting fix): evidence accumulates |
| peer (range, relative position) | ``chi2-soft``: exp(−max(NIS − χ²_conf(dof), 0) / 2σ²) | a peer's NIS includes the neighbour's broadcast covariance (v1 and v2 tasks), so one step already weighs the neighbour's own uncertainty |

CUSUM runs on every channel, peers included: its per-UAV admissibility check counts the peer
group as one witness (``integrity.py``), so its decisions on the absolute channels are exactly
``cusum``'s; only its decisions on the peer channels are replaced by ``chi2-soft``'s.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from swarmloc.agents.protocols import TrustInput
from swarmloc.agents.trust.classical import ALPHA_MIN, Chi2SoftTrust
from swarmloc.agents.trust.integrity import CusumTrust
from swarmloc.agents.trust.search_space import Param
from swarmloc.envs.tasks.channels import PEER, PEER_REL, ChannelLayout


class CusumChi2Trust:
    """α = ``cusum``'s on absolute channels, ``chi2-soft``'s on peer channels (module docstring).

    Args:
        design_ratio, arl, alpha_reject: the CUSUM's (``CusumTrust``: λ, ARL₀, the trust of a distrusted channel).
        confidence, softness: the soft gate's (``Chi2SoftTrust``: the gate quantile, σ).
    """

    privileged: bool = False
    deterministic: bool = True
    #: both parents run on every channel
    flops_per_channel = CusumTrust.flops_per_channel + Chi2SoftTrust.flops_per_channel
    #: what ``swarmloc tune cusum-chi2`` searches: the CUSUM's space, then the soft gate's (docs/tuning.md)
    SEARCH_SPACE: ClassVar[tuple[Param, ...]] = CusumTrust.SEARCH_SPACE + Chi2SoftTrust.SEARCH_SPACE

    def __init__(self, design_ratio: float = 4.0, arl: float = 1e4, alpha_reject: float = ALPHA_MIN,
                 confidence: float = 0.95, softness: float = 1.0) -> None:
        self.cusum = CusumTrust(design_ratio, arl, alpha_reject)
        self.chi2_soft = Chi2SoftTrust(confidence, softness)
        self._is_peer = np.zeros((1, 1), dtype=bool)

    # the constructor's arguments, read back from the parents that hold them
    design_ratio = property(lambda self: self.cusum.design_ratio)
    arl = property(lambda self: self.cusum.arl)
    alpha_reject = property(lambda self: self.cusum.alpha_reject)
    confidence = property(lambda self: self.chi2_soft.confidence)
    softness = property(lambda self: self.chi2_soft.softness)

    def reset(self, batch_size: int, layout: ChannelLayout, keys: np.ndarray) -> None:
        """Start B episodes: reset both parents and mark the layout's peer channels.

        Args:
            batch_size: B.
            layout: the task's channel layout.
            keys: ``(B,)`` per-episode random keys (unused: both parents are deterministic).
        """
        self.cusum.reset(batch_size, layout, keys)
        self.chi2_soft.reset(batch_size, layout, keys)
        self._is_peer = np.isin(layout.kind, (PEER, PEER_REL))  # (N, L)

    def act(self, inp: TrustInput) -> np.ndarray:
        """Step both parents; take the CUSUM's trust on absolute channels, the soft gate's on peers.

        Returns:
            ``(B, N, L)`` trust.
        """
        sequential = self.cusum.act(inp)  # every channel: the peers' alarms count in its admissibility check
        soft = self.chi2_soft.act(inp)
        return np.where(self._is_peer, soft, sequential)

    def __repr__(self) -> str:
        return (f"CusumChi2Trust(design_ratio={self.design_ratio}, arl={self.arl}, alpha_reject={self.alpha_reject}, "
                f"confidence={self.confidence}, softness={self.softness})")


def cusum_chi2_policy() -> CusumChi2Trust:
    """Registry factory: ``cusum-chi2`` (the parents' registered defaults: λ = 4, ARL₀ = 10⁴, α_min; 95 %, σ = 1)."""
    return CusumChi2Trust(4.0, 1e4, ALPHA_MIN, 0.95, 1.0)
