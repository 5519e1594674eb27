"""A command module for tests/test_cli.py: a plugin that follows the CLI convention."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class Options:
    """Say hello."""

    times: int = 1
    """How many times."""


def run(opts: Options) -> int:
    print("hello\n" * opts.times, end="")
    return 3
