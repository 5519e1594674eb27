"""Speed benchmark: side-by-side throughput on identical inputs, in one run.

Rows (``impl``): ``filterpy`` (FilterPy's ExtendedKalmanFilter, one UAV at a time),
``reference`` (our pure-numpy float64 CEKF), ``kernel`` (our fused numba CEKF, whole
sequences per call) at B = 1, 64, 1024, 4096 on the same recorded measurements (Ideal-v0
world, one UAV per episode, six anchors). Other modules add their own rows through
``EXTRA_ROWS``, first ``world`` and ``world-unfused`` (the full link-trust step on
Scale6-v0 at the same B, ``speed/world.py``). Ratios are to FilterPy.

Usage: ``swarmloc bench speed [--json PATH] [--quick]``.
"""

from __future__ import annotations

import importlib
import json
import os
import platform
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numba
import numpy as np

from swarmloc.bench.common.files import write_text_atomic
from swarmloc.envs.filter import cekf
from swarmloc.envs.filter.cekf_reference import run_reference
from swarmloc.envs.world.core import SERIAL_BELOW
from swarmloc.envs.tasks.catalogue import get_spec
from swarmloc.envs.world.sim import World

BATCHES = (1, 64, 1024, 4096)
#: ``--quick`` (a smoke run): batches below ``SERIAL_BELOW``, so that it compiles only the
#: calling-thread kernels; the threaded ones cost minutes of cold compilation, and their
#: equality with the calling-thread ones is tested on its own (tests/test_world_kernel.py)
QUICK_BATCHES = (1, 16)
#: modules exposing ``measure_rows(quick: bool) -> list[dict]`` appended to the table when importable
EXTRA_ROWS = ("swarmloc.bench.speed.world:measure_rows", "swarmloc.bench.speed.envs:measure_env_rows",
              "swarmloc.bench.speed.estimators:measure_rows", "swarmloc.bench.speed.evaluation:measure_rows")


@dataclass
class Recording:
    """Measurements of B one-UAV episodes, T steps (the identical input of every impl)."""

    x0: np.ndarray
    P0: np.ndarray
    imu: np.ndarray
    z: np.ndarray
    valid: np.ndarray
    alpha: np.ndarray
    world: World


def record(batch: int, n_steps: int) -> Recording:
    """Record ``n_steps`` of Ideal-v0 with one UAV per episode for ``batch`` episodes."""
    spec = get_spec("swarmloc/Ideal-v0", n_uav=1)
    world = World(spec, batch)
    x0 = world.reset(np.arange(batch)).copy()
    imu, z, valid = [], [], []
    for _ in range(n_steps):
        buf = world.sense()
        imu.append(buf.imu.copy())
        z.append(buf.z.copy())
        valid.append(buf.valid.copy())
    P0 = cekf.initial_covariance(batch, 1, spec.filter.init_pos_sigma, spec.filter.init_vel_sigma)
    valid_arr = np.array(valid)
    return Recording(x0, P0, np.array(imu), np.array(z), valid_arr, np.ones(valid_arr.shape), world)


