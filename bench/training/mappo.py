"""``swarmloc train mappo``: the MAPPO training script with the bench's seeds and evaluation.

The algorithm lives in ``swarmloc.agents.mappo.train`` (agents may not import bench); this
glue adds what needs the bench: training episode seeds are checked with
``check_training_seeds`` (test and dev seeds are refused), the periodic evaluation runs
the smoothed policy on **dev** seeds through the runner, and the weights are written as
a plain actor state_dict with a provenance record beside it (``<weights>.json``: the
exact command, frames, wall time, git commit, config, final dev metrics).

    swarmloc train mappo --frames 2000000 --seed 1 --weights-out agents/weights/mappo.pt
    swarmloc train mappo --frames 400 --tasks CascadedFault-v0 --run-dir /tmp/run
"""

from __future__ import annotations

import json
import os
import shlex
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from swarmloc.agents.mappo.config import MappoConfig, SetGruConfig
from swarmloc.bench.common.files import atomic_path, write_text_atomic
from swarmloc.bench.common.provenance import source_commit
from swarmloc.envs.tasks.seeds import DEV_SEED_START, check_training_seeds

#: tasks and metric of the periodic dev evaluation (the issue-5 targets' metrics)
EVAL_TASKS: dict[str, str] = {
    "swarmloc/CascadedFault-v0": "healthy_rmse",
    "swarmloc/NLOS-v0": "fault_rmse",
    "swarmloc/Scale8-v0": "rmse",
    "swarmloc/Ideal-v0": "rmse",
}

#: the same for a run on v1 tasks (the randomized families' in-distribution tasks)
EVAL_TASKS_V1: dict[str, str] = {
    "swarmloc/CascadedFaultRandom-v1": "healthy_rmse",
    "swarmloc/NLOSRandom-v1": "rmse",
    "swarmloc/ScaleRandom-v1": "rmse",
    "swarmloc/HybridNoiseRandom-v1": "rmse",
}

#: the same for a run on v2 tasks (the admitted v2 families' randomized tasks, scored UAVs)
EVAL_TASKS_V2: dict[str, str] = {
    "swarmloc/ScaleRandom-v2": "rmse",
    "swarmloc/GradualFaultRandom-v2": "rmse",
    "swarmloc/AnchorNLOSRandom-v2": "rmse",
}


def eval_tasks(training_tasks) -> dict[str, str]:
    """The dev-evaluation tasks of a run: those of the oldest benchmark version among its training tasks."""
    from swarmloc.envs.tasks.catalogue import get_spec

    return {0: EVAL_TASKS, 1: EVAL_TASKS_V1, 2: EVAL_TASKS_V2}[min(get_spec(t).version for t in training_tasks)]


@dataclass
class TrainMappoArgs(MappoConfig):
    """Train MAPPO link trust on a task mixture (training seeds only; dev-seed evaluation)."""

    weights_out: str = ""
    """write the trained actor's state_dict here (+ ``.json`` provenance); default ``<run_dir>/mappo.pt``"""
    eval_seeds: int = 4
    """dev seeds per evaluation task (0 = no periodic evaluation)"""


@dataclass
class TrainSetGruArgs(SetGruConfig):
    """Train the set + GRU link-trust actor with recurrent MAPPO (training seeds only; dev-seed evaluation)."""

    weights_out: str = ""
    """write the trained actor's state_dict here (+ ``.json`` provenance); default ``<run_dir>/mappo_set_gru.pt``"""
    eval_seeds: int = 4
    """dev seeds per evaluation task (0 = no periodic evaluation)"""


def command_line() -> str:
    """The command that is running, as a user would type it."""
    return " ".join([Path(sys.argv[0]).name, *(shlex.quote(a) for a in sys.argv[1:])])


#: the code a MAPPO training run depends on (its provenance is "dirty" if any of it changed)
TRAINING_CODE = ("envs", "agents/mappo/train.py", "agents/mappo/config.py", "agents/mappo/nets.py", "agents/mappo/policy.py",
                 "agents/mappo/collect.py", "agents/mappo/set_gru.py", "agents/mappo/set_gru_policy.py", "agents/trust/smoothing.py",
                 "bench/training/mappo.py")


