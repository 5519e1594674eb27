"""``swarmloc reproduce immarkf | federated | dtvirm`` (registered into the ``reproduce`` group).

Imported by ``swarmloc.bench.cli_commands``; the heavy module ``bench/reproduce_papers.py``
is imported inside the handlers so that ``swarmloc --help`` stays fast.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from swarmloc.bench.cli_commands import register_subcommand


@dataclass
class ReproduceImmArkfArgs:
    """imm-arkf Table 2 on HybridNoise{10,30,50}-v0 (IMM-ARKF vs IMM-KF vs IMM-EKF), beside the paper's numbers."""

    out: Path = Path("immarkf.md")
    """Markdown file to write (a folder: <out>/immarkf.md); raw numbers go beside it as .json."""
    seeds: int = 16
    """Test seeds per task (1_000_000 …), at least 2."""
    duration: float | None = None
    """Episode length [s] (default: the tasks' 60 s)."""


@dataclass
class ReproduceFederatedArgs:
    """federated Tables 2–3 on GradualFault-v0 (Scheme 1, Scheme 2, the adaptive federated filter)."""

    out: Path = Path("federated.md")
    """Markdown file to write (a folder: <out>/federated.md); raw numbers go beside it as .json."""
    seeds: int = 16
    """Test seeds (1_000_000 …), at least 2."""


@dataclass
class ReproduceDtvirmArgs:
    """dtvirm Tables 1, 5, 6: MDS-MAP initialization and the CI-EKF on AnchorFree-v0."""

    out: Path = Path("dtvirm.md")
    """Markdown file to write (a folder: <out>/dtvirm.md); raw numbers go beside it as .json."""
    seeds: int = 16
    """AnchorFree-v0 test seeds (1_000_000 …), at least 2."""
    trials: int = 200
    """Monte Carlo trials of the Table 1 initializer comparison (the paper: 500)."""


def _report(path: Path) -> int:
    print(path.read_text())
    return 0


def run_immarkf(cfg: ReproduceImmArkfArgs) -> int:
    """``swarmloc reproduce immarkf``."""
    from swarmloc.bench.reproduce_papers import reproduce_immarkf

    try:
        return _report(reproduce_immarkf(cfg.out, cfg.seeds, cfg.duration))
    except ValueError as err:
        print(f"error: {err}")
        return 2


def run_federated(cfg: ReproduceFederatedArgs) -> int:
    """``swarmloc reproduce federated``."""
    from swarmloc.bench.reproduce_papers import reproduce_federated

    try:
        return _report(reproduce_federated(cfg.out, cfg.seeds))
    except ValueError as err:
        print(f"error: {err}")
        return 2


def run_dtvirm(cfg: ReproduceDtvirmArgs) -> int:
    """``swarmloc reproduce dtvirm``."""
    from swarmloc.bench.reproduce_papers import reproduce_dtvirm

    try:
        return _report(reproduce_dtvirm(cfg.out, cfg.seeds, cfg.trials))
    except ValueError as err:
        print(f"error: {err}")
        return 2


register_subcommand("reproduce", "immarkf", ReproduceImmArkfArgs, run_immarkf,
                    "imm-arkf Table 2 on HybridNoise{10,30,50}-v0.")
register_subcommand("reproduce", "federated", ReproduceFederatedArgs, run_federated,
                    "federated Tables 2-3 on GradualFault-v0.")
register_subcommand("reproduce", "dtvirm", ReproduceDtvirmArgs, run_dtvirm,
                    "dtvirm Tables 1, 5, 6 (MDS-MAP, CI-EKF on AnchorFree-v0).")
