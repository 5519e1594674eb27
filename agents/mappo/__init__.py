"""MAPPO link trust: configuration, networks, collection, training and execution-time policies."""
