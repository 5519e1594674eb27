"""The explanation API: attributions of a Track A method's trust to its observation features.

::

    from swarmloc.bench.explain import explain
    ex = explain("mappo", "swarmloc/NLOSStep-v0", seeds=[1_000_000])
    ex.attributions.values        # (T, B, N, L, F): step k, episode b, UAV i, channel j, feature f
    ex.attributions.at(250)       # (B, N, L, F) at one step
    ex.attributions.grouped()     # (T, B, N, L, 7): the kind one-hot summed

Per step and channel, ``values[k, b, i, j]`` splits α(x) − α(x̄) over the F features of
that channel, the UAV's other channels held at their recorded values (the channel's
own game; the ``features`` module defines the baselines x̄). Two explainers play the
same game:

| explainer | for | what |
|---|---|---|
| ``integrated-gradients`` | torch policies with a differentiable form (``gradients.differentiable``: MAPPO, its smoothed variants, policies with ``torch_trust``) | Captum ``IntegratedGradients``, cut at the form's kinks |
| ``shapley-sampling`` | any Track A method (chi2-gate, huber, user black boxes …; torch ones too) | Captum ``ShapleyValueSampling`` over seven feature groups, probing ``act`` |

``explainer="auto"`` takes integrated gradients where a differentiable form exists and
Shapley sampling otherwise, so a learned and a classical policy are explained with the
same features, baseline and completeness property (both sum to α(x) − α(x̄)).
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from swarmloc.agents.registry import LoadedMethod
from swarmloc.envs.tasks.specs import TaskSpec
from swarmloc.envs.tasks.catalogue import get_spec

from swarmloc.bench.explain.episode import Episode, as_loaded, replay
from swarmloc.bench.explain.features import baseline_features, check_baseline, group_attributions

EXPLAINERS = ("auto", "integrated-gradients", "shapley-sampling")
#: a differentiable form may differ from the method's own act() by rounding (float32 vs float64), no more
FAITHFULNESS_TOL = 1e-4
#: a method's trust on one episode alone and in a batch may differ by float32 rounding (BLAS), no more
BATCH_TOL = 1e-6


@dataclass(frozen=True)
class Attributions:
    """Per-step, per-channel feature attributions of one method on one recorded episode.

    Attributes:
        values: ``(T, B, N, L, F)`` attributions; NaN on channels not explained.
        trust: ``(T, B, N, L)`` α(x), the explained method's trust on the recorded inputs.
        baseline_trust: ``(T, B, N, L)`` α(x̄), its trust at the baseline (NaN where not explained).
        explained: ``(N, L)`` bool, the channels explained.
        explainer: ``integrated-gradients`` or ``shapley-sampling``.
        baseline: ``nominal`` or ``zeros``.
        completeness_gap: max |Σ_f values − (α(x) − α(x̄))| over the explained rows.
        faithfulness_gap: max |α the explainer evaluated − α of the method's ``act``| on the
            recorded inputs (the differentiable form's, or the shadow batch's).
        settings: the explainer's parameters.
        seconds: wall time of the attribution.
    """

    values: np.ndarray
    trust: np.ndarray
    baseline_trust: np.ndarray
    explained: np.ndarray
    explainer: str
    baseline: str
    completeness_gap: float
    faithfulness_gap: float
    settings: dict[str, Any] = field(default_factory=dict)
    seconds: float = 0.0

    def at(self, k: int) -> np.ndarray:
        """``(B, N, L, F)`` attributions of step index k (0-based)."""
        return self.values[k]

    def grouped(self) -> np.ndarray:
        """``(T, B, N, L, G)`` attributions of the seven feature groups (``features.GROUP_NAMES``)."""
        return group_attributions(self.values)


@contextlib.contextmanager
def one_torch_thread() -> Iterator[None]:
    """Run torch on one thread inside the block (restored afterwards).

    The explainers make many small torch calls (one step's channels, one piece of a path):
    a second intra-op thread saves nothing there, and its spin-waiting workers cost five
    times the CPU on a busy machine (measured: 19 s → 3.7 s of CPU for one episode's IG).
    """
    import torch

    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(previous)


def _explained_mask(episode: Episode, channels: Sequence[int] | None) -> np.ndarray:
    n, n_l = episode.obs.shape[2:4]
    mask = np.zeros((n, n_l), dtype=bool)
    if channels is None:
        mask[:] = True
        return mask
    for j in channels:
        if not 0 <= int(j) < n_l:
            raise ValueError(f"channel {j} is out of range: {episode.spec.task_id} has channels 0 … {n_l - 1}")
        mask[:, int(j)] = True
    if not mask.any():
        raise ValueError("channels is empty: give at least one channel index")
    return mask


def _scatter(rows: np.ndarray, explained: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """Explained rows in (step, episode, UAV, channel) order → an array of ``shape`` (NaN elsewhere)."""
    n_t, n_b, n, n_l = shape[:4]
    out = np.full(shape, np.nan)
    mask = np.broadcast_to(explained, (n_b, n, n_l))
    out[:, mask] = rows.reshape(n_t, int(mask.sum()), *shape[4:])
    return out


def attribute(method: str | LoadedMethod, episode: Episode, *, explainer: str = "auto", baseline: str = "nominal",
              channels: Sequence[int] | None = None, n_samples: int = 25, seed: int = 0) -> Attributions:
    """Attribute a method's trust on a recorded episode to the observation features.

    The method need not be the one that flew the episode (e.g. a randomly initialised
    actor on a trained actor's episode, for a sanity check).

    Args:
        method: a registered name or entry point, or a fresh ``LoadedMethod`` (copies of
            its instance are reset and driven here).
        episode: from :func:`swarmloc.bench.explain.replay`.
        explainer: ``auto``, ``integrated-gradients`` or ``shapley-sampling``.
        baseline: ``nominal`` or ``zeros`` (``swarmloc.bench.explain.features``).
        channels: channel indices (the L axis) to explain, for every UAV; None = all.
        n_samples: random feature orders per channel and step (Shapley sampling).
        seed: seed of those orders.

    Returns:
        The ``Attributions``.

    Raises:
        ValueError: unknown explainer or baseline; ``integrated-gradients`` asked for a
            method without a differentiable form; a form that does not reproduce the method.
    """
    from swarmloc.bench.explain.gradients import differentiable

    if explainer not in EXPLAINERS:
        raise ValueError(f"unknown explainer {explainer!r}; choose one of {', '.join(EXPLAINERS)}")
    check_baseline(baseline)
    loaded = as_loaded(method, episode.spec.version)
    explained = _explained_mask(episode, channels)
    base = baseline_features(episode.obs, baseline)
    form = differentiable(loaded.method) if explainer != "shapley-sampling" else None
    if explainer == "integrated-gradients" and form is None:
        raise ValueError(f"{loaded.name} has no differentiable form (a torch policy: MappoPolicy, MarkovSmoothing "
                         f"around one, or a policy with torch_trust(obs)); use explainer='shapley-sampling'")
    started = time.perf_counter()
    with one_torch_thread():
        return _attribute(loaded, episode, form, base, explained, baseline, n_samples, seed, started)


def _attribute(loaded: LoadedMethod, episode: Episode, form: Any, base: np.ndarray, explained: np.ndarray,
               baseline: str, n_samples: int, seed: int, started: float) -> Attributions:
    """:func:`attribute` once its arguments are checked."""
    from swarmloc.bench.explain.gradients import integrated_gradients
    from swarmloc.bench.explain.shapley import fresh_copy, shapley_sampling

    shape = episode.trust.shape
    if form is not None:
        own = _own_trust(fresh_copy(loaded.method), episode)
        result = integrated_gradients(form, episode, base, explained, own)
        faithfulness = float(np.abs(result.trust - own[:, np.broadcast_to(explained, shape[1:])].ravel()).max())
        if faithfulness > FAITHFULNESS_TOL:
            raise ValueError(f"the differentiable form of {loaded.name} gives trust up to {faithfulness:.3g} away "
                             f"from its act() on the recorded inputs (allowed {FAITHFULNESS_TOL}); explain it with "
                             f"explainer='shapley-sampling'")
        name, settings = "integrated-gradients", {"quadrature": "Gauss-Legendre per smooth piece",
                                                  "max_evals_per_row": int(result.n_evals.max(initial=0))}
    else:
        result = shapley_sampling(loaded.method, episode, base, explained, n_samples=n_samples, seed=seed)
        own, faithfulness = result.method_trust, result.batch_gap
        if faithfulness > BATCH_TOL:
            raise ValueError(f"{loaded.name} gives different trust to the same episode alone and in a batch "
                             f"(up to {faithfulness:.3g}): its probes cannot be batched (Track A methods must "
                             f"not depend on the batch; see swarmloc.agents.protocols)")
        name, settings = "shapley-sampling", {"n_samples": n_samples, "seed": seed, "players": 7}
    seconds = time.perf_counter() - started
    return Attributions(
        values=_scatter(result.values, explained, (*shape, episode.obs.shape[-1])), trust=own,
        baseline_trust=_scatter(result.baseline_trust, explained, shape), explained=explained, explainer=name,
        baseline=baseline, completeness_gap=float(np.abs(result.delta).max(initial=0.0)),
        faithfulness_gap=faithfulness, settings=settings, seconds=seconds)


def _own_trust(method: Any, episode: Episode) -> np.ndarray:
    """``(T, B, N, L)`` the method's own trust on the recorded inputs."""
    method.reset(episode.obs.shape[1], episode.layout, episode.keys)
    return np.stack([np.clip(np.asarray(method.act(inp), dtype=np.float64), 0.0, 1.0) for inp in episode.inputs()])


@dataclass(frozen=True)
class Explanation:
    """An episode flown by a method, the attributions of its trust, and a reference run.

    Attributes:
        episode: the method's recorded episode.
        attributions: its attributions.
        reference: the same episode flown by the reference method (``uniform``: the
            standard CEKF), or None.
    """

    episode: Episode
    attributions: Attributions
    reference: Episode | None


def explain(method: str | LoadedMethod, task: str | TaskSpec, seeds: Sequence[int] = (1_000_000,), *,
            explainer: str = "auto", baseline: str = "nominal", channels: Sequence[int] | None = None,
            n_samples: int = 25, reference: str | None = "uniform", **overrides: Any) -> Explanation:
    """Fly a method on a task and explain its trust decisions.

    Args:
        method: a registered name or entry point, or a fresh ``LoadedMethod``.
        task: a registered task ID or a ``TaskSpec``.
        seeds: episode seeds (default: the first test seed).
        explainer, baseline, channels, n_samples: see :func:`attribute`.
        reference: a method flown on the same episodes for comparison (None: none).
        **overrides: spec overrides for a task ID (e.g. ``duration=10.0``).

    Returns:
        The ``Explanation``.
    """
    spec = task if isinstance(task, TaskSpec) else get_spec(task, **overrides)
    loaded = as_loaded(method, spec.version)
    from swarmloc.bench.explain.shapley import fresh_copy

    pristine = LoadedMethod(loaded.name, loaded.entry_point, loaded.track, loaded.privileged, loaded.deterministic,
                            fresh_copy(loaded.method))
    with one_torch_thread():
        episode = replay(loaded, spec, seeds)
        attributions = attribute(pristine, episode, explainer=explainer, baseline=baseline, channels=channels,
                                 n_samples=n_samples)
        ref = replay(reference, spec, seeds) if reference else None
    return Explanation(episode=episode, attributions=attributions, reference=ref)
