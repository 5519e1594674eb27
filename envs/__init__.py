"""swarmloc.envs."""
