"""Ceilings on the work one command may start, checked before anything runs.

A horizon of ten thousand samples, a run of a billion samples or a sweep of a billion runs is
almost always a typing error, and would otherwise run for hours or exhaust the memory before
saying anything. Beyond a ceiling the command line exits 2 naming the limit; ``--force``
lifts every ceiling (the values stay validated: a duration must still be finite).
"""

from __future__ import annotations

import math
from typing import Any

MAX_HORIZON = 200
"""Prediction horizon (samples). The NMPC's problem grows with it; 200 is five times the
longest horizon any bench uses."""
MAX_RUN_SAMPLES = 1_000_000
"""Samples in one run (about 80 MB of trajectories and 3 min at reluctance's 5 kHz)."""
MAX_SWEEP_RUNS = 10_000
"""Runs in one sweep."""
MAX_SWEEP_SAMPLES = 20_000_000
"""Samples summed over every run of a sweep."""

FORCE_HINT = "pass --force to run it anyway"


class WorkLimitError(ValueError):
    """A command would start more work than a ceiling allows."""


def run_samples(duration: float, sample_period: float, what: str = "--duration") -> int:
    """Samples in a run of ``duration`` seconds; ``ValueError`` unless finite and at least 2.

    Parameters
    ----------
    duration : float
        Length of the run (s), finite and positive.
    sample_period : float
        Sample period (s).
    what : str, optional
        Name of the value in the error message.

    Returns
    -------
    int
        ``round(duration / sample_period)``.
    """
    if not (isinstance(duration, (int, float)) and math.isfinite(duration) and duration > 0):
        raise ValueError(f"{what} must be a finite number of seconds > 0, got {duration}")
    n = int(round(duration / sample_period))
    if n < 2:
        raise ValueError(f"{what} {duration:g} s is shorter than 2 samples at {sample_period:g} s; "
                         f"allowed: >= {2 * sample_period:g} s")
    return n


def check_run_samples(n: int, what: str, force: bool) -> None:
    """``WorkLimitError`` for a run longer than :data:`MAX_RUN_SAMPLES` (unless ``force``).

    Parameters
    ----------
    n : int
        Samples in the run.
    what : str
        What needs them, for the error message.
    force : bool
        Lift the ceiling.
    """
    if n > MAX_RUN_SAMPLES and not force:
        raise WorkLimitError(f"{what} needs {n:,} samples, above the limit of {MAX_RUN_SAMPLES:,} per run; "
                             f"{FORCE_HINT}")


def check_horizons(config: dict[str, Any], force: bool) -> None:
    """``WorkLimitError`` naming a group's ``horizon`` above :data:`MAX_HORIZON` (unless ``force``).

    Parameters
    ----------
    config : dict
        Parameter groups by name; a group with an integer ``horizon`` attribute is checked.
    force : bool
        Lift the ceiling.
    """
    if force:
        return
    for group, settings in config.items():
        horizon = getattr(settings, "horizon", None)
        if isinstance(horizon, int) and horizon > MAX_HORIZON:
            raise WorkLimitError(f"{group}.horizon={horizon} is above the limit of {MAX_HORIZON} samples; "
                                 f"{FORCE_HINT}")


def check_sweep(n_runs: int, total_samples: int, force: bool) -> None:
    """``WorkLimitError`` for a sweep above the limits on runs or samples (unless ``force``).

    The limits are :data:`MAX_SWEEP_RUNS` runs and :data:`MAX_SWEEP_SAMPLES` samples in all.

    Parameters
    ----------
    n_runs : int
        Runs in the sweep.
    total_samples : int
        Samples summed over its runs.
    force : bool
        Lift the ceilings.
    """
    if force:
        return
    if n_runs > MAX_SWEEP_RUNS:
        raise WorkLimitError(f"the sweep has {n_runs:,} runs, above the limit of {MAX_SWEEP_RUNS:,}; {FORCE_HINT}")
    if total_samples > MAX_SWEEP_SAMPLES:
        raise WorkLimitError(f"the sweep's runs add up to {total_samples:,} samples, above the limit of "
                             f"{MAX_SWEEP_SAMPLES:,}; {FORCE_HINT}")
