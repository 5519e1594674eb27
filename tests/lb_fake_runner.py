"""A stand-in for ``swarmloc.bench.evaluation.runner.run_episodes`` used by the leaderboard tests.

Standard library only. Metrics are a pure function of (task, seed). Like the real
runner it builds the method by calling its factory — during verification that call goes
to the method's own sandbox (``swarmloc.bench.evaluation.remote_method``) — so the
factory's name selects a behaviour, run where the submitted code runs:

* ``good*``    — a method that does nothing; the runner returns the deterministic metrics;
* ``crash``    — raise inside the method;
* ``sleep``    — sleep far past any test time limit;
* ``oom``      — allocate far past any test memory limit;
* ``envcheck`` — fail unless the method's environment is clean (no store URL).

The runner itself also refuses to run with a store URL in its environment.
"""

from __future__ import annotations

import hashlib
import importlib
import os
import time
from typing import Any


def metrics_for(task: str, seed: int) -> dict[str, float | None]:
    """Deterministic, physically plausible metrics for one episode."""
    digest = hashlib.sha256(f"{task}|{seed}".encode()).digest()
    u = [b / 255.0 for b in digest[:8]]
    rmse = 0.2 + u[0]
    return {
        "rmse": rmse,
        "mean_error": 0.8 * rmse,
        "median_error": 0.7 * rmse,
        "max_error": 3.0 * rmse,
        "cep90": 1.5 * rmse,
        "fault_rmse": None,
        "healthy_rmse": rmse,
        "diverged": 0.0,
        "delay_ms": 1.0 + u[1],
        "energy_j": 0.1 + u[2],
        "jitter": 0.05 * u[3],
        "weight_var": 0.1 * u[4],
        "anomaly_detection_rate": None,
        "team_return": 300.0 + 100.0 * u[5],
    }


class Idle:
    """A Track A method that never runs a step (the fake runner computes nothing)."""

    def reset(self, batch_size: int, layout: Any, keys: Any) -> None:
        """Nothing to reset."""

    def act(self, inp: Any) -> None:
        """Never called."""


def _leaked() -> list[str]:
    return sorted(k for k in os.environ if k.startswith("SWARMLOC") or k == "LEAK_CANARY")


def crash() -> Idle:
    raise RuntimeError("simulated crash inside the method")


def sleep() -> Idle:
    time.sleep(120)
    return Idle()


def oom() -> Idle:
    hog = bytearray(8 * 1024**3)
    raise AssertionError(f"allocated {len(hog)} bytes despite the memory limit")


def envcheck() -> Idle:
    if _leaked():
        raise RuntimeError(f"the method's process inherited {_leaked()}")
    return Idle()


def __getattr__(name: str) -> Any:
    if name.startswith("good"):
        return Idle
    raise AttributeError(f"module 'lb_fake_runner' has no attribute {name!r}")


def run_episodes(method: str, episodes: list[tuple[str, int]], weights: str | None = None) -> list[dict]:
    """Build the method through its factory, then return the metrics of ``episodes``."""
    if _leaked():
        raise RuntimeError(f"the verification worker inherited {_leaked()}")
    module_name, sep, attr = method.partition(":")
    if sep:  # registered names are shipped methods: nothing to build here
        factory = getattr(importlib.import_module(module_name), attr)
        factory(weights=weights) if weights else factory()
    return [{"task": t, "seed": s, "metrics": metrics_for(t, s)} for t, s in episodes]


def run_episodes_with_reference(method: str, episodes: list[tuple[str, int]],
                                weights: str | None = None) -> list[dict]:
    """As :func:`run_episodes`, and every episode carries ``uniform_rmse`` (= its RMSE: a gain of 0)."""
    return [{**e, "metrics": {**e["metrics"], "uniform_rmse": e["metrics"]["rmse"]}}
            for e in run_episodes(method, episodes, weights)]
