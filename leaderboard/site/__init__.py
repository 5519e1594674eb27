"""Showing the board: ranking, terminal views, the static HTML site and its plots."""
