"""Recorded flight data: readers and importers for real logs (e.g. the UTIL UWB dataset)."""
