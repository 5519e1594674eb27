"""Presenting results: plots, method styles, the demo tables and Markdown reports."""
