"""Scoring evaluated episodes: metrics, the score, statistics, bounds, families, comparisons."""
