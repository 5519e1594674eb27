"""swarmloc.bench: evaluating methods on suites, the stable Python API.

The five names below are the API that the README, the command line and the tests use; every
other module of ``swarmloc.bench`` is internal and may move between releases::

    from swarmloc.bench import evaluate, evaluate_task, get_suite, load_results, compare

    suite = get_suite("quick-v1")                      # .tasks, .seeds(task), .episodes, .sha256
    results = evaluate("chi2-soft", suite)             # every (task, seed) episode of the suite
    outcome = evaluate_task(["uniform", "chi2-soft"], "swarmloc/NLOS-v1", seeds=[0, 1])
    outcome.episodes["chi2-soft"]                      # one metrics dict per seed
    delta = compare(load_results("a.json"), load_results("b.json"))  # paired bootstrap, B − A

The names resolve on first use, so that ``import swarmloc.bench`` (and ``swarmloc --help``)
imports neither numba nor torch.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from swarmloc.bench.scoring.compare import compare
    from swarmloc.bench.evaluation.results import load_results
    from swarmloc.bench.evaluation.runner import evaluate, evaluate_task
    from swarmloc.bench.evaluation.suites import get_suite

__all__ = ["compare", "evaluate", "evaluate_task", "get_suite", "load_results"]

_HOME = {
    "compare": ".scoring.compare",
    "evaluate": ".evaluation.runner",
    "evaluate_task": ".evaluation.runner",
    "get_suite": ".evaluation.suites",
    "load_results": ".evaluation.results",
}


def __getattr__(name: str) -> Any:
    if name not in _HOME:
        raise AttributeError(f"module 'swarmloc.bench' has no attribute {name!r}; the stable API is {__all__}")
    value = getattr(import_module(_HOME[name], __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