def _best_of(fn: Callable[[], None], repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def time_filterpy(rec: Recording, n_steps: int) -> float | None:
    """Seconds for FilterPy to filter the first episode for ``n_steps`` (None if not installed)."""
    try:
        from filterpy.kalman import ExtendedKalmanFilter
    except ImportError:
        return None
    spec = rec.world.spec
    anchors = rec.world.anchors
    dt = spec.dt
    G = np.vstack([0.5 * dt * dt * np.eye(3), dt * np.eye(3)])

    def hx(x):
        return np.linalg.norm(x[:3] - anchors, axis=1)

    def jac(x):
        H = np.zeros((len(anchors), 6))
        H[:, :3] = (x[:3] - anchors) / hx(x)[:, None]
        return H

    def run() -> None:
        ekf = ExtendedKalmanFilter(dim_x=6, dim_z=len(anchors), dim_u=3)
        ekf.x, ekf.P = rec.x0[0, 0].copy(), rec.P0[0, 0].copy()
        ekf.F = np.block([[np.eye(3), dt * np.eye(3)], [np.zeros((3, 3)), np.eye(3)]])
        ekf.B, ekf.Q, ekf.R = G, spec.sensors.imu_sigma**2 * G @ G.T, np.diag(rec.world.layout.r0[0])
        for k in range(n_steps):
            ekf.predict(u=rec.imu[k, 0, 0])
            ekf.update(rec.z[k, 0, 0, :, 0], jac, hx)

    return _best_of(run, 2)


def time_reference(rec: Recording, n_steps: int) -> float:
    """Seconds for the numpy reference to filter the first episode for ``n_steps``."""
    w, spec = rec.world, rec.world.spec
    sl = slice(0, n_steps)

    def run() -> None:
        run_reference(rec.x0[:1], rec.P0[:1], rec.imu[sl, :1], rec.z[sl, :1], rec.valid[sl, :1],
                      rec.alpha[sl, :1], w.layout.kind, w.layout.target, w.layout.r0, w.anchors, w.landmarks,
                      spec.dt, spec.sensors.imu_sigma, spec.filter.alpha_th, spec.filter.alpha_min)

    return _best_of(run, 2)


def time_kernel(rec: Recording, batch: int) -> float:
    """Seconds for the fused kernel to filter ``batch`` episodes over the whole recording."""
    w, spec = rec.world, rec.world.spec
    est = np.empty((rec.z.shape[0], batch, 1, 3))
    args = (rec.imu[:, :batch], rec.z[:, :batch], rec.valid[:, :batch], rec.alpha[:, :batch],
            w.layout.kind, w.layout.target, w.layout.r0, w.anchors, w.landmarks, spec.dt,
            spec.sensors.imu_sigma, spec.filter.alpha_th, spec.filter.alpha_min)
    args = tuple(np.ascontiguousarray(a) if isinstance(a, np.ndarray) else a for a in args)

    def run() -> None:
        x, P = rec.x0[:batch].copy(), rec.P0[:batch].copy()
        cekf.cekf_run(x, P, *args, est)

    # small batches run on the calling thread, as the core runs them (envs.core.SERIAL_BELOW)
    threads = numba.get_num_threads()
    numba.set_num_threads(1 if batch < SERIAL_BELOW else threads)
    try:
        run()  # compile / warm caches
        return _best_of(run, 3)
    finally:
        numba.set_num_threads(threads)


def machine_info() -> dict:
    """The machine the figures were measured on."""
    return {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
            "cpu_count": os.cpu_count(), "python": platform.python_version(), "numpy": np.__version__,
            "numba": numba.__version__, "numba_threads": numba.get_num_threads()}


def measure(quick: bool = False) -> list[dict]:
    """Measure every row; ``quick`` shortens the runs (for smoke tests)."""
    n_steps = 40 if quick else 400
    batches = QUICK_BATCHES if quick else BATCHES
    rec = record(max(batches), n_steps if max(batches) <= 1024 else 100)
    t_steps = rec.z.shape[0]
    rows: list[dict] = []
    n_ref = min(t_steps, 100)
    fp = time_filterpy(rec, n_ref)
    if fp is not None:
        rows.append({"impl": "filterpy", "B": 1, "uav_steps_per_s": n_ref / fp, "env_steps_per_s": n_ref / fp})
    ref = time_reference(rec, n_ref)
    rows.append({"impl": "reference", "B": 1, "uav_steps_per_s": n_ref / ref, "env_steps_per_s": n_ref / ref})
    for b in batches:
        sec = time_kernel(rec, b)
        rows.append({"impl": "kernel", "B": b, "uav_steps_per_s": b * t_steps / sec,
                     "env_steps_per_s": b * t_steps / sec})
    for target in EXTRA_ROWS:
        module, func = target.split(":")
        try:
            fn = getattr(importlib.import_module(module), func)
        except (ImportError, AttributeError):
            continue
        rows.extend(fn(quick=quick))
    return rows


def print_table(rows: list[dict]) -> None:
    """Print the rows with their ratio to FilterPy (UAV-steps/s)."""
    from rich.console import Console
    from rich.table import Table

    base = next((r["uav_steps_per_s"] for r in rows if r["impl"] == "filterpy"), None)
    table = Table(title="swarmloc speed (one run, identical inputs)")
    for col in ("impl", "B", "UAV-steps/s", "env-steps/s", "× FilterPy"):
        table.add_column(col, justify="right")
    for r in rows:
        uav = r.get("uav_steps_per_s")
        ratio = f"{uav / base:,.0f}×" if base and uav else "—"
        table.add_row(r["impl"], str(r["B"]), f"{uav:,.0f}" if uav else "—", f"{r['env_steps_per_s']:,.0f}", ratio)
    Console().print(table)


def run(json_path: Path | None = None, quick: bool = False) -> dict:
    """Measure, print the table, optionally write JSON ``{"rows": [...], "machine": {...}}``."""
    rows = measure(quick=quick)
    report = {"rows": rows, "machine": machine_info()}
    print_table(rows)
    if json_path is not None:
        write_text_atomic(json_path, json.dumps(report, indent=2))
    return report
