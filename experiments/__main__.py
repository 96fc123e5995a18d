"""``python -m experiments`` is ``hystmpc``."""

from hystmpc.experiments.cli import entry_point

entry_point()
