"""The tuned classical methods: ``<method>-tuned`` builds ``<method>``'s policy with the values ``swarmloc tune`` chose.

Every tunable method is a registered Track A method whose policy class declares a
``SEARCH_SPACE`` (:data:`TUNABLE`). ``swarmloc tune <method>`` searches that space on dev-v2
with one budget for every method and writes a record, shipped with the package as
``agents/weights/tuned/<method>.json`` (docs/tuning.md). A ``-tuned`` factory reads its
record's ``params`` and builds the policy with them; handed ``weights=<file>``, it reads that
file instead (a record of another tuning run, or one trial's parameters: any JSON object
with ``method`` and ``params``).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from swarmloc.agents.registry import WEIGHTS_DIR, load_method
from swarmloc.agents.trust.classical import Chi2GateTrust, Chi2SoftTrust, HuberTrust
from swarmloc.agents.trust.composite import CusumChi2Trust
from swarmloc.agents.trust.integrity import CusumTrust, RaimTrust
from swarmloc.agents.trust.search_space import Param

#: registered name → its policy class, whose ``SEARCH_SPACE`` the tuner searches
TUNABLE: dict[str, type] = {
    "huber": HuberTrust,
    "chi2-gate": Chi2GateTrust,
    "chi2-soft": Chi2SoftTrust,
    "cusum": CusumTrust,
    "raim": RaimTrust,
    "cusum-chi2": CusumChi2Trust,
}
TUNED_SUFFIX = "-tuned"
#: the shipped tuning records, one ``<method>.json`` each
RECORDS_DIR = WEIGHTS_DIR / "tuned"


def check_tunable(method: str) -> str:
    """``method`` if it is tunable.

    Raises:
        ValueError: not in :data:`TUNABLE` (the message lists the tunable methods).
    """
    if method not in TUNABLE:
        raise ValueError(f"method {method!r} is not tunable; tunable: {', '.join(TUNABLE)}")
    return method


def search_space(method: str) -> tuple[Param, ...]:
    """The search space of a tunable method (its policy class's ``SEARCH_SPACE``)."""
    return TUNABLE[check_tunable(method)].SEARCH_SPACE


def default_params(method: str) -> dict[str, float]:
    """The values of the registered, untuned ``method`` on its search space's parameters (the tuner's first trial)."""
    policy = load_method(check_tunable(method)).method
    return {p.name: float(getattr(policy, p.name)) for p in search_space(method)}


def record_path(method: str) -> Path:
    """Where the shipped record of ``method``'s tuning lies: ``agents/weights/tuned/<method>.json``."""
    return RECORDS_DIR / f"{check_tunable(method)}.json"


def read_params(method: str, path: str | Path | None = None) -> dict[str, float]:
    """The tuned values of ``method`` from its record (the shipped one when ``path`` is None).

    Args:
        method: a tunable method.
        path: a JSON file with ``method`` and ``params`` (a tuning record or one trial's parameters).

    Returns:
        Parameter name → value, the names of the method's search space.

    Raises:
        FileNotFoundError: no record (the message names the command that writes it).
        ValueError: the file is for another method, or its parameters are not the search space's.
    """
    path = record_path(method) if path is None else Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no tuning record of {method!r} at {path}; write it with `swarmloc tune {method}` "
                                f"(needs the 'tune' extra), or evaluate the untuned {method!r}")
    record: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    if record.get("method") != method:
        raise ValueError(f"{path} holds parameters of {record.get('method')!r}, not of {method!r}")
    params = record.get("params")
    names = [p.name for p in search_space(method)]
    if not isinstance(params, dict) or sorted(params) != sorted(names):
        raise ValueError(f"{path}: 'params' must name exactly {names}, got {params!r}")
    return {name: float(params[name]) for name in names}


def tuned_policy(method: str, weights: str | Path | None = None) -> Any:
    """``method``'s policy built with its tuned values (:func:`read_params` of ``weights`` or the shipped record)."""
    return TUNABLE[check_tunable(method)](**read_params(method, weights))


# --------------------------------------------------------------------------- factories (registry)


def huber_tuned(weights: str | None = None) -> HuberTrust:
    """Registry factory: ``huber-tuned`` (k from the tuning record)."""
    return tuned_policy("huber", weights)


def chi2_gate_tuned(weights: str | None = None) -> Chi2GateTrust:
    """Registry factory: ``chi2-gate-tuned`` (confidence, α_reject from the tuning record)."""
    return tuned_policy("chi2-gate", weights)


def chi2_soft_tuned(weights: str | None = None) -> Chi2SoftTrust:
    """Registry factory: ``chi2-soft-tuned`` (confidence, σ from the tuning record)."""
    return tuned_policy("chi2-soft", weights)


def cusum_tuned(weights: str | None = None) -> CusumTrust:
    """Registry factory: ``cusum-tuned`` (λ, ARL₀, α_reject from the tuning record)."""
    return tuned_policy("cusum", weights)


def raim_tuned(weights: str | None = None) -> RaimTrust:
    """Registry factory: ``raim-tuned`` (P_fa, α_reject from the tuning record)."""
    return tuned_policy("raim", weights)


def cusum_chi2_tuned(weights: str | None = None) -> CusumChi2Trust:
    """Registry factory: ``cusum-chi2-tuned`` (the CUSUM's λ, ARL₀, α_reject and the soft gate's confidence, σ)."""
    return tuned_policy("cusum-chi2", weights)
