"""Recorded flight data: readers and importers for real logs (the UTIL UWB dataset) and their replay.

- ``cfusdlog``: the Crazyflie µSD event-log reader;
- ``util_import``: the UTIL TWR importer (CSV layout, ``find_util_data``, ``swarmloc data import-util``);
- ``util_flight``: one imported log resampled onto filter steps (AHRS world acceleration, per-anchor
  range calibration, truth, fault labels);
- ``replay``: ``RecordedWorld``, the world interface over a recording (task ``UTILFlight-v0``).

The data itself is never part of the repository (the UTIL data set has no licence).
"""
