"""``swarmloc train supervised-trust``: fit the per-channel error-label classifier on training seeds (no RL).

The fit lives in ``swarmloc.agents.trust.supervised_fit`` (agents may not import bench); this glue
adds what needs the bench: every training and held-out seed is checked with
``check_training_seeds`` (test and dev seeds are refused), and the weights are written with their
record beside them (``<weights>.json``: the command that reproduces them, provenance, the fit's
settings, data size and label rate per task, training losses, held-out AUC / average precision /
precision-recall against the NIS alone, the weights' SHA-256).

The fixed budget of the shipped weights (the defaults): ``ScaleRandom-v2`` seeds 0–15 and
``AnchorNLOSRandom-v2`` seeds 0–63 (one UAV, so four times the episodes), 400 steps each, uniform
trust; held out: seeds 900000–900007 and 900000–900031 of the same tasks; 12 Adam epochs.

    swarmloc train supervised-trust                          # the shipped agents/weights/supervised_trust.npz
    swarmloc train supervised-trust --episodes 2 --steps 20 --weights-out /tmp/st.npz
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

from swarmloc.agents.registry import WEIGHTS_DIR
from swarmloc.bench.training.weights_file import write_npz_with_record
from swarmloc.envs.tasks.seeds import check_training_seeds

#: the shipped weights (``swarmloc.agents.trust.supervised.WEIGHTS_PATH``)
WEIGHTS_PATH = WEIGHTS_DIR / "supervised_trust.npz"
#: the training tasks (the v2 randomized families of the two tracks' ranging tasks)
TASKS = ("swarmloc/ScaleRandom-v2", "swarmloc/AnchorNLOSRandom-v2")
#: episodes of each task per ``--episodes`` (AnchorNLOS flies one UAV: four times the episodes)
EPISODE_FACTOR = (1, 4)
#: first held-out seed (training range, far from the training seeds)
HELDOUT_SEED_START = 900_000


@dataclass
class TrainSupervisedTrustArgs:
    """Fit the supervised-trust classifier on the v2 randomized families (training seeds; no RL)."""

    episodes: int = 16
    """Training episodes of ScaleRandom-v2 (seeds seed_start …); AnchorNLOSRandom-v2 gets four times as many."""
    seed_start: int = 0
    """First training seed; every seed must be a training seed (< 1_000_000)."""
    heldout_episodes: int = 8
    """Held-out episodes of ScaleRandom-v2 from seed 900000 (four times as many of AnchorNLOSRandom-v2)."""
    steps: int | None = None
    """Filter steps per episode (default: the task's, 400)."""
    epochs: int = 12
    """Adam passes over the pooled frames."""
    hidden: int = 32
    """Hidden units of both layers."""
    lr: float = 3e-3
    """Adam learning rate."""
    torch_seed: int = 0
    """Seed of the initialisation and the minibatch order."""
    weights_out: Path = WEIGHTS_PATH
    """Where to write the weights (.npz); the record goes to the same path with .json."""

    def command(self) -> str:
        """The ``swarmloc train supervised-trust`` command line that reproduces these weights."""
        parts = ["swarmloc train supervised-trust", f"--episodes {self.episodes}", f"--seed-start {self.seed_start}",
                 f"--heldout-episodes {self.heldout_episodes}"]
        if self.steps is not None:
            parts.append(f"--steps {self.steps}")
        parts += [f"--epochs {self.epochs}", f"--hidden {self.hidden}", f"--lr {self.lr:g}",
                  f"--torch-seed {self.torch_seed}"]
        if Path(self.weights_out).resolve() != WEIGHTS_PATH:
            parts.append(f"--weights-out {self.weights_out}")
        return " ".join(parts)


def train_supervised_trust(args: TrainSupervisedTrustArgs, log=print) -> Path:
    """Collect, fit, score on held-out seeds, and write the weights with their record.

    Args:
        args: the command's options.
        log: progress printer.

    Returns:
        The weights path.

    Raises:
        ValueError: a seed outside the training range (test or dev seeds), or bad settings.
    """
    if args.episodes < 1 or args.heldout_episodes < 1:
        raise ValueError(f"episodes={args.episodes} and heldout_episodes={args.heldout_episodes} must be >= 1")
    seeds = tuple(tuple(range(args.seed_start, args.seed_start + args.episodes * f)) for f in EPISODE_FACTOR)
    heldout = tuple(tuple(range(HELDOUT_SEED_START, HELDOUT_SEED_START + args.heldout_episodes * f))
                    for f in EPISODE_FACTOR)
    for group in (*seeds, *heldout):
        check_training_seeds(group)
    for task, train, held in zip(TASKS, seeds, heldout):
        if set(train) & set(held):
            raise ValueError(f"{task}: training seeds {train[0]}…{train[-1]} overlap the held-out seeds "
                             f"{held[0]}…{held[-1]}; choose a seed_start that keeps them apart")
    from swarmloc.agents.trust.supervised import FEATURE_NAMES
    from swarmloc.agents.trust.supervised_fit import FitConfig, fit

    cfg = FitConfig(tasks=TASKS, seeds=seeds, heldout_seeds=heldout, steps=args.steps, hidden=args.hidden,
                    epochs=args.epochs, lr=args.lr, torch_seed=args.torch_seed)
    result = fit(cfg, log=log)
    out = Path(args.weights_out)
    # the ranges say the same as the fit's seed lists in two numbers per task
    fit_record = {k: v for k, v in asdict(cfg).items() if k not in ("seeds", "heldout_seeds")}
    write_npz_with_record(
        out, result.weights.save, "supervised-trust", args.command(),
        fit={**fit_record, "training_seeds": {t: [s[0], s[-1]] for t, s in zip(TASKS, seeds)},
             "heldout_seeds": {t: [s[0], s[-1]] for t, s in zip(TASKS, heldout)}},
        features=list(FEATURE_NAMES), data=result.data, losses=result.losses, heldout=result.heldout,
        seconds=round(result.seconds, 1),
        note=("Fitted by binary cross-entropy to the error labels (privileged, read while training only) of "
              "uniform-trust rollouts on training seeds; no reward, no RL. At evaluation it reads the "
              "observation only: alpha = 1 - P(error label)."))
    log(f"wrote {out} and {out.with_suffix('.json')}")
    return out
