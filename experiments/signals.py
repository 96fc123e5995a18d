"""Reference shapes shared by the benches' scenarios (vectorised functions of time)."""

from __future__ import annotations

import numpy as np


def smooth_path(waypoints, segment: float):
    """Raised-cosine moves through ``waypoints``, ``segment`` seconds each."""
    waypoints = np.asarray(waypoints, float)

    def reference(t):
        t = np.asarray(t, float)
        k = np.clip((t // segment).astype(int), 0, len(waypoints) - 2)
        frac = np.clip((t - k * segment) / segment, 0.0, 1.0)
        return waypoints[k] + (waypoints[k + 1] - waypoints[k]) * 0.5 * (1 - np.cos(np.pi * frac))
    return reference


def staircase(levels, dwell: float):
    """Constant ``levels``, ``dwell`` seconds each (the last one held)."""
    levels = np.asarray(levels, float)

    def reference(t):
        k = np.clip((np.asarray(t, float) // dwell).astype(int), 0, len(levels) - 1)
        return levels[k]
    return reference
