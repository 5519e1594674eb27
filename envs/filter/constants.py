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
#: ``"split_ci"``: the smallest weight a step leaves; a source at it adds nothing (D/ω dwarfs the rest)
OMEGA_FLOOR = 1e-6
