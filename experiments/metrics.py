"""Tracking metrics: RMSE, MAE, max error and step-response figures."""

from __future__ import annotations

import numpy as np


def tracking_metrics(reference, output) -> dict[str, float]:
    """RMSE, MAE and max |error| of ``reference − output`` over the whole run."""
    e = np.asarray(reference, float) - np.asarray(output, float)
    return {"rmse": float(np.sqrt(np.mean(e**2))), "mae": float(np.mean(np.abs(e))),
            "max_abs_error": float(np.max(np.abs(e))), "n_samples": int(len(e))}


def step_metrics(t, reference, output, min_step: float) -> dict[str, float] | None:
    """Mean overshoot (%), 2 % settling time (s) and steady-state error over the reference steps.

    A step is a reference jump larger than ``min_step``; each is judged over the first 80 %
    of the time to the next jump (or the run's end): a controller with preview legitimately
    leaves early for the next step, and that must not count as not settled. Settling: the
    last time ``|error| > 2 %`` of the step size, measured from the jump. Steady-state error:
    mean error over the last eighth of the judged window. Returns ``None`` without steps.
    """
    t = np.asarray(t, float)
    r = np.asarray(reference, float)
    y = np.asarray(output, float)
    jumps = np.flatnonzero(np.abs(np.diff(r)) > min_step) + 1
    starts = list(jumps)
    if abs(r[0] - y[0]) > min_step:
        starts = [0, *starts]
    if not starts:
        return None
    overshoot, settling, steady = [], [], []
    for i, s in enumerate(starts):
        end = starts[i + 1] if i + 1 < len(starts) else len(r)
        end = s + max(1, int(0.8 * (end - s)))
        y0 = y[s - 1] if s > 0 else y[0]
        size = r[s] - y0
        seg_y, seg_r, seg_t = y[s:end], r[s:end], t[s:end]
        over = (seg_y - seg_r) * np.sign(size)
        overshoot.append(max(0.0, float(over.max())) / abs(size) * 100)
        outside = np.flatnonzero(np.abs(seg_r - seg_y) > 0.02 * abs(size))
        settling.append(float(seg_t[outside[-1]] - seg_t[0]) + (t[1] - t[0]) if len(outside) else 0.0)
        tail = max(1, len(seg_y) // 8)
        steady.append(float(np.mean(seg_r[-tail:] - seg_y[-tail:])))
    return {"overshoot_pct": float(np.mean(overshoot)), "settling_time_s": float(np.mean(settling)),
            "steady_state_error": float(np.mean(np.abs(steady))), "n_steps": len(starts)}
