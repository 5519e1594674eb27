"""The CEKF peer updates' numeric constants, in a module without numba (``world.cost`` counts FLOPs
with them, and ``swarmloc --help`` must not import numba)."""

#: a range shorter than this is degenerate (no direction): the channel is skipped
MIN_RANGE = 1e-9
#: the covariance intersections' weight ω is searched on {1/CI_GRID, …, (CI_GRID − 1)/CI_GRID} and 1
CI_GRID = 50
#: ``"split_ci"``: the weight search's ω_0 grid {1/SPLIT_CI_GRID, …} and the multiplicative steps after it.
#: Measured (uniform, faults off, dev seeds 2000000–3, position NEES / RMSE in m; Scale6-v0 world steps at
#: B=1024 on the 2-core dev machine), grid/steps 50/20: Scale8-v1 with anchors ranged within 11 m 2.31 /
#: 0.238, Scale32-v1 likewise 2.10 / 0.212, Scale8-v1 3.03 / 0.139, 19.6k env-steps/s; 10/5: 2.27 / 0.243,
#: 2.01 / 0.211, 3.03 / 0.139, 58k env-steps/s; 5/5: 0.246, 0.217, 68k; 2/10: 0.243, 0.214, 59k
SPLIT_CI_GRID = 10
SPLIT_CI_STEPS = 5
#: ``"split_ci"`` after an update with peers: the next search starts warm, from the weights of the UAV's
#: previous update (each peer's by its channel) mixed with the Δ-share start in this proportion (a peer the
#: steps drove to the floor, or a new one, gets back a share: the start mixes in ω_0 = 1/2 and the shares
#: of the other half), then takes this many multiplicative steps. Measured as above, mix / steps 0.02 / 3:
#: 2.28 / 0.242, 2.01 / 0.213, 3.03 / 0.139, 93.5k env-steps/s (cold searches at every update: 62k);
#: 0.02 / 2: 0.244, 0.215, 102k; 0.1 / 2: 0.250, 0.221, 99k
SPLIT_CI_WARM_MIX = 0.02
SPLIT_CI_WARM_STEPS = 3
#: ``"split_ci"``: weights are kept for the next search only where the dependent parts they act on
#: (tr D' + Σ_j the neighbours' dependent position parts) exceed this share of tr P (at a reset there are
#: none: every weight gives the same update, and the search only follows the gradients' rounding)
SPLIT_CI_DEPENDENT_FLOOR = 1e-9
#: ``"split_ci"``: the smallest weight a step leaves; a source at it adds nothing (D/ω dwarfs the rest)
OMEGA_FLOOR = 1e-6
