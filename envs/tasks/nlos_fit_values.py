"""The Gauss–Markov NLOS parameters fitted to the UTIL residual statistics (numba-free constants).

``swarmloc reproduce nlos-fit`` reproduces them (``swarmloc.bench.reproduce.nlos_fit``: the
statistics, the grid + Nelder–Mead fit, and its report ``docs/reproduce/nlos-fit.md``);
``tests/test_nlos_fit.py`` checks, where the data is present, that the process with these
values, observed as the logs are, has the logs' statistics. Keys are ``specs.NlosGaussMarkov``
fields.

What they say (the report has the numbers): the UTIL obstacle residuals are short-lived.
Biased samples (|excess| > 3 σ_LOS) are 11 % (TWR) and 14 % (TDOA) of the samples, but a
biased run lasts 0.2–0.3 s and the excess autocorrelation is ≈ 0.4 at 0.2 s and 0.05–0.2 at
1 s; the fitted episodes last about 1 s with τ well under 1 s, far from v1's hand-chosen
``INDOOR_NLOS`` (8 s episodes, τ 2 s). The TWR fit is a near-zero-mean bias (clipped at 0)
switched on about half of the time: a heavy tail more than obstruction episodes.
"""

from __future__ import annotations

#: fitted to the TWR obstacle flight twr-obs-log1 (log00 calibration), σ_LOS 0.077 m
UTIL_NLOS_TWR = dict(onset_rate=1.0, mean_duration=1.0, mean_bias=0.0103, bias_sigma=0.284, tau=0.618,
                     max_bias=5.0, onset="ramp")
#: fitted to the four UTIL TDOA flights among obstacles, pooled (σ_LOS 0.151 m TDOA2, 0.194 m TDOA3)
UTIL_NLOS_TDOA = dict(onset_rate=0.223, mean_duration=1.0, mean_bias=0.521, bias_sigma=0.853, tau=0.172,
                      max_bias=5.0, onset="ramp")
