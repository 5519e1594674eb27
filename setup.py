"""Package layout: the four rooms install as subpackages of the ``swarmloc`` namespace.

``swarmloc.envs`` → ``envs/``, ``swarmloc.agents`` → ``agents/``, ``swarmloc.bench`` →
``bench/``, ``swarmloc.leaderboard`` → ``leaderboard/``; their subpackages are discovered
so a new folder with an ``__init__.py`` is never left out of a wheel. Everything else
lives in pyproject.toml.
"""

from setuptools import find_packages, setup

ROOMS = ("envs", "agents", "bench", "leaderboard")

packages = []
package_dir = {}
for room in ROOMS:
    packages.append(f"swarmloc.{room}")
    package_dir[f"swarmloc.{room}"] = room
    packages.extend(f"swarmloc.{room}.{sub}" for sub in find_packages(room))

setup(packages=packages, package_dir=package_dir)
