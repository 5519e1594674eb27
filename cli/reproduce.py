"""``swarmloc reproduce …``: the paper reproductions and calibration reports, one command each.

Each command is a dataclass (its fields are the options, its docstring the help line) whose
``run`` writes the report, then prints it. The work happens in ``swarmloc.bench.reproduce``,
imported inside ``run`` so that ``swarmloc --help`` stays light.
"""

from __future__ import annotations

import shlex
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Callable


def print_report(write: Callable[[], Path]) -> int:
    """Write a report, then print it.

    Args:
        write: writes the report and returns its path.

    Returns:
        0, or 2 after printing ``error: …`` when an option names something that does not
        exist or is not allowed (``ValueError``, ``KeyError``, ``FileNotFoundError``).
    """
    try:
        path = write()
    except (ValueError, KeyError, FileNotFoundError) as err:
        print(f"error: {err.args[0] if isinstance(err, KeyError) and err.args else err}")
        return 2
    print(path.read_text(encoding="utf-8"))
    return 0


@dataclass
class Madrl:
    """madrl Experiments 1, 3–7 on our tasks (test seeds), beside the paper's tables."""

    out: Path = Path("madrl.md")
    """Markdown file to write (a folder: <out>/madrl.md); raw numbers go beside it as .json."""
    seeds: int = 32
    """test seeds per task (1_000_000 …; 32 = the standard-v0 / standard-v1 episodes)."""
    traces: int = 8
    """seeds per task whose per-step traces give per-channel weights, pre-fault and peak errors."""
    weights: Path | None = None
    """MAPPO weights (default: the shipped agents/weights/mappo.pt)."""
    accuracy_only_weights: Path | None = None
    """Weights of the reward ablation (default: the shipped mappo_accuracy_only.pt, if present)."""
    version: int = 1
    """Benchmark version of the tasks: 1 (`*-v1`, with the learned reference beside mappo) or 0 (the frozen v0)."""

    def run(self) -> int:
        from swarmloc.bench.reproduce.madrl import reproduce_madrl

        return print_report(lambda: reproduce_madrl(self.out, self.seeds, self.traces, self.weights,
                                                    self.accuracy_only_weights, version=self.version))


@dataclass
class Pfnn:
    """pf-nn Tables 4 (accuracy) and 5 (time per step) on Indoor, beside the paper's numbers."""

    out: Path = Path("pfnn.md")
    """Markdown file to write (a folder: <out>/pfnn.md); raw numbers go beside it as .json."""
    seeds: int = 32
    """Indoor test seeds (1_000_000 …)."""
    duration: float | None = None
    """Episode length [s] (default: the task's 100 s)."""
    timing_steps: int = 300
    """Steps of the Table 5 timing episode."""
    oracle: bool = True
    """Also run the privileged online-trained PF-NN (shown apart)."""
    version: int = 1
    """Benchmark version of the task: 1 (Indoor-v1, pf-nn's v1 fit) or 0 (the frozen Indoor-v0)."""

    def run(self) -> int:
        from swarmloc.bench.reproduce.pfnn import reproduce_pfnn

        return print_report(lambda: reproduce_pfnn(self.out, self.seeds, self.duration, self.timing_steps,
                                                   self.oracle, version=self.version))


@dataclass
class Immarkf:
    """imm-arkf Table 2 on HybridNoise{10,30,50} (IMM-ARKF vs IMM-KF vs IMM-EKF), beside the paper's numbers."""

    out: Path = Path("immarkf.md")
    """Markdown file to write (a folder: <out>/immarkf.md); raw numbers go beside it as .json."""
    seeds: int = 16
    """Test seeds per task (1_000_000 …), at least 2."""
    duration: float | None = None
    """Episode length [s] (default: the tasks' 60 s)."""
    version: int = 1
    """Benchmark version of the tasks: 1 (contamination mixture) or 0 (the frozen v0, eq. 1 as printed)."""

    def run(self) -> int:
        from swarmloc.bench.reproduce.immarkf import reproduce_immarkf

        return print_report(lambda: reproduce_immarkf(self.out, self.seeds, self.duration, self.version))


@dataclass
class Federated:
    """federated Tables 2–3 on GradualFault (Scheme 1, Scheme 2, the adaptive federated filter)."""

    out: Path = Path("federated.md")
    """Markdown file to write (a folder: <out>/federated.md); raw numbers go beside it as .json."""
    seeds: int = 16
    """Test seeds (1_000_000 …), at least 2."""
    version: int = 1
    """Benchmark version of the task: 1 (GradualFault-v1) or 0 (the frozen GradualFault-v0)."""

    def run(self) -> int:
        from swarmloc.bench.reproduce.federated import reproduce_federated

        return print_report(lambda: reproduce_federated(self.out, self.seeds, self.version))


