"""Episode seeds: their bound and the ranges that training, tuning and testing own.

An episode seed is an integer in ``[0, SEED_BOUND)``; every random draw of an episode is
keyed by it (``envs/tasks/rng.py``). The ranges are disjoint so that no training or tuning run
ever sees a test episode:

| range | use |
|---|---|
| ``[0, 1_000_000)`` | training: anything, as much as you like |
| ``[1_000_000, 2_000_000)`` | **test** seeds (the leaderboard suites) |
| ``[2_000_000, 3_000_000)`` | **dev** (tuning) seeds |
| ``≥ 3_000_000`` | reserved for future suites |
"""

from __future__ import annotations

from collections.abc import Iterable

#: exclusive upper bound of every episode seed (and of Gymnasium's seeds here)
SEED_BOUND = 2**63 - 1
#: exclusive upper bound of training seeds
TRAINING_SEED_LIMIT = 1_000_000
TEST_SEED_START = 1_000_000
DEV_SEED_START = 2_000_000
RESERVED_SEED_START = 3_000_000


def check_training_seeds(seeds: Iterable[int]) -> None:
    """Refuse seeds that training may not use (test, dev and reserved ranges).

    Args:
        seeds: the seeds a training run draws.

    Raises:
        ValueError: naming the offending seeds; training seeds must be in [0, 1_000_000).
    """
    bad = [int(s) for s in seeds if not 0 <= int(s) < TRAINING_SEED_LIMIT]
    if bad:
        kinds = []
        if any(TEST_SEED_START <= s < DEV_SEED_START for s in bad):
            kinds.append("test")
        if any(DEV_SEED_START <= s < RESERVED_SEED_START for s in bad):
            kinds.append("dev")
        what = " and ".join(kinds) or "out-of-range"
        raise ValueError(f"{len(bad)} {what} seed(s) given to training, e.g. {bad[:5]}; "
                         f"training seeds must be in [0, {TRAINING_SEED_LIMIT})")
