"""Evaluating methods on suites: the runner, its backends, results files, metrics and comparisons.

The stable entry points are re-exported by ``swarmloc.bench`` (``evaluate``, ``evaluate_task``,
``get_suite``, ``load_results``, ``compare``); the modules here are internal.
"""
