"""The simulated world: truth, sensors, faults, labels, reward and the batched link-trust core."""
