"""A stand-in for ``swarmloc.bench.evaluation.runner.run_episodes`` used by the leaderboard tests.

Standard library only (it runs inside the verification worker). Metrics are a pure
function of (task, seed). The method's factory name selects a behaviour:

* ``...:good*``  — return the deterministic metrics;
* ``...:crash``  — raise inside the method;
* ``...:sleep``  — sleep far past any test time limit;
* ``...:oom``    — allocate far past any test memory limit;
* ``...:envcheck`` — fail unless the worker's environment is clean (no store URL).
"""

from __future__ import annotations

import hashlib
import os
import time


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
        "normalized_score": u[6] - 0.2,
    }


def run_episodes(method: str, episodes: list[tuple[str, int]], weights: str | None = None) -> list[dict]:
    """Re-run ``episodes`` of ``method`` (see the module docstring for behaviours)."""
    behaviour = method.rpartition(":")[2]
    if behaviour == "crash":
        raise RuntimeError("simulated crash inside the method")
    if behaviour == "sleep":
        time.sleep(120)
    if behaviour == "envcheck":
        leaked = sorted(k for k in os.environ if k.startswith("SWARMLOC") or k == "LEAK_CANARY")
        if leaked:
            raise RuntimeError(f"the worker inherited {leaked}")
    if behaviour == "oom":
        hog = bytearray(8 * 1024**3)
        return [{"task": "never", "seed": len(hog), "metrics": {}}]
    return [{"task": t, "seed": s, "metrics": metrics_for(t, s)} for t, s in episodes]
