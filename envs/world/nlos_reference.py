"""The world kernel's Gauss–Markov NLOS process, in readable NumPy (no numba).

``gm_nlos_bias`` is the per-channel update of ``sim_kernel.sense_episodes`` written over
arrays of channels, fed with the draws it would use; ``tests/test_nlos_fit.py`` holds it equal
to the kernel on the kernel's own counter-based draws. ``simulate_gm_nlos`` runs it on draws
from a NumPy generator (the same law, other numbers): what ``swarmloc reproduce nlos-fit``
simulates to match the UTIL residual statistics, many parameter sets in seconds.

Per channel and step (``NlosGaussMarkov``'s docstring):

* outside an episode the bias is 0; with probability p_on = 1 − exp(−onset_rate·dt) an
  episode starts, lasting max(1, −mean_duration·ln u / dt) steps; its first bias is 0
  (``onset="ramp"``) or μ + σ·n clipped to [0, max_bias] (``"jump"``);
* inside, b ← μ + φ(b − μ) + σ√(1 − φ²)·n, φ = exp(−dt/τ), clipped to [0, max_bias], and one
  step of the episode is spent; the range carries b while steps are left.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

#: the Gauss–Markov parameters a fit sets (``specs.NlosGaussMarkov`` fields), in this order
GM_FIELDS = ("onset_rate", "mean_duration", "mean_bias", "bias_sigma", "tau", "max_bias")


def gm_nlos_bias(params: Mapping[str, float], ramp: bool, dt: float, onset_u: np.ndarray, duration_u: np.ndarray,
                 normals: np.ndarray) -> np.ndarray:
    """The range bias of C channels over T steps, from their draws.

    Args:
        params: ``GM_FIELDS`` values (onset rate [1/s], mean duration [s], mean bias [m],
            bias σ [m], τ [s], max bias [m]).
        ramp: an episode starts at zero bias (``onset="ramp"``), else at a stationary draw.
        dt: step length [s].
        onset_u, duration_u: ``(T, C)`` uniforms in (0, 1): the onset test and the episode length.
        normals: ``(T, C)`` standard normals: the process noise (and a jump onset's bias).

    Returns:
        ``(T, C)`` the bias each step's range carries [m] (0 outside episodes).
    """
    rate, duration, mu, sigma, tau, max_bias = (float(params[k]) for k in GM_FIELDS)
    p_on = 1.0 - np.exp(-rate * dt)
    # AR(1) coefficient and innovation scale: b ← μ + φ(b − μ) + σ√(1−φ²)·n
    phi = np.exp(-dt / tau)
    step_sigma = sigma * np.sqrt(1.0 - phi * phi)
    n_t, n_c = onset_u.shape
    bias, left = np.zeros(n_c), np.zeros(n_c)
    out = np.zeros((n_t, n_c))
    for k in range(n_t):
        idle = left <= 0.0
        starts = idle & (onset_u[k] < p_on)
        inside = ~idle
        start_bias = 0.0 if ramp else np.clip(mu + sigma * normals[k], 0.0, max_bias)
        step_bias = np.clip(mu + phi * (bias - mu) + step_sigma * normals[k], 0.0, max_bias)
        bias = np.where(inside, step_bias, np.where(starts, start_bias, 0.0))
        new_left = np.maximum(1.0, -duration * np.log(duration_u[k]) / dt)
        left = np.where(inside, left - 1.0, np.where(starts, new_left, left))
        out[k] = np.where(left > 0.0, bias, 0.0)
    return out


def simulate_gm_nlos(params: Mapping[str, float], ramp: bool, dt: float, n_steps: int, n_channels: int,
                     rng: np.random.Generator) -> np.ndarray:
    """``gm_nlos_bias`` of ``n_channels`` independent channels over ``n_steps`` steps, drawn from ``rng``.

    Returns:
        ``(n_steps, n_channels)`` bias [m].
    """
    if n_steps < 1 or n_channels < 1:
        raise ValueError(f"n_steps={n_steps} and n_channels={n_channels} must be >= 1")
    onset_u = rng.random((n_steps, n_channels))
    # (0, 1]: ln u is finite
    duration_u = 1.0 - rng.random((n_steps, n_channels))
    normals = rng.standard_normal((n_steps, n_channels))
    return gm_nlos_bias(params, ramp, dt, onset_u, duration_u, normals)
