"""swarmloc.agents."""
