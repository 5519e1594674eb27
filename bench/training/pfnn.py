"""``swarmloc train pfnn``: fit the PF-NN weight-correction network offline, on training seeds.

The fit itself lives in ``swarmloc.agents.estimators.pf.train`` (agents may not import bench); this
glue adds what needs the bench: the episode seeds are checked with
``check_training_seeds`` (test and dev seeds are refused), and the weights are written
with their provenance beside them (``<weights>.json``: the exact command that reproduces
them, the git commit, library versions, the fit's settings and losses, the weights'
SHA-256). At evaluation the network is frozen (``pf-nn``); nothing about the test
episodes' truth reaches it.

    swarmloc train pfnn                       # the shipped agents/weights/pfnn.npz
    swarmloc train pfnn --seeds 4 --duration 20 --weights-out /tmp/pfnn.npz
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from swarmloc.agents.registry import WEIGHTS_DIR
from swarmloc.bench.training.weights_file import write_npz_with_record
from swarmloc.envs.tasks.seeds import check_training_seeds

if TYPE_CHECKING:
    from swarmloc.agents.estimators.pf.train import FitConfig, FitResult

#: the shipped weights (``swarmloc.agents.estimators.pf.pfnn.WEIGHTS_PATH``, named here without importing the PF kernels)
WEIGHTS_PATH = WEIGHTS_DIR / "pfnn.npz"


@dataclass
class TrainPfnnArgs:
    """Fit the PF-NN weight-correction network offline on training seeds (frozen at evaluation)."""

    task: str = "swarmloc/Indoor-v0"
    """Task the training episodes come from."""
    seeds: int = 16
    """Number of training episodes (seeds seed_start … seed_start + seeds − 1)."""
    seed_start: int = 0
    """First training seed; every seed must be a training seed (< 1_000_000)."""
    duration: float | None = None
    """Episode length [s] (default: the task's)."""
    rounds: int = 2
    """Collection rounds (round 0 with the plain adaptive PF, later rounds with the network)."""
    epochs: int = 20
    """Adam passes over the pooled samples per round."""
    lr: float = 0.01
    """Learning rate (pf-nn Table 2)."""
    torch_seed: int = 0
    """Seed of the network initialisation and minibatch order."""
    weights_out: Path = WEIGHTS_PATH
    """Where to write the weights (.npz); the provenance goes to the same path with .json."""

    def command(self) -> str:
        """The ``swarmloc train pfnn`` command line that reproduces these weights."""
        parts = ["swarmloc train pfnn", f"--task {self.task}", f"--seeds {self.seeds}",
                 f"--seed-start {self.seed_start}"]
        if self.duration is not None:
            parts.append(f"--duration {self.duration:g}")
        parts += [f"--rounds {self.rounds}", f"--epochs {self.epochs}", f"--lr {self.lr:g}",
                  f"--torch-seed {self.torch_seed}"]
        if Path(self.weights_out).resolve() != WEIGHTS_PATH:
            parts.append(f"--weights-out {self.weights_out}")
        return " ".join(parts)


def write_weights(result: FitResult, args: TrainPfnnArgs, fit: FitConfig) -> Path:
    """Write ``args.weights_out`` (.npz) and its provenance (.json), each atomically."""
    write_npz_with_record(
        Path(args.weights_out), result.weights.save, "pf-nn", args.command(),
        fit={**{k: v for k, v in asdict(fit).items() if k != "filter"}, "seeds": list(fit.seeds),
             "filter": asdict(fit.filter)},
        losses=result.losses, n_samples=result.n_samples, target_mean=result.target_mean,
        seconds=round(result.seconds, 1),
        note=("Fitted offline on training seeds only, target exp(-||p - p_true||) (pf-nn eq. 15); "
              "frozen at evaluation. The paper's online training on ground truth is the separate, "
              "privileged method pf-nn-online-oracle."))
    return Path(args.weights_out)


def train_pfnn(args: TrainPfnnArgs, log=print) -> Path:
    """Fit the network on training seeds and write the weights with their provenance.

    Args:
        args: the command's options.
        log: progress printer.

    Returns:
        The weights path.

    Raises:
        ValueError: a seed outside the training range (test or dev seeds), or bad settings.
    """
    if args.seeds < 1:
        raise ValueError(f"seeds={args.seeds} must be >= 1")
    seeds = tuple(range(args.seed_start, args.seed_start + args.seeds))
    check_training_seeds(seeds)
    from swarmloc.agents.estimators.pf.train import FitConfig, fit_pfnn

    fit = FitConfig(task=args.task, seeds=seeds, duration=args.duration, rounds=args.rounds, epochs=args.epochs,
                    lr=args.lr, torch_seed=args.torch_seed)
    result = fit_pfnn(fit, log=log)
    path = write_weights(result, args, fit)
    log(f"wrote {path} and {path.with_suffix('.json')}")
    return path
