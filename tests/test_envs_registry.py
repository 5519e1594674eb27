"""Registration, task classes and their docs: registry == catalogue, sections, docs pages, errors."""

from __future__ import annotations

import doctest
import inspect
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import pytest

import swarmloc.envs
from swarmloc.envs.tasks.docgen import task_pages
from swarmloc.envs.adapters.gym_env import SwarmLocEnv
from swarmloc.envs.tasks.docs import SECTIONS
from swarmloc.envs.adapters.task_envs import TASK_CLASSES
from swarmloc.envs.tasks.catalogue import CATALOGUE

REPO = Path(__file__).resolve().parents[1]
REGISTERED = sorted(i for i in gym.registry if i.startswith("swarmloc/"))


def test_registry_equals_catalogue_and_task_classes():
    assert REGISTERED == sorted(CATALOGUE)
    assert sorted(TASK_CLASSES) == sorted(CATALOGUE)
    assert set(swarmloc.envs.TASK_IDS) == set(CATALOGUE)


@pytest.mark.parametrize("task_id", sorted(CATALOGUE))
def test_registration_is_declarative(task_id):
    env_spec = gym.spec(task_id)
    assert isinstance(env_spec.entry_point, str) and isinstance(env_spec.vector_entry_point, str)
    module, name = env_spec.entry_point.split(":")
    assert getattr(__import__(module, fromlist=[name]), name) is TASK_CLASSES[task_id]
    assert env_spec.max_episode_steps == CATALOGUE[task_id]().n_steps
    assert env_spec.kwargs == {"task_id": task_id}


@pytest.mark.parametrize("task_id", sorted(CATALOGUE))
def test_class_docstring_has_every_section(task_id):
    doc = inspect.cleandoc(TASK_CLASSES[task_id].__doc__)
    for section in SECTIONS:
        assert f"## {section}\n" in doc, f"{task_id}: missing section {section}"
    assert "| Num | Observation | Min | Max |" in doc
    assert "Termination" in doc and "Truncation" in doc
    assert ">>> " in doc and "| Argument |" in doc


@pytest.mark.parametrize("task_id", ["swarmloc/NLOS-v0", "swarmloc/GradualFault-v0"])
def test_docstring_doctest_runs(task_id):
    cls = TASK_CLASSES[task_id]
    finder, runner = doctest.DocTestFinder(), doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    for test in finder.find(cls, cls.__name__, globs={}):
        if test.docstring is cls.__doc__:
            runner.run(test)
    assert runner.summarize(verbose=False).failed == 0


def test_generated_docs_are_committed_and_current():
    pages = task_pages()
    assert len(pages) == len(CATALOGUE) + 1
    for name, text in pages.items():
        path = REPO / "docs" / "tasks" / name
        assert path.exists(), f"{path} missing: run swarmloc docs tasks"
        assert path.read_text(encoding="utf-8") == text, f"{path} is stale: run swarmloc docs tasks"


def test_fresh_interpreter_make_with_module_prefix_and_cheap_import():
    code = (
        "import sys, gymnasium as gym\n"
        "env = gym.make('swarmloc.envs:swarmloc/NLOS-v0', duration=1.0)\n"
        "obs, info = env.reset(seed=0)\n"
        "assert obs.shape == (4, 11, 11), obs.shape\n"
        "env2 = gym.make('swarmloc/Ideal-v0')\n"
        "print('ok')\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    cheap = "import sys, swarmloc.envs\nprint(sorted(m for m in ('numba', 'torch') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", cheap], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]", "registration must not import numba or torch"


def test_unknown_task_ids_list_the_known_ones():
    for factory in (swarmloc.envs.parallel_env, swarmloc.envs.make):
        with pytest.raises(ValueError, match="known: .*swarmloc/NLOS-v0"):
            factory("swarmloc/Nope-v0")
    with pytest.raises(ValueError, match="known: .*swarmloc/Ideal-v0"):
        swarmloc.envs.torchrl_env("Nope-v0", 2)
    with pytest.raises(ValueError, match="known: .*swarmloc/Ideal-v0"):
        SwarmLocEnv("swarmloc/Nope-v0")


def test_bad_overrides_are_named():
    with pytest.raises(TypeError, match="durration"):
        gym.make("swarmloc/NLOS-v0", durration=5.0)
    with pytest.raises(Exception, match="duration"):
        gym.make("swarmloc/NLOS-v0", duration=-1.0)
    with pytest.raises(ValueError, match="policy_flops"):
        gym.make("swarmloc/NLOS-v0", policy_flops=float("nan"))
    with pytest.raises(ValueError, match="NLOSEnv is task"):
        gym.make("swarmloc/NLOS-v0", task_id="swarmloc/Ideal-v0")
