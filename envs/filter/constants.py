"""The CEKF peer updates' numeric constants, in a module without numba (``world.cost`` counts FLOPs
with them, and ``swarmloc --help`` must not import numba)."""

#: a range shorter than this is degenerate (no direction): the channel is skipped
MIN_RANGE = 1e-9
#: the covariance intersections' weight ω is searched on {1/CI_GRID, …, (CI_GRID − 1)/CI_GRID} and 1
CI_GRID = 50
#: ``"split_ci"``: multiplicative steps of the weight search after the grid (Scale32 with the anchors
#: ranged within 11 m, 31 peers, step 200: tr P⁺ within 0.1 % of its value after 1,000 steps; without
#: the steps, uniform's RMSE is 5–9 % higher on the Scale variants, 4 dev seeds)
SPLIT_CI_STEPS = 20
#: ``"split_ci"``: the smallest weight a step leaves; a source at it adds nothing (D/ω dwarfs the rest)
OMEGA_FLOOR = 1e-6
