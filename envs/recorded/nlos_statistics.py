"""NLOS statistics of range residuals on filter steps, one definition for real logs and simulation.

A residual series is ``(T, C)`` on the step grid (step k at k·dt) with a ``(T, C)`` validity
mask: a recorded flight's ``Recording.residual``/``valid`` (measured − true range or range
difference), or a simulated bias plus white noise observed on the same mask. The statistics
(``residual_statistics``) are defined here once and computed the same way on both:

* **Excess.** Each channel's residual minus its own median over its valid samples: a
  constant per-channel offset (antenna delay left after calibration, the TDOA pairs'
  persistent offsets) is not NLOS. ``channel_offsets`` keeps the medians for the report.
* **Biased.** A sample is biased when its excess exceeds ``k·σ_LOS`` in magnitude (both
  signs: on a TDOA channel a blocked first anchor shortens the range difference);
  ``σ_LOS`` is the line-of-sight residual std measured elsewhere (``robust_sigma`` on the
  line-of-sight logs).
* **Magnitude.** Quantiles of |excess| over the biased samples.
* **Time correlation.** The mean duration of biased runs (consecutive biased samples of a
  channel, gaps without a sample neither break nor extend a run; a run of n samples lasts
  n times the channel's mean sample interval T·dt / n_valid), and the autocorrelation of the
  excess at a lag in seconds (samples held until the next one, pairs of distinct samples that
  lag apart, channels pooled).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

MAD_TO_SIGMA = 1.4826
#: quantiles of the biased samples' |excess| that the statistics report
MAGNITUDE_QUANTILES = (0.25, 0.5, 0.9)
#: lags [s] of the excess autocorrelation that the statistics report
ACF_LAGS_S = (0.2, 1.0, 3.0)


@dataclass(frozen=True)
class ResidualStatistics:
    """NLOS statistics of a set of residual series (module docstring has the definitions).

    Attributes:
        n_samples: valid samples.
        threshold: |excess| above this is biased [m] (k·σ_LOS).
        share_biased: fraction of the valid samples that are biased.
        magnitude: |excess| of the biased samples at ``MAGNITUDE_QUANTILES`` [m] (NaN if none).
        mean_run_s: mean duration of a biased run [s] (NaN if none).
        acf: autocorrelation of the excess at ``ACF_LAGS_S``.
    """

    n_samples: int
    threshold: float
    share_biased: float
    magnitude: tuple[float, ...]
    mean_run_s: float
    acf: tuple[float, ...]

    def as_dict(self) -> dict:
        return asdict(self)


def _check(residual: np.ndarray, valid: np.ndarray) -> None:
    if residual.ndim != 2 or residual.shape != valid.shape:
        raise ValueError(f"residual {residual.shape} and valid {valid.shape} must both be (T, C)")


def channel_offsets(residual: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """``(C,)`` median residual of each channel over its valid samples (NaN for a channel without any)."""
    _check(residual, valid)
    return np.array([np.median(residual[valid[:, c], c]) if valid[:, c].any() else np.nan
                     for c in range(residual.shape[1])])


def excess(residual: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """``(T, C)`` residual minus its channel's median (``channel_offsets``); 0 where not valid."""
    offsets = np.nan_to_num(channel_offsets(residual, valid))
    return np.where(valid, residual - offsets, 0.0)


def robust_sigma(residual: np.ndarray, valid: np.ndarray) -> float:
    """The median over channels of each channel's robust std (1.4826·MAD about its median) [m]."""
    e = excess(residual, valid)
    spreads = [MAD_TO_SIGMA * np.median(np.abs(e[valid[:, c], c])) for c in range(e.shape[1]) if valid[:, c].any()]
    if not spreads:
        raise ValueError("no valid sample")
    return float(np.median(spreads))


def run_lengths(flags: np.ndarray) -> np.ndarray:
    """Lengths of the runs of True in a 1-D bool array."""
    padded = np.concatenate([[False], flags, [False]]).astype(np.int8)
    edges = np.diff(padded)
    return np.nonzero(edges == -1)[0] - np.nonzero(edges == 1)[0]


