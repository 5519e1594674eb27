"""The evaluation runner's stable import path: ``from swarmloc.bench.runner import run_episodes``.

The code lives in ``swarmloc.bench.evaluation.runner``; this module re-exports its public API
so that scripts written against the flat layout keep working.
"""

from swarmloc.bench.evaluation.runner import *  # noqa: F401,F403
from swarmloc.bench.evaluation.runner import __all__  # noqa: F401
