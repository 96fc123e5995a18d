"""Benches, scenarios, baseline controllers, the runner, reports and the ``hystmpc`` CLI."""
