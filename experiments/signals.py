"""Reference shapes shared by the benches' scenarios (vectorised functions of time)."""

from __future__ import annotations

import numpy as np


def smooth_path(waypoints, segment: float):
    """Raised-cosine moves through ``waypoints``, ``segment`` seconds each.

    Parameters
    ----------
    waypoints : array_like
        The levels passed through, the last one held.
    segment : float
        Duration of each move (s).

    Returns
    -------
    callable
        The reference as a vectorised function of time (s).
    """
    waypoints = np.asarray(waypoints, float)

    def reference(t):
        t = np.asarray(t, float)
        k = np.clip((t // segment).astype(int), 0, len(waypoints) - 2)
        frac = np.clip((t - k * segment) / segment, 0.0, 1.0)
        return waypoints[k] + (waypoints[k + 1] - waypoints[k]) * 0.5 * (1 - np.cos(np.pi * frac))
    return reference


def staircase(levels, dwell: float):
    """Constant ``levels``, ``dwell`` seconds each (the last one held).

    Parameters
    ----------
    levels : array_like
        The levels, in order.
    dwell : float
        Time at each level (s).

    Returns
    -------
    callable
        The reference as a vectorised function of time (s).
    """
    levels = np.asarray(levels, float)

    def reference(t):
        k = np.clip((np.asarray(t, float) // dwell).astype(int), 0, len(levels) - 1)
        return levels[k]
    return reference


def after_approach(core, approach: float):
    """``core(t − approach)`` after a raised-cosine approach from 0 to ``core(0)`` lasting ``approach`` s.

    Parameters
    ----------
    core : callable
        The reference after the approach, a vectorised function of time (s).
    approach : float
        Duration of the approach (s).

    Returns
    -------
    callable
        The reference as a vectorised function of time (s).
    """
    start = float(core(np.zeros(1))[0])

    def reference(t):
        t = np.asarray(t, float)
        ramp = start * 0.5 * (1 - np.cos(np.pi * np.clip(t / approach, 0.0, 1.0)))
        return np.where(t < approach, ramp, core(t - approach))
    return reference


def triangle_wave(mean: float, amplitude: float, period: float):
    """A triangle ``mean ± amplitude`` starting at the mean, rising.

    Parameters
    ----------
    mean, amplitude : float
        Centre and half the peak-to-peak swing.
    period : float
        Period (s).

    Returns
    -------
    callable
        The reference as a vectorised function of time (s).
    """
    def reference(t):
        phase = np.mod(np.asarray(t, float) / period + 0.25, 1.0)
        return mean - amplitude * (4 * np.abs(phase - 0.5) - 1)
    return reference


def square_wave(mean: float, amplitude: float, period: float):
    """A square wave ``mean ± amplitude``, high for the first half of each period.

    Parameters
    ----------
    mean, amplitude : float
        Centre and half the peak-to-peak swing.
    period : float
        Period (s).

    Returns
    -------
    callable
        The reference as a vectorised function of time (s).
    """
    def reference(t):
        return mean + amplitude * np.where(np.mod(np.asarray(t, float), period) < period / 2, 1.0, -1.0)
    return reference
