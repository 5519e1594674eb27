"""MDS-MAP vs nonlinear least squares swarm initialization (dtvirm Table 1).

dtvirm §4.1: 12 nodes, 0.5 m ranging error, 500 Monte Carlo runs; MDS-MAP 0.19 m /
25.8 ms against a GTSAM range-residual optimization 0.34 m / 152.6 ms (i9-13900HX). The
paper does not state the layout, the move or how the optimizer was started, so we state
ours (``make_scenario``): nodes uniform in a ``area`` × ``area`` m square at altitudes
uniform in [0, ``altitude_spread``] m, node 0 the origin, node 0 makes one horizontal move
of ``step`` m in a random heading (known exactly, as VIO + compass are taken to be), every
range measured once per epoch with i.i.d. N(0, noise²) error, altitudes known exactly,
the mirror resolved by the stated ``side`` convention. MDS-MAP runs in both layout
variants (Algorithm 2 and joint); NLS starts from a random layout (``nls_init`` default,
seed = trial index); a last row refines MDS-MAP with NLS.

Error = mean over nodes 1..N−1 of ‖x̂ − x‖ (node 0 is the origin by definition), then
mean over trials. Time = wall-clock per single-problem call (B = 1), as a per-swarm
initializer runs; the batched MDS-MAP time per problem is reported too.

Run by ``swarmloc reproduce dtvirm`` (its Table 1).
"""

from __future__ import annotations

import platform
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from swarmloc.agents.estimators.init import mdsmap_init, nls_init

PAPER_TABLE1 = {
    "nls": {"mean_error_m": 0.34, "var_error_m2": 0.045, "ci95_m": (0.32, 0.36), "mean_ms": 152.6},
    "mdsmap": {"mean_error_m": 0.19, "var_error_m2": 0.012, "ci95_m": (0.18, 0.20), "mean_ms": 25.8},
}


def make_scenario(
    rng: np.random.Generator,
    trials: int,
    n_nodes: int,
    noise: float,
    *,
    area: float = 20.0,
    altitude_spread: float = 2.0,
    step: float = 5.0,
) -> dict[str, np.ndarray]:
    """Random swarms and their noisy ranges for the initializer comparison.

    Args:
        rng: random generator (all draws come from it).
        trials: number of swarms T.
        n_nodes: UAVs per swarm N ≥ 3.
        noise: range error standard deviation [m] ≥ 0.
        area: side of the square the nodes are drawn in [m].
        altitude_spread: altitudes uniform in [0, altitude_spread] [m].
        step: length of node 0's horizontal move [m].

    Returns:
        dict with ``x`` (T, N, 3) truth (node 0 at the origin), ``D_pre`` (T, N, N),
        ``D_post`` (T, 1, N, N), ``dX`` (T, 1, 3), ``z`` (T, N), ``side`` (T,).
    """
    if n_nodes < 3 or trials < 1 or noise < 0:
        raise ValueError(f"need n_nodes >= 3, trials >= 1, noise >= 0; got {n_nodes}, {trials}, {noise}")
    T, N = trials, n_nodes
    p = np.concatenate(
        [rng.uniform(0.0, area, (T, N, 2)), rng.uniform(0.0, altitude_spread, (T, N, 1))], axis=-1
    )
    x = p - p[:, :1]
    heading = rng.uniform(0.0, 2.0 * np.pi, T)
    dX = np.stack([step * np.cos(heading), step * np.sin(heading), np.zeros(T)], axis=-1)[:, None, :]
    iu = np.triu_indices(N, k=1)

    def ranges(pos: np.ndarray) -> np.ndarray:
        d = np.linalg.norm(pos[:, :, None] - pos[:, None, :], axis=-1)
        e = np.zeros_like(d)
        e[:, iu[0], iu[1]] = rng.normal(0.0, noise, (T, iu[0].size))
        e = e + e.swapaxes(1, 2)  # one measurement per pair, reported both ways
        return np.abs(d + e)

    D_pre = ranges(x)
    moved = x.copy()
    moved[:, 0] += dX[:, 0]
    D_post = ranges(moved)[:, None]
    a = dX[:, 0, :2]
    side = np.sign(a[:, 0] * x[:, 1, 1] - a[:, 1] * x[:, 1, 0]).astype(np.int64)
    side[side == 0] = 1
    return {"x": x, "D_pre": D_pre, "D_post": D_post, "dX": dX, "z": p[:, :, 2], "side": side}


def _stats(err: np.ndarray, ms: np.ndarray) -> dict[str, Any]:
    n = err.size
    half = 1.96 * err.std(ddof=1) / np.sqrt(n) if n > 1 else float("nan")
    return {
        "mean_error_m": float(err.mean()),
        "var_error_m2": float(err.var(ddof=1)) if n > 1 else float("nan"),
        "ci95_m": (float(err.mean() - half), float(err.mean() + half)),
        "median_error_m": float(np.median(err)),
        "p95_error_m": float(np.quantile(err, 0.95)),
        "mean_ms": float(ms.mean()),
    }