def dev_evaluator(n_seeds: int, tasks: dict[str, str] = EVAL_TASKS, method_name: str = "mappo",
                  smoothed: bool = True):
    """An ``evaluate(policy)`` callback: the policy, as it executes, on ``n_seeds`` dev seeds of ``tasks``.

    ``tasks`` maps each task to the metric it reports.

    ``smoothed``: wrap it in the adaptive Markov smoothing, as ``mappo`` executes (``mappo-set-gru``
    executes unsmoothed).

    Returns a function mapping an unsmoothed policy (``MappoPolicy`` or ``SetGruPolicy``) to
    ``{"<Task>/<metric>": value, "<Task>/<metric>_vs_uniform": ratio}`` (means over seeds).
    """
    from swarmloc.agents.registry import LoadedMethod, load_method
    from swarmloc.agents.trust.smoothing import BETA_MAX, SMOOTHING_GAMMA, MarkovSmoothing
    from swarmloc.bench.evaluation.runner import rollout
    from swarmloc.envs.tasks.catalogue import get_spec

    seeds = list(range(DEV_SEED_START, DEV_SEED_START + n_seeds))
    uniform: dict[str, float] = {}

    def evaluate(policy) -> dict[str, float]:
        method = MarkovSmoothing(policy, BETA_MAX, SMOOTHING_GAMMA) if smoothed else policy
        loaded = LoadedMethod(name=method_name, entry_point="(training snapshot)", track="A",
                              privileged=False, deterministic=True, method=method)
        out: dict[str, float] = {}
        for task, metric in tasks.items():
            spec = get_spec(task)
            name = task.removeprefix("swarmloc/")
            values = [m[metric] for m in rollout(loaded, spec, seeds)[0]]
            value = float(np.mean([v for v in values if v is not None]))
            if task not in uniform:
                base = [m[metric] for m in rollout(load_method("uniform"), spec, seeds)[0]]
                uniform[task] = float(np.mean([v for v in base if v is not None]))
            out[f"{name}/{metric}"] = value
            out[f"{name}/{metric}_vs_uniform"] = value / max(uniform[task], 1e-9)
        return out

    return evaluate


def train_mappo(config: TrainMappoArgs | TrainSetGruArgs) -> Path:
    """Train MAPPO link trust and write the weights and their provenance record.

    Args:
        config: a ``TrainMappoArgs`` (the paper's per-channel actor) or a ``TrainSetGruArgs``
            (the set + GRU actor), each with ``weights_out`` and ``eval_seeds``.

    Returns:
        The path of the written weights (a plain ``ChannelActor`` or ``SetGruActor`` state_dict).

    Raises:
        ValueError: the run's seed or any episode seed is not a training seed.
    """
    import torch

    if isinstance(config, SetGruConfig):
        from swarmloc.agents.mappo.set_gru import train

        # the set + GRU actor executes unsmoothed (``agents/mappo/set_gru_policy.py``), the paper's actor smoothed
        method, default_name, smoothed = "mappo-set-gru", "mappo_set_gru.pt", False
    else:
        from swarmloc.agents.mappo.train import train

        method = "mappo-accuracy-only" if config.accuracy_only else "mappo"
        default_name, smoothed = "mappo.pt", True
    check_training_seeds([config.seed])
    evaluate = (dev_evaluator(config.eval_seeds, eval_tasks(config.tasks), method, smoothed)
                if config.eval_seeds > 0 else None)
    started = time.strftime("%Y-%m-%dT%H:%M:%S%z")
    commit = source_commit(TRAINING_CODE)  # before training: the code that runs (HEAD may move while it does)
    result = train(config, evaluate=evaluate, check_seeds=check_training_seeds)
    out = Path(config.weights_out) if config.weights_out else Path(config.run_dir) / default_name
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(out) as tmp:
        torch.save(result.actor_state, tmp)
    record = {
        "method": method,
        "command": command_line(),
        "frames": result.frames,
        "iterations": result.iterations,
        "wall_time_s": round(result.wall_time_s, 1),
        "started": started,
        "git_commit": commit,
        "torch": torch.__version__,
        "machine": f"{os.cpu_count()} CPU(s), {config.threads} thread(s)",
        "episode_seeds": {"count": len(result.episode_seeds), "min": min(result.episode_seeds),
                          "max": max(result.episode_seeds)},
        "dev_eval": result.last_eval,
        "config": {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(config).items()},
    }
    meta = out.with_suffix(".json")
    write_text_atomic(meta, json.dumps(record, indent=2) + "\n")
    print(f"wrote {out} and {meta} ({result.frames} frames in {result.wall_time_s:.0f} s)")
    return out
