"""Tracking metrics: RMSE, MAE, max error and step-response figures."""

from __future__ import annotations

import numpy as np


def tracking_metrics(reference, output) -> dict[str, float]:
    """RMSE, MAE and max |error| of ``reference − output`` over the whole run.

    Parameters
    ----------
    reference, output : array_like
        Reference and output samples, of the same length.

    Returns
    -------
    dict
        ``rmse``, ``mae``, ``max_abs_error`` (output units) and ``n_samples`` (int).
    """
    e = np.asarray(reference, float) - np.asarray(output, float)
    return {"rmse": float(np.sqrt(np.mean(e**2))), "mae": float(np.mean(np.abs(e))),
            "max_abs_error": float(np.max(np.abs(e))), "n_samples": int(len(e))}


def step_metrics(t, reference, output, min_step: float) -> dict[str, float] | None:
    """Mean overshoot (%), 2 % settling time (s) and steady-state error over the reference steps.

    A step is a reference jump larger than ``min_step``; each is judged over the first 80 %
    of the time to the next jump (or the run's end): a controller with preview legitimately
    leaves early for the next step, and that must not count as not settled. Settling: the
    last time ``|error| > 2 %`` of the step size, measured from the jump. Steady-state error:
    mean error over the last eighth of the judged window. An initial reference-output gap
    larger than ``min_step`` counts as a step at the first sample.

    Parameters
    ----------
    t : array_like
        Sample times (s).
    reference, output : array_like
        Reference and output samples.
    min_step : float
        Smallest reference jump that counts as a step (output units).

    Returns
    -------
    dict or None
        Means over the steps: ``overshoot_pct`` (%), ``settling_time_s`` (s) and
        ``steady_state_error`` (of its absolute value), with ``n_steps``; ``None`` without steps.
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


OSCILLATION_THRESHOLD = 0.02
"""A swing of the output counts when it reverses by more than this share of the reference's
span (or of the output's, for a constant reference, but never less than
:data:`NOISE_FLOOR` times the output's estimated noise)."""
NOISE_FLOOR = 8.0
"""With a constant reference, a swing must also exceed this many standard deviations of the
output's noise (:func:`noise_level`): white noise swings by more than 8 σ between two
samples about once in 10⁸, so a settled, noisy output does not count as oscillating. A
quantised output (an encoder) must also swing by more than two steps (±1 count)."""
OSCILLATING_CYCLES = 5.0
"""A run whose output swings this many cycles in one train, while the reference keeps its
direction, is flagged as oscillating (a step response that rings for two or three periods
is not; a limit cycle lasts until the reference turns)."""


def reversals(signal, threshold: float) -> np.ndarray:
    """Indices where ``signal`` turns.

    A turn is where it has moved back from its last extremum by more than ``threshold`` (a swing
    smaller than that, e.g. sensor noise, is not a turn).

    Parameters
    ----------
    signal : array_like
        The samples.
    threshold : float
        Smallest move back that counts as a turn (signal units).

    Returns
    -------
    ndarray
        Sample indices (int) of the turns.
    """
    return _turns(signal, threshold)[0]


def noise_level(signal) -> float:
    """Standard deviation of the white noise on ``signal``, from its second differences.

    The estimate is robust: 1.4826 × their median absolute deviation, over √6; a smooth signal
    gives about 0.

    Parameters
    ----------
    signal : array_like
        The samples.

    Returns
    -------
    float
        The estimated standard deviation (signal units); 0 for fewer than 3 samples.
    """
    x = np.asarray(signal, float)
    if len(x) < 3:
        return 0.0
    second = np.diff(x, 2)
    return float(1.4826 * np.median(np.abs(second - np.median(second))) / np.sqrt(6.0))


def _turns(signal, threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`reversals` and the direction (+1, −1) the signal moves in after each turn."""
    x = np.asarray(signal, float)
    turns, directions = [], []
    direction, high, low = 0, x[0], x[0]
    for k in range(1, len(x)):
        v = x[k]
        if direction == 0:  # not moved by more than the threshold yet
            high, low = max(high, v), min(low, v)
            if high - low > threshold:
                direction = 1 if v == high else -1
                extremum = v
        elif direction * (v - extremum) > 0:
            extremum = v
        elif direction * (extremum - v) > threshold:
            direction, extremum = -direction, v
            turns.append(k)
            directions.append(direction)
    return np.asarray(turns, int), np.asarray(directions, int)


def oscillation_metrics(t, reference, output, threshold: float = OSCILLATION_THRESHOLD) -> dict[str, float]:
    """How much the output swings back and forth on its own, not following the reference.

    The output's turns (:func:`reversals`, by more than ``threshold`` × the reference's span;
    for a constant reference, × the output's span and above a noise floor) are grouped into
    trains: turns between the same two turns or jumps of the reference, each at most twice
    as far from the previous turn as that one was from its own (a rhythm). The first turn
    after a turn or jump of the reference, in its direction, is the output following it and
    does not count. A step response that overshoots turns once; a limit cycle turns twice
    per period for as long as it lasts.

    Parameters
    ----------
    t : array_like
        Sample times (s).
    reference, output : array_like
        Reference and output samples.
    threshold : float, optional
        Smallest turn, as a share of the reference's span (:data:`OSCILLATION_THRESHOLD`).

    Returns
    -------
    dict
        ``oscillation_cycles``, the longest train's cycles (turns / 2), ``oscillation_hz``, its
        frequency (Hz; 0 below two turns), and ``oscillating``, 1.0 when the cycles reach
        :data:`OSCILLATING_CYCLES`.
    """
    t = np.asarray(t, float)
    r = np.asarray(reference, float)
    y = np.asarray(output, float)
    if np.ptp(r) > 0:
        delta = threshold * float(np.ptp(r))
    else:
        steps = np.abs(np.diff(y))
        quantum = float(steps[steps > 0].min()) if np.any(steps > 0) else 0.0  # an encoder's count
        delta = max(threshold * (float(np.ptp(y)) or 1.0), NOISE_FLOOR * noise_level(y), 2.5 * quantum)
    turns, turn_directions = _turns(y, delta)
    ref_turns, ref_directions = _turns(r, delta)
    jumps = np.flatnonzero(np.abs(np.diff(r)) > delta) + 1
    direction_at = dict(zip(ref_turns.tolist(), ref_directions.tolist(), strict=True))
    direction_at.update({int(k): int(np.sign(r[k] - r[k - 1])) for k in jumps})
    events = sorted(set(direction_at) | {0, len(r)})
    longest: list[int] = []
    for start, end in zip(events[:-1], events[1:], strict=True):
        inside = (turns >= start) & (turns < end)
        ks, directions = turns[inside], turn_directions[inside]
        if len(ks) and directions[0] == direction_at.get(start, 0):
            ks = ks[1:]  # the output following the reference
        train: list[int] = []
        for k in ks:
            if len(train) >= 2 and k - train[-1] > 2 * (train[-1] - train[-2]):
                train = []
            train.append(int(k))
            if len(train) > len(longest):
                longest = list(train)
    cycles = len(longest) / 2
    hz = (len(longest) - 1) / (2 * (t[longest[-1]] - t[longest[0]])) if len(longest) > 1 else 0.0
    return {"oscillation_cycles": cycles, "oscillation_hz": float(hz),
            "oscillating": float(cycles >= OSCILLATING_CYCLES)}


def input_metrics(u) -> dict[str, float]:
    """``input_tv``: the input's total variation Σ|u_k − u_{k−1}| (input units).

    It measures how much the actuator is moved, chattering included.

    Parameters
    ----------
    u : array_like
        The applied input samples.

    Returns
    -------
    dict
        ``input_tv``.
    """
    return {"input_tv": float(np.sum(np.abs(np.diff(np.asarray(u, float)))))}
