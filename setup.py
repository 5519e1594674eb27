"""Package layout: the five rooms install as subpackages of the ``swarmloc`` namespace.

``swarmloc.envs`` → ``envs/``, ``swarmloc.agents`` → ``agents/``, ``swarmloc.bench`` →
``bench/``, ``swarmloc.leaderboard`` → ``leaderboard/``, ``swarmloc.cli`` → ``cli/``
(docs/architecture.md); their subpackages are discovered
so a new folder with an ``__init__.py`` is never left out of a wheel (``tests/test_packaging.py``
fails on a code folder without one). Everything else lives in pyproject.toml.
"""

import shutil
import warnings
from pathlib import Path

from setuptools import find_packages, setup
from setuptools.command.build_py import build_py
from setuptools.warnings import InformationOnly

# The rooms are not under one ``swarmloc/`` folder, so an editable install maps them with a
# meta path finder, and setuptools tells every ``pip install -e .`` (pip shows it even with
# -q) to beware of a working-directory folder named like the package. There is none here:
# that note is not ours to print.
warnings.filterwarnings("ignore", message="Editable installation", category=InformationOnly)

ROOMS = ("envs", "agents", "bench", "leaderboard", "cli")


class FreshBuildPy(build_py):
    """``build_py`` into an emptied folder: setuptools reuses ``build/lib`` between builds of a
    checkout and ships all of it, so a module deleted since the last build would stay in the wheel."""

    def run(self) -> None:
        shutil.rmtree(Path(self.build_lib) / "swarmloc", ignore_errors=True)
        super().run()


packages = []
package_dir = {}
for room in ROOMS:
    packages.append(f"swarmloc.{room}")
    package_dir[f"swarmloc.{room}"] = room
    packages.extend(f"swarmloc.{room}.{sub}" for sub in find_packages(room))

setup(packages=packages, package_dir=package_dir, cmdclass={"build_py": FreshBuildPy})
