"""``swarmloc reproduce nlos-fit``: the Gauss–Markov NLOS process fitted to the UTIL residual statistics.

Two data sets, each with its line-of-sight reference (``DATASETS``):

* **TWR** — the obstacle flight ``twr-obs-log1`` with the ``log00`` calibration
  (``UTILFlight-v0``'s recording: ranges minus the mocap distance). There is no line-of-sight
  flight of the tag, and ``log00`` is an almost static hover whose residual spread (reported)
  has no motion in it, so σ_LOS is the flight's own median robust std over the eight anchors
  (1.4826·MAD ignores a minority of biased samples).
* **TDOA** — the four UTIL TDOA flights among obstacles, pooled; σ_LOS per mode (TDOA2 /
  TDOA3) is the median robust std of the line-of-sight flights of that mode.

The statistics (``envs.recorded.nlos_statistics``: share of samples with |excess| > 3·σ_LOS,
quantiles of their magnitude, mean biased-run duration, excess autocorrelation at 0.2 / 1 /
3 s) are computed on the real residuals and on the simulated process observed exactly as
they are: per real channel, a few simulated channels (``replicates_for``) carry the Gauss–Markov bias of
``envs.world.nlos_reference`` (the world kernel's process) plus white N(0, σ_LOS²) noise, on
the real channel's validity mask, and go through the same function.

The fit minimises the sum of squared log ratios simulated / real of the share, the three
magnitude quantiles and the mean run duration, plus the autocorrelation differences at the
three lags over 0.1, over log onset rate, mean duration, mean bias, bias σ and τ: the best
point of a coarse grid (``GRID``, and v1's ``INDOOR_NLOS``), refined with
``scipy.optimize.minimize(method="Nelder-Mead")``; the onset
is a ramp and the clip 5 m, as in ``INDOOR_NLOS``. The simulated draws are fixed (one
generator seed per evaluation: common random numbers), so the objective is deterministic and
the fit reproducible. The fitted values are frozen in ``envs.tasks.nlos_fit_values``;
``tests/test_nlos_fit.py`` recomputes both sides' statistics with them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from swarmloc.bench.reproduce.common import write_paper_report
from swarmloc.envs.recorded.nlos_statistics import (ACF_LAGS_S, MAD_TO_SIGMA, MAGNITUDE_QUANTILES,
                                                    ResidualStatistics, channel_offsets, residual_statistics,
                                                    robust_sigma)
from swarmloc.envs.tasks.catalogue import get_spec
from swarmloc.envs.tasks.nlos_fit_values import UTIL_NLOS_TDOA, UTIL_NLOS_TWR
from swarmloc.envs.tasks.v1 import INDOOR_NLOS
from swarmloc.envs.world.nlos_reference import GM_FIELDS, simulate_gm_nlos

#: a sample is biased above this many σ_LOS (the world's injected-fault label, ``INJECTED_FAULT_SIGMAS``)
K_SIGMA = 3.0
#: simulated samples per data set at least (``replicates_for``: whole copies of the real channels)
SIM_SAMPLES = 120_000
#: the generator seed of the simulated draws (common random numbers across the fit's evaluations)
SIM_SEED = 20210607
#: the parameters the fit moves (the onset stays a ramp and the clip at max_bias, as in ``INDOOR_NLOS``)
FITTED = ("onset_rate", "mean_duration", "mean_bias", "bias_sigma", "tau")
#: an autocorrelation difference of this size weighs as a factor e in the other statistics
ACF_SCALE = 0.1


@dataclass(frozen=True)
class Dataset:
    """A data set of the fit: its obstacle flights and, per flight, the line-of-sight reference tasks."""

    name: str
    flights: tuple[str, ...]
    los: dict[str, tuple[str, ...]]


DATASETS = (
    Dataset("twr", ("swarmloc/UTILFlight-v0",), {"swarmloc/UTILFlight-v0": ("swarmloc/UTILFlight-v0",)}),
    Dataset("tdoa",
            ("swarmloc/UTILC0426Tdoa2Wood-v1", "swarmloc/UTILC0426Tdoa2WoodCardPlasticMetal-v1",
             "swarmloc/UTILC0426Tdoa3WoodCardPlasticMetal-v1", "swarmloc/UTILC0607Tdoa2WoodPlasticMetal-v1"),
            {**{t: ("swarmloc/UTILC0425Tdoa2Los-v1", "swarmloc/UTILC0426Tdoa2NoLabel-v1")
                for t in ("swarmloc/UTILC0426Tdoa2Wood-v1", "swarmloc/UTILC0426Tdoa2WoodCardPlasticMetal-v1",
                          "swarmloc/UTILC0607Tdoa2WoodPlasticMetal-v1")},
             "swarmloc/UTILC0426Tdoa3WoodCardPlasticMetal-v1": ("swarmloc/UTILC0425Tdoa3Los-v1",
                                                                "swarmloc/UTILC0426Tdoa3NoObs-v1")}),
)
FROZEN = {"twr": UTIL_NLOS_TWR, "tdoa": UTIL_NLOS_TDOA}


@dataclass(frozen=True)
class Series:
    """One flight's residual series on its steps 1 … T and the σ_LOS it is judged against."""

    task: str
    residual: np.ndarray
    valid: np.ndarray
    sigma_los: float
    dt: float


