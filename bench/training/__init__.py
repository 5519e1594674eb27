"""Training glue: the bench's seed checks and evaluation around the algorithms in ``swarmloc.agents``."""