def biased_run_durations(biased: np.ndarray, valid: np.ndarray, dt: float) -> np.ndarray:
    """Durations [s] of the biased runs of every channel (samples of a channel in order, gaps skipped)."""
    _check(biased, valid)
    out = []
    for c in range(biased.shape[1]):
        n_valid = int(valid[:, c].sum())
        if n_valid:
            interval = biased.shape[0] * dt / n_valid
            out.append(interval * run_lengths(biased[valid[:, c], c]))
    return np.concatenate(out) if out else np.zeros(0)


def autocorrelation(x: np.ndarray, valid: np.ndarray, lag: int) -> float:
    """Σ x_k x_{k+lag} / √(Σ x_k² Σ x_{k+lag}²) over steps k, channels pooled, on held samples.

    A channel's sample stands from its step until the next one (sample and hold), so that
    channels sampled slower than the step, or not on the step grid (TWR round-robin), still
    have pairs at every lag; a pair counts when both steps hold a sample and the two samples
    are distinct. ``x`` is centred per channel on the mean over its pairs first (NaN without a pair).
    """
    _check(x, valid)
    n_t = x.shape[0]
    if lag <= 0 or lag >= n_t:
        raise ValueError(f"lag={lag} must be in [1, {n_t - 1}]")
    # the step of the sample each step holds (−1 before a channel's first sample)
    source = np.maximum.accumulate(np.where(valid, np.arange(n_t)[:, None], -1), axis=0)
    held = np.take_along_axis(x, np.maximum(source, 0), axis=0)
    both = (source[: n_t - lag] >= 0) & (source[: n_t - lag] != source[lag:])
    a, b = held[: n_t - lag], held[lag:]
    count = both.sum(axis=0)
    if count.sum() == 0:
        return float("nan")
    mean_a = (a * both).sum(axis=0) / np.maximum(count, 1)
    mean_b = (b * both).sum(axis=0) / np.maximum(count, 1)
    da, db = (a - mean_a) * both, (b - mean_b) * both
    return float((da * db).sum() / np.sqrt((da * da).sum() * (db * db).sum()))


def residual_statistics(series: list[tuple[np.ndarray, np.ndarray]], sigma_los: float, dt: float,
                        k: float = 3.0) -> ResidualStatistics:
    """The NLOS statistics of residual series pooled (module docstring).

    Args:
        series: ``(residual, valid)`` pairs, each ``(T, C)`` on the step grid (flights may
            differ in T and C).
        sigma_los: line-of-sight residual std [m]; a sample is biased above ``k·sigma_los``.
        dt: step length [s].
        k: threshold in σ_LOS.

    Returns:
        The pooled ``ResidualStatistics``.
    """
    if sigma_los <= 0.0 or k <= 0.0 or dt <= 0.0:
        raise ValueError(f"sigma_los={sigma_los}, k={k} and dt={dt} must be > 0")
    threshold = k * sigma_los
    n, n_biased, magnitudes, runs = 0, 0, [], []
    acf_num = {lag: [] for lag in ACF_LAGS_S}
    for residual, valid in series:
        e = excess(residual, valid)
        biased = valid & (np.abs(e) > threshold)
        n += int(valid.sum())
        n_biased += int(biased.sum())
        magnitudes.append(np.abs(e[biased]))
        runs.append(biased_run_durations(biased, valid, dt))
        for lag in ACF_LAGS_S:
            acf_num[lag].append((autocorrelation(e, valid, int(round(lag / dt))), int(valid.sum())))
    if n == 0:
        raise ValueError("no valid sample")
    mags, durations = np.concatenate(magnitudes), np.concatenate(runs)
    # the series' autocorrelations pooled by their sample counts
    acf = tuple(float(np.average([r for r, _ in acf_num[lag]], weights=[w for _, w in acf_num[lag]]))
                for lag in ACF_LAGS_S)
    return ResidualStatistics(
        n_samples=n, threshold=threshold, share_biased=n_biased / n,
        magnitude=tuple(float(np.quantile(mags, q)) if mags.size else float("nan") for q in MAGNITUDE_QUANTILES),
        mean_run_s=float(durations.mean()) if durations.size else float("nan"), acf=acf)