def _recording(task: str, data_dir: str | Path | None) -> tuple[np.ndarray, np.ndarray, float]:
    from swarmloc.envs.recorded.flights import load_flight

    spec = get_spec(task)
    _, rec = load_flight(spec, data_dir)
    return rec.residual[1:], rec.valid[1:], float(spec.dt)


def load_dataset(dataset: Dataset, data_dir: str | Path | None = None) -> list[Series]:
    """The obstacle flights' residual series, each with the robust σ of its line-of-sight flights (pooled median).

    Raises:
        FileNotFoundError: the data set is not here (the message says where it comes from).
    """
    out = []
    for task in dataset.flights:
        residual, valid, dt = _recording(task, data_dir)
        sigmas = [robust_sigma(*_recording(los, data_dir)[:2]) for los in dataset.los[task]]
        out.append(Series(task, residual, valid, float(np.median(sigmas)), dt))
    return out


def log00_sigma(data_dir: str | Path | None = None) -> float:
    """Median over anchors of the robust residual std of the static TWR calibration log ``log00`` [m]."""
    from swarmloc.envs.recorded.util_flight import range_residuals, read_anchors, read_flight_log
    from swarmloc.envs.recorded.util_import import find_util_data

    folder = find_util_data(data_dir)
    log = read_flight_log(folder / "log00")
    resid, ids = range_residuals(log.uwb, log.mocap, read_anchors(folder)), log.uwb[:, 1].astype(int)
    spreads = [MAD_TO_SIGMA * np.median(np.abs(resid[ids == a] - np.median(resid[ids == a])))
               for a in np.unique(ids)]
    return float(np.median(spreads))


def real_statistics(series: list[Series]) -> ResidualStatistics:
    """The pooled statistics of the real residuals (each flight against its own σ_LOS)."""
    # one threshold per flight: the flights' excesses are scaled to a common σ_LOS of 1
    return residual_statistics([(s.residual / s.sigma_los, s.valid) for s in series], 1.0, series[0].dt, K_SIGMA)


def simulated_statistics(params: dict, series: list[Series], seed: int = SIM_SEED,
                         replicates: int | None = None) -> ResidualStatistics:
    """The same statistics of the simulated process: bias + N(0, σ_LOS²) on each real channel's mask.

    Args:
        params: ``GM_FIELDS`` values and ``onset`` (``"ramp"`` or ``"jump"``).
        series: the real flights (their masks, lengths, σ_LOS and dt; one dt for all).
        seed: generator seed of the draws.
        replicates: simulated channels per real channel (default: ``replicates_for(series)``).
    """
    dt = series[0].dt
    if any(s.dt != dt for s in series):
        raise ValueError(f"the flights' steps differ: {sorted({s.dt for s in series})}")
    r = replicates or replicates_for(series)
    rng = np.random.default_rng(seed)
    widths = [s.valid.shape[1] * r for s in series]
    # every flight's channels in one run of the process (the longest flight's steps; each reads its own)
    n_t = max(s.valid.shape[0] for s in series)
    bias = simulate_gm_nlos(params, params.get("onset", "ramp") == "ramp", dt, n_t, sum(widths), rng)
    noise = rng.standard_normal(bias.shape)
    sim, col = [], 0
    for s, w in zip(series, widths):
        t = s.valid.shape[0]
        # residual / σ_LOS = bias / σ_LOS + n
        sim.append((bias[:t, col:col + w] / s.sigma_los + noise[:t, col:col + w], np.tile(s.valid, (1, r))))
        col += w
    return residual_statistics(sim, 1.0, dt, K_SIGMA)


def replicates_for(series: list[Series]) -> int:
    """Simulated channels per real channel: enough for about ``SIM_SAMPLES`` simulated samples (at least 2)."""
    n = sum(int(s.valid.sum()) for s in series)
    return max(2, int(np.ceil(SIM_SAMPLES / n)))


def mismatch(sim: ResidualStatistics, real: ResidualStatistics) -> float:
    """The fit's objective: squared log ratios of share, magnitudes and run duration, plus ACF differences / 0.1."""
    ratios = [sim.share_biased / real.share_biased, sim.mean_run_s / real.mean_run_s,
              *(a / b for a, b in zip(sim.magnitude, real.magnitude))]
    if not all(np.isfinite(r) and r > 0 for r in ratios):
        return 1e6
    acf = [(a - b) / ACF_SCALE for a, b in zip(sim.acf, real.acf)]
    return float(sum(np.log(r) ** 2 for r in ratios) + sum(d * d for d in acf))


