"""Submissions: the pipeline from a results file to a stored entry, entry points, metadata."""