def _run(solve: Callable[[slice], np.ndarray], x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Solve every trial as its own B = 1 call; returns per-trial error and ms."""
    T = x.shape[0]
    err = np.empty(T)
    ms = np.empty(T)
    for t in range(T):
        sl = slice(t, t + 1)
        t0 = time.perf_counter()
        xh = solve(sl)
        ms[t] = (time.perf_counter() - t0) * 1e3
        err[t] = np.linalg.norm(xh[0, 1:] - x[t, 1:], axis=-1).mean()
    return err, ms


def compare_mdsmap_nls(
    n_nodes: int = 12,
    noise: float = 0.5,
    trials: int = 500,
    seed: int = 0,
    *,
    area: float = 20.0,
    altitude_spread: float = 2.0,
    step: float = 5.0,
) -> dict[str, Any]:
    """Mean error and time of MDS-MAP, NLS and MDS-MAP + NLS refinement (dtvirm Table 1).

    Args:
        n_nodes: UAVs per swarm.
        noise: range error standard deviation [m].
        trials: Monte Carlo trials.
        seed: seed of the scenario generator.
        area: side of the deployment square [m].
        altitude_spread: altitude range [m].
        step: node 0's move [m].

    Returns:
        dict with per-method stats under ``mdsmap`` (Algorithm 2), ``mdsmap_joint``,
        ``nls``, ``mdsmap_nls`` (mean / var /
        95 % CI / median / p95 error [m], mean ms per call), ``mdsmap_batched_ms`` (per
        problem, all trials in one call), the NLS/MDS-MAP ratios, ``paper`` (Table 1) and
        ``scenario``.
    """
    sc = make_scenario(
        np.random.default_rng(seed), trials, n_nodes, noise, area=area, altitude_spread=altitude_spread, step=step
    )
    args = (sc["D_pre"], sc["D_post"], sc["dX"], sc["z"])
    side = sc["side"]

    def mds(sl: slice) -> np.ndarray:
        return mdsmap_init(*(a[sl] for a in args), side=side[sl])

    def joint(sl: slice) -> np.ndarray:
        return mdsmap_init(*(a[sl] for a in args), side=side[sl], variant="joint")

    def nls(sl: slice) -> np.ndarray:
        return nls_init(*(a[sl] for a in args), side=side[sl], seed=sl.start)

    def refine(sl: slice) -> np.ndarray:
        x0 = mdsmap_init(*(a[sl] for a in args), side=side[sl])[..., :2]
        return nls_init(*(a[sl] for a in args), side=side[sl], x0=x0)

    methods = (("mdsmap", mds), ("mdsmap_joint", joint), ("nls", nls), ("mdsmap_nls", refine))
    for _, f in methods:  # warm-up: first-call imports and caches
        f(slice(0, 1))
    out: dict[str, Any] = {}
    for name, f in methods:
        out[name] = _stats(*_run(f, sc["x"]))
    t0 = time.perf_counter()
    mdsmap_init(*args, side=side)
    out["mdsmap_batched_ms"] = (time.perf_counter() - t0) * 1e3 / trials
    out["error_ratio_nls_over_mdsmap"] = out["nls"]["mean_error_m"] / out["mdsmap"]["mean_error_m"]
    out["time_ratio_nls_over_mdsmap"] = out["nls"]["mean_ms"] / out["mdsmap"]["mean_ms"]
    out["paper"] = PAPER_TABLE1
    out["scenario"] = {
        "n_nodes": n_nodes, "noise_m": noise, "trials": trials, "seed": seed, "area_m": area,
        "altitude_spread_m": altitude_spread, "step_m": step, "machine": platform.processor() or platform.machine(),
    }
    return out


def format_table(res: dict[str, Any]) -> str:
    """The comparison as a small text table, ours beside dtvirm Table 1."""
    p = res["paper"]
    rows = [
        ("GTSAM / NLS (scipy LM, random start)", res["nls"], p["nls"]),
        ("MDS-MAP (Algorithm 2)", res["mdsmap"], p["mdsmap"]),
        ("MDS-MAP (joint layout)", res["mdsmap_joint"], None),
        ("MDS-MAP + NLS refine", res["mdsmap_nls"], None),
    ]
    lines = [
        f"{'method':38s} {'err ours':>9s} {'paper':>6s} {'CI95 ours':>15s} {'median':>7s} {'ms ours':>8s} {'paper':>6s}",
    ]
    for name, r, q in rows:
        ci = f"[{r['ci95_m'][0]:.2f}, {r['ci95_m'][1]:.2f}]"
        pe = f"{q['mean_error_m']:.2f}" if q else "—"
        pt = f"{q['mean_ms']:.1f}" if q else "—"
        lines.append(
            f"{name:38s} {r['mean_error_m']:9.3f} {pe:>6s} {ci:>15s} {r['median_error_m']:7.3f} "
            f"{r['mean_ms']:8.3f} {pt:>6s}"
        )
    pr = p["nls"]["mean_error_m"] / p["mdsmap"]["mean_error_m"]
    pt = p["nls"]["mean_ms"] / p["mdsmap"]["mean_ms"]
    lines.append(
        f"ratio NLS / MDS-MAP: error {res['error_ratio_nls_over_mdsmap']:.2f} (paper {pr:.2f}), "
        f"time {res['time_ratio_nls_over_mdsmap']:.1f}x (paper {pt:.1f}x)"
    )
    lines.append(f"MDS-MAP batched over all trials: {res['mdsmap_batched_ms']:.4f} ms per swarm")
    s = res["scenario"]
    lines.append(
        f"scenario: N={s['n_nodes']}, σ={s['noise_m']} m, {s['trials']} trials, seed {s['seed']}, "
        f"{s['area_m']:g} m square, altitudes 0–{s['altitude_spread_m']:g} m, step {s['step_m']:g} m"
    )
    return "\n".join(lines)
