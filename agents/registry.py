"""The method registry: name → factory and metadata, and loading user methods.

``load_method(text)`` accepts

* a registered name, e.g. ``uniform`` or ``dead-reckoning`` (see :data:`REGISTRY`);
* a registered Track A name with ``+smooth``, e.g. ``huber+smooth``: the policy wrapped
  in adaptive Markov smoothing (madrl eq. 15–17);
* ``package.module:factory`` — an importable callable returning a method;
* ``path/to/file.py:factory`` — the same from a file.

A factory is called with no argument, or with ``weights=<path>`` when a weights file is
given, and with ``version=<benchmark version>`` when the caller names the version of the
tasks it will run and the factory names a ``version`` parameter (a ``**kwargs`` of settings
does not count). A learned method ships one set of weights per benchmark version
(``shipped_for_version``), trained on that version's tasks, so that the frozen v0 results
stay reproducible beside v1. The method it returns is a Track A ``LinkTrustPolicy`` (has
``act``) or a Track B ``Estimator`` (has ``step``); its ``privileged`` and
``deterministic`` attributes are read (defaults False and True).

Adding a shipped method: one :class:`MethodEntry` line in :data:`REGISTRY` with a lazy
``module:attr`` factory string (modules are imported only when the method is loaded, so
the registry stays cheap to import even for torch-based methods).
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Literal

from swarmloc.agents.protocols import is_deterministic, is_privileged
from swarmloc.agents.trust.smoothing import MarkovSmoothing

Track = Literal["A", "B"]
SMOOTH_SUFFIX = "+smooth"
#: folder of the shipped weights (``mappo.pt``, ``pfnn.npz`` …, each with its provenance record)
WEIGHTS_DIR = Path(__file__).resolve().parent / "weights"


@dataclass(frozen=True)
class MethodEntry:
    """A registered method.

    Attributes:
        name: registry name.
        factory: ``module:attr`` of a zero-argument callable returning the method.
        track: ``"A"`` (link trust in the env's CEKF) or ``"B"`` (full estimator).
        summary: one line for tables and ``--help``.
        privileged: reads fault labels (shown apart, never ranked).
        deterministic: re-running an episode reproduces it exactly.
        privileged_training: its shipped weights were fitted to privileged labels (fault or error
            labels, read while training only); it runs without them (``privileged`` False, ranked).
    """

    name: str
    factory: str
    track: Track
    summary: str
    privileged: bool = False
    deterministic: bool = True
    privileged_training: bool = False


_A = "swarmloc.agents.trust.classical"
_M = "swarmloc.agents.mappo.policy"
_P = "swarmloc.agents.estimators.pf.filters"
#: every shipped method, in display order
REGISTRY: dict[str, MethodEntry] = {e.name: e for e in (
    MethodEntry("uniform", f"{_A}:uniform_policy", "A", "standard CEKF, α = 1 (score 0)"),
    MethodEntry("fixed", f"{_A}:fixed_policy", "A", "fixed trust α = 0.6 (madrl Exp. 3)"),
    MethodEntry("huber", f"{_A}:huber_policy", "A", "Huber weight of √NIS, k = 1.345"),
    MethodEntry("chi2-gate", f"{_A}:chi2_gate_policy", "A", "hard χ²₀.₉₅ gate, α_min beyond"),
    MethodEntry("chi2-soft", f"{_A}:chi2_soft_policy", "A", "exp. down-weighting past χ²₀.₉₅ (dtvirm)"),
    MethodEntry("federated-coef", f"{_A}:federated_coef_policy", "A",
                "information-allocation coefficient (federated eq. 17–21)"),
    MethodEntry("cusum", "swarmloc.agents.trust.integrity:cusum_policy", "A",
                "CUSUM per channel on the NIS (λ = 4, ARL₀ = 10⁴), readmits on a reverse CUSUM"),
    MethodEntry("raim", "swarmloc.agents.trust.integrity:raim_policy", "A",
                "RAIM per UAV: Σ NIS vs χ²₀.₉₉₉, leave-one-out exclusion up to a minority"),
    MethodEntry("cusum-chi2", "swarmloc.agents.trust.composite:cusum_chi2_policy", "A",
                "cusum on the absolute channels, chi2-soft on the peer channels (their defaults)"),
    *(MethodEntry(f"{m}-tuned", f"swarmloc.agents.trust.tuned:{m.replace('-', '_')}_tuned", "A",
                  f"{m} with the values swarmloc tune chose on dev-v2 (record: weights/tuned/{m}.json)")
      for m in ("huber", "chi2-gate", "chi2-soft", "cusum", "raim", "cusum-chi2")),
    MethodEntry("non-cooperative", f"{_A}:non_cooperative_policy", "A",
                "each UAV alone: peer channels skipped, absolute ones trusted (a shortcut probe)"),
    MethodEntry("random", f"{_A}:random_policy", "A", "α ~ U(0, 1), seeded (the floor)"),
    MethodEntry("dead-reckoning", "swarmloc.agents.estimators.dead_reckoning:dead_reckoning", "B",
                "IMU only from the initial prior"),
    MethodEntry("imm-kf", "swarmloc.agents.estimators.imm:imm_kf", "B",
                "IMM (CV, CT±) Kalman filter on GPS fixes (imm-arkf Table 1)"),
    MethodEntry("imm-ekf", "swarmloc.agents.estimators.imm:imm_ekf", "B",
                "IMM (CV, CT±) EKF on range/bearing of the fix (imm-arkf Table 1)"),
    MethodEntry("imm-arkf", "swarmloc.agents.estimators.imm:imm_arkf", "B",
                "IMM adaptive robust KF: correntropy weights + χ² fading factor (imm-arkf §2.3)"),
    MethodEntry("federated", "swarmloc.agents.estimators.federated:federated", "B",
                "adaptive fault-tolerant federated filter (federated §4)"),
    MethodEntry("federated-fdi", "swarmloc.agents.estimators.federated:federated_fdi", "B",
                "federated filter, equal allocation + χ² FDI only (federated Scheme 2)"),
    MethodEntry("ci-ekf", "swarmloc.agents.estimators.ci_ekf:ci_ekf", "B",
                "anchor-free CI-EKF + χ² UWB adaptive adjustment, MDS-MAP init (dtvirm)"),
    MethodEntry("ci-ekf-no-aa", "swarmloc.agents.estimators.ci_ekf:ci_ekf_no_aa", "B",
                "CI-EKF without the UWB adaptive adjustment (dtvirm ablation)"),
    MethodEntry("pf", f"{_P}:make_pf", "B", "particle filter, 500 particles (pf-nn Table 4)"),
    MethodEntry("pf-800", f"{_P}:make_pf800", "B", "particle filter, 800 particles"),
    MethodEntry("adaptive-pf", f"{_P}:make_adaptive_pf", "B", "ESS-adaptive particle count in [100, 800] (pf-nn §3.3)"),
    MethodEntry("pf-nn", f"{_P}:make_pfnn", "B",
                "adaptive PF + 6–12–1 weight-correcting network, trained offline (pf-nn §3.4)"),
    MethodEntry("isam2-robust", "swarmloc.agents.estimators.isam2:isam2_robust", "B",
                "fixed-lag (2 s) iSAM2 smoother over the swarm (≤ 6 UAVs), Huber factors (gtsam; 'factorgraph' extra)"),
    MethodEntry("mappo", f"{_M}:mappo", "A",
                "MAPPO link trust (shipped weights of the task's benchmark version) + Markov smoothing",
                privileged_training=True),
    MethodEntry("mappo-no-smoothing", f"{_M}:mappo_no_smoothing", "A", "MAPPO, raw α without smoothing (madrl Exp. 6)",
                privileged_training=True),
    MethodEntry("mappo-no-isolation", f"{_M}:mappo_no_isolation", "A",
                "MAPPO with trust fixed at 1 (madrl Exp. 6 no evaluation)"),
    MethodEntry("mappo-accuracy-only", f"{_M}:mappo_accuracy_only", "A",
                "MAPPO trained on the accuracy term only (madrl Exp. 7)", privileged_training=True),
    MethodEntry("mappo-set-gru", "swarmloc.agents.mappo.set_gru_policy:mappo_set_gru", "A",
                "MAPPO, actor with DeepSets over a UAV's channels + per-channel GRU memory (v1 randomized families)",
                privileged_training=True),
    MethodEntry("supervised-trust", "swarmloc.agents.trust.supervised:supervised_trust", "A",
                "α = 1 − P(error label) of a per-channel MLP fitted to the labels, no RL (v2 randomized families)",
                privileged_training=True),
    MethodEntry("oracle", f"{_A}:oracle_policy", "A",
                "privileged: α_min on channels with an error label (the trust ceiling)", privileged=True),
    MethodEntry("centralized-oracle", "swarmloc.agents.estimators.centralized:centralized_oracle", "B",
                "privileged: one EKF over the swarm's joint state, error-labelled channels left out", privileged=True),
)}

#: the reference of the score: every episode's gain is log2(RMSE of uniform / RMSE) on the same episode
REFERENCE_UNIFORM = "uniform"

_ENTRY = re.compile(r"^(?P<module>[^:]+):(?P<attr>[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*)$")


@dataclass(frozen=True)
class LoadedMethod:
    """A method instance and what the runner needs to know about it.

    Attributes:
        name: registered name, or the factory's attribute name for user methods.
        entry_point: the text it was loaded from.
        track, privileged, deterministic: see :class:`MethodEntry`.
        method: the instance (a ``LinkTrustPolicy`` or an ``Estimator``).
        privileged_training: see :class:`MethodEntry`; a user method declares it as an attribute
            ``privileged_training`` (default False).
    """

    name: str
    entry_point: str
    track: Track
    privileged: bool
    deterministic: bool
    method: Any
    privileged_training: bool = False


def method_names(include_privileged: bool = True) -> list[str]:
    """Registered method names in display order.

    Args:
        include_privileged: include the privileged oracles.
    """
    return [n for n, e in REGISTRY.items() if include_privileged or not e.privileged]


def get_entry(name: str) -> MethodEntry:
    """The registry entry of ``name``.

    Raises:
        KeyError: unknown name (the message lists the registered ones).
    """
    if name not in REGISTRY:
        raise KeyError(f"unknown method {name!r}; registered: {', '.join(REGISTRY)} "
                       f"(or '<name>{SMOOTH_SUFFIX}', 'package.module:factory', 'path/to/file.py:factory')")
    return REGISTRY[name]


def _resolve(module_name: str, attr: str, text: str) -> Callable[..., Any]:
    """Import ``module_name`` (a dotted module or a ``.py`` path) and get ``attr``."""
    if module_name.endswith(".py"):
        path = Path(module_name)
        if not path.is_file():
            raise FileNotFoundError(f"method file {path} (from {text!r}) does not exist")
        mod_name = f"swarmloc_user_{path.stem}"
        spec = importlib.util.spec_from_file_location(mod_name, path)
        if spec is None or spec.loader is None:
            raise ImportError(f"cannot load method file {path} (from {text!r})")
        module = importlib.util.module_from_spec(spec)
        sys.modules[mod_name] = module
        spec.loader.exec_module(module)
    else:
        module = importlib.import_module(module_name)
    obj: Any = module
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise AttributeError(f"{module_name!r} has no attribute {attr!r} (from {text!r})")
        obj = getattr(obj, part)
    if not callable(obj):
        raise TypeError(f"{text!r} names {type(obj).__name__}, not a callable factory")
    return obj


def shipped_for_version(table: dict[int, Path], version: int | None) -> Path:
    """The shipped weights of benchmark ``version``: ``table``'s entry for it, else for the newest older one.

    ``version`` None means the newest benchmark version in ``table``.

    Raises:
        ValueError: ``version`` is negative or older than every entry.
    """
    if version is None:
        return table[max(table)]
    if isinstance(version, bool) or not isinstance(version, int) or version < min(table):
        raise ValueError(f"version must be an int >= {min(table)} (a benchmark version), got {version!r}")
    return table[max(v for v in table if v <= version)]


def _accepts(factory: Callable[..., Any], name: str, *, by_var_keyword: bool = True) -> bool:
    """Whether ``factory`` takes the keyword ``name``: as a named parameter, or through ``**kwargs``
    when ``by_var_keyword`` (a ``**overrides`` of settings is no promise to understand ``version``)."""
    try:
        params = inspect.signature(factory).parameters
    except (TypeError, ValueError):
        return False
    return name in params or (by_var_keyword and any(p.kind is p.VAR_KEYWORD for p in params.values()))


def _call_factory(factory: Callable[..., Any], weights: str | Path | None, text: str,
                  version: int | None = None) -> Any:
    kwargs: dict[str, Any] = {}
    if weights is not None:
        if not _accepts(factory, "weights"):
            raise TypeError(f"a weights file was given but the factory of {text!r} takes no 'weights' argument")
        kwargs["weights"] = str(weights)
    if version is not None and _accepts(factory, "version", by_var_keyword=False):
        kwargs["version"] = int(version)
    return factory(**kwargs)


def track_of(method: Any, text: str = "") -> Track:
    """``"A"`` for an object with ``act`` (link-trust policy), ``"B"`` for one with ``step`` (estimator).

    Raises:
        TypeError: neither.
    """
    if callable(getattr(method, "act", None)) and callable(getattr(method, "reset", None)):
        return "A"
    if callable(getattr(method, "step", None)) and callable(getattr(method, "reset", None)):
        return "B"
    raise TypeError(f"method {text or type(method).__name__!r} is neither a LinkTrustPolicy (reset + act) "
                    f"nor an Estimator (reset + step); see swarmloc.agents.protocols")


def load_method(text: str, weights: str | Path | None = None, version: int | None = None) -> LoadedMethod:
    """Build a method from a registered name or an entry point.

    Args:
        text: ``name``, ``name+smooth``, ``package.module:factory`` or ``path/to/file.py:factory``.
        weights: optional weights file handed to the factory as ``weights=``.
        version: the benchmark version of the tasks the method will run (``TaskSpec.version``),
            handed to a factory with a named ``version`` parameter (the shipped weights of that
            version); None: the newest.

    Returns:
        The ``LoadedMethod``.

    Raises:
        KeyError: unknown registered name. ImportError / AttributeError / TypeError: the
        entry point cannot be loaded or does not return a method.
    """
    if not isinstance(text, str) or not text.strip():
        raise ValueError(f"method must be a non-empty string, got {text!r}")
    text = text.strip()
    smooth = text.endswith(SMOOTH_SUFFIX) and ":" not in text
    base = text[: -len(SMOOTH_SUFFIX)] if smooth else text
    match = _ENTRY.match(base)
    if match is None:
        entry = get_entry(base)
        module_name, attr = entry.factory.split(":")
        method = _call_factory(_resolve(module_name, attr, text), weights, text, version)
        name = entry.name
        privileged_training = entry.privileged_training
    else:
        method = _call_factory(_resolve(match["module"], match["attr"], text), weights, text, version)
        name = match["attr"].rsplit(".", 1)[-1]
        privileged_training = getattr(method, "privileged_training", False)
        if not isinstance(privileged_training, bool):
            raise TypeError(f"{text!r}: privileged_training must be True or False, got {privileged_training!r}")
    track = track_of(method, text)
    if smooth:
        if track != "A":
            raise ValueError(f"{SMOOTH_SUFFIX} applies to link-trust (Track A) methods; {base!r} is Track {track}")
        method = MarkovSmoothing(method)
        name = f"{name}{SMOOTH_SUFFIX}"
    return LoadedMethod(name=name, entry_point=text, track=track, privileged=is_privileged(method),
                        deterministic=is_deterministic(method), method=method,
                        privileged_training=privileged_training)
