"""``python -m swarmloc.bench.speed [--json PATH] [--quick]``: the same as ``swarmloc bench speed``."""

import sys

from swarmloc.bench.cli import main

sys.exit(main(["bench", "speed", *sys.argv[1:]]))
