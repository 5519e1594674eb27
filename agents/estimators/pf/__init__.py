"""Particle-filter family and PF-NN (pf-nn-cooperative-localization): Track B estimators.

``core`` holds the numba kernels, ``reference`` the straightforward per-UAV numpy
version of the same filter, ``pfnn`` the 6–12–1 weight-correction network, ``filters``
the estimator classes and their factories, ``train`` the offline network fit.
"""

from swarmloc.agents.estimators.pf.filters import (
    ADAPTIVE,
    FIXED_800,
    STANDARD,
    ParticleFilter,
    PFConfig,
    PFNNOnlineOracle,
    make_adaptive_pf,
    make_pf,
    make_pf800,
    make_pfnn,
    make_pfnn_online_oracle,
)

__all__ = [
    "ADAPTIVE",
    "FIXED_800",
    "STANDARD",
    "PFConfig",
    "PFNNOnlineOracle",
    "ParticleFilter",
    "make_adaptive_pf",
    "make_pf",
    "make_pf800",
    "make_pfnn",
    "make_pfnn_online_oracle",
]
