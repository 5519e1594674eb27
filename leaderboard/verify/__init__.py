"""Verification: sandboxed re-runs of a sample of submitted episodes."""
