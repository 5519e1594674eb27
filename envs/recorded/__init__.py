"""Recorded flight data: readers and importers for real logs (the UTIL UWB dataset) and their replay.

- ``cfusdlog``: the Crazyflie µSD event-log reader;
- ``util_import``: the UTIL TWR importer (CSV layout, ``find_util_data``, ``swarmloc data import-util``);
- ``util_flight``: one imported log resampled onto filter steps (AHRS world acceleration, per-anchor
  range calibration, truth, fault labels);
- ``tdoa_import``: the UTIL TDOA importer (``swarmloc data import-util-tdoa``, ``find_tdoa_data``);
- ``tdoa_flight``: one imported TDOA flight on filter steps, with the staged README's filtering rules
  (impossible values dropped and counted, the airborne window, reversed pairs, dropouts masked);
- ``flights``: which loader a recorded task's data set uses (the one place that dispatches);
- ``replay``: ``RecordedWorld``, the world interface over a recording (``UTILFlight-v0``/``-v1``, the
  ``UTIL*Tdoa*-v1`` flights).

The data itself is never part of the repository (the UTIL data set has no licence).
"""