#: the coarse grid the fit starts from: onset rate [1/s], mean duration [s], mean bias [m] (bias σ = mean
#: bias), τ [s]; Nelder–Mead then refines the best point (the objective has several local minima)
GRID = {"onset_rate": (0.03, 0.1, 0.3, 1.0, 3.0), "mean_duration": (0.3, 1.0, 3.0, 8.0),
        "mean_bias": (0.2, 0.5, 1.0, 2.0), "tau": (0.3, 2.0)}


def fit_dataset(series: list[Series], real: ResidualStatistics, start: dict,
                max_evaluations: int = 300) -> tuple[dict, float, int]:
    """The coarse ``GRID``, then Nelder–Mead over the log of the ``FITTED`` parameters from its best point.

    Args:
        series: the real flights.
        real: their statistics.
        start: the parameters the fit does not move (``max_bias``, ``onset``) and the grid's
            competitor (v1's values enter the grid search as one more point).
        max_evaluations: Nelder–Mead's evaluations (the grid's come on top).

    Returns:
        The fitted parameters (``start`` with ``FITTED`` replaced, rounded to 3 significant
        digits), the objective at them and the number of evaluations.
    """
    from itertools import product

    from scipy.optimize import minimize

    def params_of(x: np.ndarray) -> dict:
        return {**start, **{k: float(np.exp(v)) for k, v in zip(FITTED, x)}}

    def objective(x: np.ndarray) -> float:
        return mismatch(simulated_statistics(params_of(x), series), real)

    candidates = [np.log([start[k] for k in FITTED])]
    for rate, duration, bias, tau in product(*GRID.values()):
        candidates.append(np.log([rate, duration, bias, bias, tau]))
    scores = [objective(x) for x in candidates]
    x0 = candidates[int(np.argmin(scores))]
    result = minimize(objective, x0, method="Nelder-Mead", options={"maxfev": max_evaluations, "xatol": 0.02,
                                                                      "fatol": 1e-3})
    fitted = {k: float(f"{v:.3g}") if k in FITTED else v for k, v in params_of(result.x).items()}
    return fitted, mismatch(simulated_statistics(fitted, series), real), len(candidates) + int(result.nfev)


def _stat_row(label: str, s: ResidualStatistics) -> str:
    mags = " / ".join(f"{m:.2f}" for m in s.magnitude)
    acf = " / ".join(f"{a:.2f}" for a in s.acf)
    return (f"| {label} | {s.n_samples} | {100 * s.share_biased:.1f} % | {mags} | {s.mean_run_s:.2f} | {acf} |")


def _params_row(label: str, p: dict) -> str:
    return f"| {label} | " + " | ".join(f"{p[k]:g}" for k in GM_FIELDS) + f" | {p['onset']} |"


def _channel_rows(series: list[Series]) -> list[str]:
    """Per flight and channel: its constant offset and share of biased samples (is the bias a few channels' own?)."""
    rows = ["| flight | σ_LOS (m) | channel offsets, median (m) | offset spread (m) | biased share per channel "
            "(min / median / max) |", "|---|---|---|---|---|"]
    for s in series:
        offsets = channel_offsets(s.residual, s.valid)
        shares = []
        for c in range(s.valid.shape[1]):
            v = s.valid[:, c]
            if v.any():
                e = s.residual[v, c] - offsets[c]
                shares.append(np.mean(np.abs(e) > K_SIGMA * s.sigma_los))
        rows.append(f"| {s.task.removeprefix('swarmloc/')} | {s.sigma_los:.3f} | {np.nanmedian(offsets):+.3f} | "
                    f"{np.nanstd(offsets):.3f} | {100 * min(shares):.1f} / {100 * np.median(shares):.1f} / "
                    f"{100 * max(shares):.1f} % |")
    return rows


