"""Track A link-trust policies: classical baselines, integrity monitors, the oracle, smoothing."""
