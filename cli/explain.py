"""``swarmloc explain``: why a Track A method trusted each channel as it did (madrl Experiment 4)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal


@dataclass
class Options:
    """Attribute a Track A method's trust to its observation features over one episode; Figure 6 chain + Table 5."""

    method: str
    """Track A method: a registered name (mappo, chi2-gate, …), name+smooth, or module:factory."""
    task: str = "swarmloc/NLOSStep-v0"
    """Task ID."""
    seed: int = 1_000_000
    """Episode seed (default: the first test seed)."""
    channels: tuple[int, ...] = ()
    """Channel indices (the L axis, every UAV) to explain; default all."""
    out: Path = Path("swarmloc-explain")
    """Output folder: figure.png, summary.md, summary.json, attributions.npz."""
    explainer: Literal["auto", "integrated-gradients", "shapley-sampling"] = "auto"
    """auto: integrated gradients for torch policies with a differentiable form, Shapley sampling otherwise."""
    baseline: Literal["nominal", "zeros"] = "nominal"
    """Reference input: nominal = a quiet, fully trusted channel of the same kind; zeros = every feature 0."""
    samples: int = 25
    """Random feature orders per channel and step (Shapley sampling)."""
    weights: Path | None = None
    """Weights file handed to the method's factory."""
    reference: str = "uniform"
    """Method flown on the same episode for comparison in the figure and table ('' for none)."""
    duration: float | None = None
    """Episode length override [s] (default: the task's)."""
    uav: int | None = None
    """UAV shown in the figure (default: the one whose channel is attacked longest)."""


def run(opts: Options) -> int:
    """Explain, write the four files and print the summary."""
    import time

    import numpy as np

    # without the explain extra these raise ModuleNotFoundError: the command line names the extra
    from swarmloc.agents.registry import load_method
    from swarmloc.bench.common.files import atomic_path
    from swarmloc.bench.explain import explain
    from swarmloc.bench.explain.features import FEATURE_NAMES, GROUP_NAMES
    from swarmloc.bench.explain.figure import plot_chain
    from swarmloc.bench.explain.report import summarize, write_summary
    from swarmloc.envs.tasks.catalogue import get_spec
    started = time.perf_counter()
    overrides = {} if opts.duration is None else {"duration": opts.duration}
    try:
        spec = get_spec(opts.task, **overrides)
        method = load_method(opts.method, opts.weights, version=spec.version)
        ex = explain(method, spec, [opts.seed], explainer=opts.explainer, baseline=opts.baseline,
                     channels=opts.channels or None, n_samples=opts.samples, reference=opts.reference or None)
        opts.out.mkdir(parents=True, exist_ok=True)
        figure = plot_chain(ex, opts.out / "figure.png", opts.uav)
    except (KeyError, ValueError, TypeError, FileNotFoundError) as err:
        print(f"error: {err}")
        return 2
    a, ep = ex.attributions, ex.episode
    with atomic_path(opts.out / "attributions.npz", suffix=".npz") as tmp:
        np.savez_compressed(tmp, values=a.values, grouped=a.grouped(), trust=a.trust, baseline_trust=a.baseline_trust,
                            explained=a.explained, times=ep.times, obs=ep.obs, resid=ep.resid, label=ep.label,
                            error=ep.error, feature_names=np.array(FEATURE_NAMES), group_names=np.array(GROUP_NAMES))
    summary = summarize(ex)
    summary["total_seconds"] = time.perf_counter() - started
    report = write_summary(summary, opts.out, figure.name)
    print(report.read_text())
    print(f"wrote {figure}, {report}, {report.with_suffix('.json')}, {opts.out / 'attributions.npz'} "
          f"in {summary['total_seconds']:.1f} s")
    return 0