@dataclass
class Dtvirm:
    """dtvirm Tables 1, 5, 6: MDS-MAP initialization and the CI-EKF on AnchorFree-v0."""

    out: Path = Path("dtvirm.md")
    """Markdown file to write (a folder: <out>/dtvirm.md); raw numbers go beside it as .json."""
    seeds: int = 16
    """AnchorFree-v0 test seeds (1_000_000 …), at least 2."""
    trials: int = 200
    """Monte Carlo trials of the Table 1 initializer comparison (the paper: 500)."""

    def run(self) -> int:
        from swarmloc.bench.reproduce.dtvirm import reproduce_dtvirm

        return print_report(lambda: reproduce_dtvirm(self.out, self.seeds, self.trials))


@dataclass
class Real:
    """The sim-to-real report: every method on real-v1 (UTIL TWR + 8 TDOA flights) and on TDOA-v1."""

    out: Path = Path("real.md")
    """Markdown file to write (a folder: <out>/real.md); raw numbers beside it as .json, the plot as .png."""
    workers: int = 2
    """Worker processes."""
    seeds: int = 4
    """Test seeds per task, 1 … 4 (the suite's 4)."""
    methods: tuple[str, ...] = ()
    """Methods (default: every registered one)."""

    def run(self) -> int:
        """Without the data, says where it comes from (exit status 2)."""
        from swarmloc.bench.reproduce.real import reproduce_real

        return print_report(lambda: reproduce_real(self.out, list(self.methods) or None, workers=self.workers,
                                                   seeds=self.seeds))


@dataclass
class NlosFit:
    """The Gauss–Markov NLOS process fitted to the UTIL residual statistics (TWR and TDOA obstacle flights):
    share of biased samples, their magnitudes, biased-run durations and autocorrelation, real beside simulated."""

    out: Path = Path("nlos-fit.md")
    """Markdown file to write (a folder: <out>/nlos-fit.md); the numbers go beside it as .json."""
    max_evaluations: int = 300
    """Objective evaluations of the Nelder–Mead fit per data set (each simulates every flight once)."""

    def run(self) -> int:
        """Without the data, says where it comes from (exit status 2)."""
        from swarmloc.bench.reproduce.nlos_fit import reproduce_nlos_fit

        return print_report(lambda: reproduce_nlos_fit(self.out, max_evaluations=self.max_evaluations))


@dataclass
class Labels:
    """Calibrate the error labels: the oracle at k = 1 … 3 on every standard-v0 task, beside the best
    shipped method and the information bound."""

    out: Path = Path("docs/reproduce/labels.md")
    """Markdown file to write (a folder: <out>/labels.md); raw numbers go beside it as .json."""
    workers: int = 2
    """Worker processes of the runner (1 … 64)."""
    seeds: int = 32
    """Test seeds per task, the first of standard-v0's 32 (2 … 32; the shipped results are compared per seed)."""
    progress: bool = True
    """Show the runner's progress bars."""

    def run(self) -> int:
        from swarmloc.bench.reproduce.labels import reproduce_labels

        return print_report(lambda: reproduce_labels(self.out, workers=self.workers, seeds=self.seeds,
                                                     progress=self.progress))


@dataclass
class Calibration:
    """Calibrate the tasks. --version 1: per v1 task the five criteria (ceiling valid, the fault matters, headroom,
    the paper's phenomenon, nothing degenerate), the split comparison and the gap closed. --version 2: the admission
    criteria of every v2 task on dev seeds (which tasks enter each track's headline)."""

    version: int = 1
    """Benchmark version: 1 (the suite's v1 tasks) or 2 (the v2 tasks, dev seeds, docs/calibration-v2.*)."""
    suite: str = "standard-v1"
    """--version 1: suite whose tasks are calibrated (see docs/suites.md)."""
    tasks: str | None = None
    """Only these tasks, comma-separated IDs (the `swarmloc/` prefix may be omitted)."""
    seeds: int | None = None
    """The first this many seeds of each task, at least 2 (default: all of the suite's; --version 2: 8 dev seeds)."""
    out_md: Path | None = None
    """Markdown report to write (default docs/calibration.md, --version 2: docs/calibration-v2.md)."""
    out_json: Path | None = None
    """The report's numbers, machine-readable (default docs/calibration.json, --version 2: docs/calibration-v2.json)."""
    workers: int = 1
    """Worker processes of the runner (1 … 64)."""
    progress: bool = True
    """Show the runner's progress bar."""

    def command_line(self) -> str:
        """The command that reproduces the report: ``swarmloc reproduce calibration`` and its non-default options."""
        words = ["swarmloc", "reproduce", "calibration"]
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name not in ("workers", "progress") and value != f.default:
                words += [f"--{f.name.replace('_', '-')}", str(value)]
        return shlex.join(words)

    def run(self) -> int:
        if self.version not in (1, 2):
            raise SystemExit(f"--version {self.version}: the calibrated benchmark versions are 1 and 2")
        suffix = "" if self.version == 1 else "-v2"
        out_md = self.out_md or Path(f"docs/calibration{suffix}.md")
        out_json = self.out_json or Path(f"docs/calibration{suffix}.json")

        def write() -> Path:
            if self.version == 2:
                from swarmloc.bench.reproduce.calibration_v2 import DEFAULT_SEEDS, reproduce_calibration_v2

                tasks = [t.strip() for t in self.tasks.split(",")] if self.tasks else None
                reproduce_calibration_v2(out_md, out_json, tasks=tasks, seeds=self.seeds or DEFAULT_SEEDS,
                                         workers=self.workers, progress=self.progress, command=self.command_line())
            else:
                from swarmloc.bench.reproduce.calibration import reproduce_calibration

                reproduce_calibration(self.suite, self.tasks, self.seeds, out_md, out_json, workers=self.workers,
                                      progress=self.progress, command=self.command_line())
            return out_md

        return print_report(write)


