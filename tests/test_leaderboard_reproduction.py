"""What verification relies on: re-running one episode alone gives its metrics from the full batch.

``swarmloc evaluate`` runs a task's 32 seeds as one batch; verification re-runs a sample,
often one seed of a task alone, and compares every metric exactly (deterministic methods).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from swarmloc.bench.evaluation.runner import evaluate_task, run_episodes
from swarmloc.bench.evaluation.suites import get_suite

pytestmark = pytest.mark.slow

POLICY = '''\
import numpy as np


class Ones:
    privileged = False
    flops_per_channel = 1.0

    def reset(self, batch_size, layout, keys):
        pass

    def act(self, inp):
        return np.ones(inp.nis.shape)


def make():
    return Ones()
'''


def test_one_episode_alone_reproduces_the_full_batch(tmp_path: Path) -> None:
    method_file = tmp_path / "ones.py"
    method_file.write_text(POLICY)
    method = f"{method_file}:make"
    task = "swarmloc/HybridNoise10-v0"
    seeds = get_suite("standard-v0").seeds(task)
    batch = evaluate_task([method], task, seeds).episodes[method]
    for seed in seeds[:4]:
        (alone,) = run_episodes(method, [(task, seed)])
        assert alone["metrics"] == batch[seeds.index(seed)], seed
