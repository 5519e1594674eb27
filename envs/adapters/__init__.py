"""Gymnasium, vector, PettingZoo and torchrl adapters, registration and rendering."""