@dataclass
class PeerUpdate:
    """The CEKF's peer update as registered (a known point, madrl §2.3) against covariance intersection, on
    the standard-v1 tasks with peer channels: oracle ceiling, fault size and gate lock-outs under each."""

    out: Path = Path("peer-update.md")
    """Markdown file to write (a folder: <out>/peer-update.md); raw numbers go beside it as .json."""
    seeds: int = 32
    """Test seeds per task (1_000_000 …), at least 2."""
    tasks: list[str] = field(default_factory=list)
    """Task IDs (default: every standard-v1 task with peer channels)."""
    variants: bool = True
    """Also measure the spec variants a consistent filter could start from (Scale with anchors ranged
    within 11 m, HybridNoise without peers); not registered tasks."""

    def run(self) -> int:
        from swarmloc.bench.reproduce.peer_update import reproduce_peer_update

        return print_report(lambda: reproduce_peer_update(self.out, self.seeds, self.tasks or None,
                                                          variants=self.variants))


@dataclass
class Consistency:
    """Is the cooperative filter consistent, and does cooperating pay? Uniform's position NEES and RMSE under each
    peer update (point, ci, split_ci) beside non-cooperative's RMSE, one task per simulated family with its faults
    on and removed, and Scale N = 2 … 32 fault-free, on dev seeds."""

    out: Path = Path("consistency.md")
    """Markdown file to write (a folder: <out>/consistency.md); the rows go beside it as .json."""
    seeds: int = 8
    """Dev seeds per task (2_000_000 …), at least 2."""
    tasks: list[str] = field(default_factory=list)
    """Task IDs (default: one task per simulated family, swarmloc.bench.reproduce.consistency.FAMILY_TASKS)."""
    scale: bool = True
    """Also the Scale family's sizes N = 2 … 32 with the faults removed."""

    def run(self) -> int:
        from swarmloc.bench.reproduce.consistency import reproduce_consistency

        return print_report(lambda: reproduce_consistency(self.out, self.seeds, self.tasks or None, scale=self.scale))


@dataclass
class Shipped:
    """Regenerate the shipped reference results of a suite (bench/results/<suite>/<method>.json)."""

    methods: tuple[str, ...] = ()
    """Methods, or training runs ``<method>.seed<k>``, to re-evaluate (default: every shipped file of the suite)."""
    suite: str = "standard-v2"
    """standard-v2 (the default board), standard-v1 or standard-v0."""
    workers: int = 2
    """Worker processes."""
    bounds_only: bool = False
    """Recompute only the information bound (bound_rmse, and the aggregates and score that read it) of every
    shipped file of the suite with the current bound; every other number stays as evaluated."""

    def run(self) -> int:
        from swarmloc.bench.evaluation.shipped import RESULTS_DIRS, refresh_bounds, regenerate, shipped_results

        if self.suite not in RESULTS_DIRS:
            print(f"error: suite {self.suite!r} has no shipped results; allowed: {', '.join(RESULTS_DIRS)}")
            return 2
        if self.bounds_only:
            for path in refresh_bounds(self.suite):
                print(f"rewrote {path}")
            return 0
        methods = list(self.methods) or [path.stem for path in shipped_results(RESULTS_DIRS[self.suite])]
        for path in regenerate(methods, self.suite, workers=self.workers):
            print(f"wrote {path}")
        return 0
