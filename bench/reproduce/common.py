"""What the paper reproductions share: test seeds, runner metrics, per-step errors, paired orderings.

Headline RMSEs and every ordering come from the runner (``rollout``, the leaderboard's
metrics). Per-axis and per-UAV breakdowns and the raw-range anomaly statistics need
per-step errors and the truth, so :func:`episode_errors` observes the runner's episode
loop (same world, measurements, alignment) and keeps them. Our worlds are not the papers'
simulators: compare orderings and magnitudes, not digits.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from swarmloc.agents.registry import LoadedMethod
from swarmloc.bench.common.provenance import collect_provenance
from swarmloc.bench.evaluation.alignment import align_estimates
from swarmloc.bench.evaluation.episode import EpisodeBatch, StepRecord, fly_episodes
from swarmloc.bench.evaluation.runner import rollout
from swarmloc.bench.evaluation.suites import TEST_SEED_START
from swarmloc.bench.reports.markdown import report_path, write_report
from swarmloc.bench.scoring.stats import bootstrap_ci
from swarmloc.envs.tasks.channels import PEER
from swarmloc.envs.tasks.specs import TaskSpec

Factory = Callable[[], Any]


def seeds_from(n: int) -> list[int]:
    """The first ``n`` test seeds (1_000_000 …)."""
    if n < 2:
        raise ValueError(f"need at least 2 seeds for confidence intervals, got {n}")
    return list(range(TEST_SEED_START, TEST_SEED_START + n))


def runner_metrics(label: str, make: Factory, spec: TaskSpec, seeds: list[int]) -> list[dict]:
    """Per-seed runner metrics of a configured estimator (``rollout``, as ``swarmloc evaluate``)."""
    loaded = LoadedMethod(name=label, entry_point=label, track="B", privileged=False, deterministic=True,
                          method=make())
    metrics, _ = rollout(loaded, spec, seeds)
    return metrics


class _StepErrors:
    """The episode loop's observer behind :func:`episode_errors`: positions, truth, trust, raw range errors, time."""

    def begin(self, batch: EpisodeBatch) -> None:
        n_t, n_b, n = batch.spec.n_steps, len(batch.seeds), batch.spec.n_uav
        peer = batch.layout.kind == PEER
        self.peer, self.target = peer, np.where(peer, batch.layout.target, 0)
        self.pos, self.truth = np.zeros((n_t, n_b, n, 3)), np.zeros((n_t, n_b, n, 3))
        self.weights = np.ones((n_t, n_b) + peer.shape)
        self.range_err = np.full((n_t, n_b) + peer.shape, np.nan)
        self.valid = np.zeros((n_t, n_b) + peer.shape, dtype=bool)
        self.spent = 0.0

    def observe(self, r: StepRecord) -> None:
        k, out, truth = r.k, r.output, r.truth
        assert out is not None and r.measurements is not None  # a Track B step
        self.pos[k], self.truth[k], self.valid[k] = out.positions, truth, r.valid
        if out.weights is not None:
            self.weights[k] = out.weights
        d = np.linalg.norm(truth[:, :, None, :] - truth[:, self.target, :], axis=-1)
        self.range_err[k] = np.where(self.peer, np.abs(r.measurements.z[..., 0] - d), np.nan)
        self.spent += r.method_s


def episode_errors(make: Factory, spec: TaskSpec, seeds: list[int]) -> dict[str, np.ndarray]:
    """An estimator through the episode loop (``fly_episodes``, as the runner), keeping per-step errors, trust
    and the raw range errors.

    Returns:
        ``err`` (T, B, N, 3) estimate − truth after the task's scoring alignment,
        ``times`` (T,), ``weights`` (T, B, N, L) applied trust (ones if none reported),
        ``range_err`` (T, B, N, L) |measured − true range| on peer channels (NaN elsewhere),
        ``valid`` (T, B, N, L), ``step_ms`` mean wall time of ``step`` [ms].
    """
    est = make()
    name = type(est).__name__
    loaded = LoadedMethod(name=name, entry_point=name, track="B", privileged=False, deterministic=True, method=est)
    steps = _StepErrors()
    fly_episodes(loaded, spec, seeds, [steps])
    T = spec.n_steps
    times = spec.dt * np.arange(1, T + 1)
    err = align_estimates(spec, times, steps.pos, steps.truth) - steps.truth
    return {"err": err, "times": times, "weights": steps.weights, "range_err": steps.range_err,
            "valid": steps.valid, "step_ms": 1e3 * steps.spent / T}


def paired(a: np.ndarray, b: np.ndarray, claim: str) -> dict:
    """The claim "a < b" on paired per-seed values: mean difference a − b and its 95 % bootstrap CI."""
    d = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
    lo, hi = bootstrap_ci(d)
    return {"claim": claim, "mean_diff": float(d.mean()), "ci": [lo, hi], "holds": bool(d.mean() < 0),
            "significant": bool(hi < 0), "contradicted": bool(lo > 0), "wins": int((d < 0).sum()), "n": int(d.size)}


def verdict(row: dict) -> str:
    if row["significant"]:
        return "holds (CI < 0)"
    if row["contradicted"]:
        return "reversed (CI > 0)"
    return "not resolved (CI ∋ 0)"


def ordering_table(rows: list[dict]) -> list[str]:
    out = ["| claim | mean difference (m) | 95 % CI | verdict | seeds won |", "|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['claim']} | {r['mean_diff']:+.4f} | [{r['ci'][0]:+.4f}, {r['ci'][1]:+.4f}] "
                   f"| {verdict(r)} | {r['wins']}/{r['n']} |")
    return out


def mean_sd(values: np.ndarray, digits: int = 3) -> str:
    v = np.asarray(values, dtype=float)
    return f"{v.mean():.{digits}f} ± {v.std(ddof=1):.{digits}f}"


def write_paper_report(out: Path, name: str, text: str, raw: dict) -> Path:
    """Write ``<out>`` (or ``<out>/<name>.md``) and the raw numbers beside it, atomically.

    The report ends with its provenance (package version and git commit).
    """
    prov = collect_provenance()
    raw = {**raw, "provenance": prov.model_dump(mode="json")}
    text += (f"\n---\nGenerated by `swarmloc reproduce {name}` with swarmloc {prov.package_version}, commit "
             f"{(prov.git_commit or 'unknown')[:10]}.\n")
    return write_report(report_path(out, name), text, raw)
