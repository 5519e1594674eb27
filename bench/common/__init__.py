"""What every part of the bench shares: atomic file writes, provenance, report formatting."""
