"""Paper reproductions: one module per ``swarmloc reproduce`` command, each writing a report."""
