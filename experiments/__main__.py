"""``python -m experiments`` is ``hystmpc``."""

from experiments.cli import entry_point

entry_point()