def reproduce_nlos_fit(out: Path, data_dir: str | Path | None = None, max_evaluations: int = 300) -> Path:
    """Measure the UTIL residual statistics, fit the Gauss–Markov NLOS process to them, write the report.

    Args:
        out: Markdown file, or a folder for ``<out>/nlos-fit.md``; the numbers go beside it as JSON.
        data_dir: the folder that holds ``util-twr/`` and ``util-tdoa/`` (default: ``$SWARMLOC_DATA``,
            else ``../shared/data`` beside the checkout).
        max_evaluations: objective evaluations per data set (each simulates every flight once).

    Raises:
        FileNotFoundError: the UTIL data is not here.
    """
    if max_evaluations < 1:
        raise ValueError(f"max_evaluations={max_evaluations} must be >= 1")
    start = {**{k: INDOOR_NLOS[k] for k in GM_FIELDS}, "onset": INDOOR_NLOS["onset"]}
    raw: dict = {"k_sigma": K_SIGMA, "sim_samples": SIM_SAMPLES, "sim_seed": SIM_SEED, "magnitude_quantiles":
                 list(MAGNITUDE_QUANTILES), "acf_lags_s": list(ACF_LAGS_S), "datasets": {}}
    header = ["| process | valid samples | biased (>3σ_LOS) | |excess| of biased, q25 / q50 / q90 (σ_LOS) | "
              "mean biased run (s) | excess ACF at 0.2 / 1 / 3 s |", "|---|---|---|---|---|---|"]
    lines = ["# The Gauss–Markov NLOS process fitted to the UTIL residuals", "",
             "What `swarmloc reproduce nlos-fit` measures on the real logs and fits (definitions in "
             "`swarmloc.envs.recorded.nlos_statistics`, the fit in `swarmloc.bench.reproduce.nlos_fit`). "
             "Magnitudes are in units of each flight's σ_LOS. The fitted values are frozen in "
             "`swarmloc.envs.tasks.nlos_fit_values` (a test recomputes this table's real and fitted rows).", ""]
    params_header = ["| parameters | " + " | ".join(GM_FIELDS) + " | onset |",
                     "|---|" + "---|" * (len(GM_FIELDS) + 1)]
    for dataset in DATASETS:
        series = load_dataset(dataset, data_dir)
        real = real_statistics(series)
        fitted, objective, n_eval = fit_dataset(series, real, start, max_evaluations)
        frozen = FROZEN[dataset.name]
        rows = {"real (obstacle flights)": real, "simulated, v1 INDOOR_NLOS": simulated_statistics(start, series),
                "simulated, fitted now": simulated_statistics(fitted, series),
                "simulated, frozen UTIL_NLOS": simulated_statistics(frozen, series)}
        los_series = [Series(t, *_recording(t, data_dir)[:2], s.sigma_los, s.dt)
                      for s in series for t in dataset.los[s.task] if t != s.task]
        if los_series:
            rows = {"real (line-of-sight flights)": real_statistics(los_series), **rows}
        note = []
        if dataset.name == "twr":
            note = [f"σ_LOS {series[0].sigma_los:.3f} m is the flight's median robust std over the anchors; the "
                    f"static log00 hover's is {log00_sigma(data_dir):.3f} m (no motion: too small a reference "
                    "for a flight).", ""]
        lines += [f"## {dataset.name.upper()}: {', '.join(s.task.removeprefix('swarmloc/') for s in series)}", "",
                  *note, *header, *(_stat_row(k, v) for k, v in rows.items()), "",
                  *params_header, _params_row("v1 INDOOR_NLOS", start), _params_row("fitted now", fitted),
                  _params_row("frozen", frozen), "",
                  f"Grid ({len(GRID['onset_rate']) * len(GRID['mean_duration']) * len(GRID['mean_bias']) * len(GRID['tau']) + 1} "
                  f"points) + Nelder–Mead: {n_eval} evaluations in all, objective {objective:.3f}.", "",
                  "Constant offsets and how the bias spreads over the channels (a Gauss–Markov process with one "
                  "parameter set biases every channel alike):", "", *_channel_rows(series), ""]
        raw["datasets"][dataset.name] = {
            "flights": {s.task: {"sigma_los": s.sigma_los} for s in series},
            "statistics": {k: v.as_dict() for k, v in rows.items()}, "fitted": fitted, "frozen": dict(frozen),
            "start": start, "objective": objective, "evaluations": n_eval}
    lines += ["## Reading", "",
              "* Is it a Gauss–Markov process? In its time structure, roughly: the fitted process matches the "
              "share, the magnitudes within the test's tolerances and the autocorrelation at 0.2 / 1 / 3 s. But the "
              "episodes it needs are about 1 s long with τ under 1 s, an order of magnitude shorter than v1's "
              "hand-chosen INDOOR_NLOS, and the TWR fit has a mean bias near 0: a bias switched on about half of "
              "the time with a half-normal spread, i.e. a heavy tail rather than discrete obstruction episodes.",
              "* Where it is not: the bias concentrates on a few channels (the per-channel table: a median channel "
              "is biased 5–12 % of the time, one channel per flight 30–60 %: TWR anchor 6's slow drift, the pairs "
              "behind the metal box), which one parameter set for every channel cannot produce; and each channel "
              "has a constant offset (spread 0.07–0.18 m) that the statistics remove by centring on the channel "
              "median and that is not NLOS.",
              "* The line-of-sight TDOA flights are biased by the same definition too (their row): obstacles add a "
              "few points of share and, above all, the large magnitudes (q90).", ""]
    return write_paper_report(out, "nlos-fit", "\n".join(lines), raw)
