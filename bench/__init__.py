"""swarmloc.bench."""
