"""Speed benchmarks: throughput measured side by side on identical inputs, in one run.

``kernels`` (FilterPy vs our numpy reference vs the numba CEKF kernel, and the full world
step), ``envs`` (our adapters beside other multi-agent envs), ``estimators`` (Track B
estimators per step), ``evaluation`` (episodes/s of the ``process`` and ``ray`` execution
backends). Run them all with ``swarmloc bench speed [--json PATH]``.
"""
