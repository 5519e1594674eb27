"""Swarm position initializers from inter-UAV ranges (dtvirm §3.3 and §3.5).

``mdsmap_init`` is dtvirm's algebraic MDS-MAP initializer; ``nls_init`` is the nonlinear
least-squares initializer it is compared with (dtvirm Table 1). Both take the same inputs
(range matrices before and after node 0's short known moves, that displacement, the
altitudes) and return positions in the same frame: ENU with node 0's starting point at
the origin. See ``swarmloc.agents.estimators.init.mdsmap`` for the frame and the mirror convention.
"""

from swarmloc.agents.estimators.init.mdsmap import (
    InitProblem,
    classical_mds,
    complete_distances,
    mdsmap_init,
    prepare_init_problem,
)
from swarmloc.agents.estimators.init.nls import nls_init

__all__ = [
    "InitProblem",
    "classical_mds",
    "complete_distances",
    "mdsmap_init",
    "nls_init",
    "prepare_init_problem",
]
