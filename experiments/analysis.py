"""Model checks reported in the docs: how far the smooth step drifts from the exact one."""

from __future__ import annotations

import numpy as np


def smoothing_error(model, inputs, eps: float, window: int, **smooth_options) -> dict[str, float]:
    """Output error of ``model.smooth_step(eps)`` against ``model.step`` along ``inputs``.

    Works for any model with the common shape (``initial_state``, ``step``,
    ``smooth_step``). Two figures: the whole sequence open loop, and the worst over
    windows of ``window`` steps each restarted from the exact state, which is what the
    NMPC's prediction faces (its estimate is re-anchored every sample).

    Parameters
    ----------
    model : object
        The hysteresis model.
    inputs : array_like
        Input sequence, at least two samples; the models start from ``model.initial_state(inputs[0])``.
    eps : float
        Smoothing parameter given to ``model.smooth_step``.
    window : int
        Length of the windows (steps, at least 1); they start every ``window // 2`` steps.
    **smooth_options
        More keyword arguments for ``model.smooth_step``.

    Returns
    -------
    dict
        ``max_open_loop``, ``max_in_window`` and ``rms_in_window`` (output units).
    """
    inputs = np.asarray(inputs, float)
    if window < 1 or len(inputs) < 2:
        raise ValueError(f"need window >= 1 and at least two inputs, got {window}, {len(inputs)}")
    smooth = model.smooth_step(eps, **smooth_options)
    exact_states = [model.initial_state(inputs[0])]
    exact_out = [model.output(exact_states[0])]
    for u in inputs[1:]:
        state, y = model.step(exact_states[-1], u)
        exact_states.append(state)
        exact_out.append(y)
    exact_out = np.asarray(exact_out)

    def run_smooth(start, stop):
        state = exact_states[start]
        out = []
        for u in inputs[start + 1: stop]:
            state, y = smooth(state, u)
            state = np.asarray(state).ravel()
            out.append(float(y))
        return np.asarray(out)

    open_loop = np.abs(run_smooth(0, len(inputs)) - exact_out[1:])
    in_window = []
    for start in range(0, len(inputs) - 1, max(1, window // 2)):
        stop = min(len(inputs), start + window + 1)
        in_window.append(run_smooth(start, stop) - exact_out[start + 1: stop])
    in_window = np.concatenate(in_window)
    return {"max_open_loop": float(open_loop.max()), "max_in_window": float(np.abs(in_window).max()),
            "rms_in_window": float(np.sqrt(np.mean(in_window**2)))}


def creep_window_error(model, inputs, windows) -> dict[str, dict[str, float]]:
    """Creep output of an FCKP model with memory window L against the full memory.

    The same input sequence drives the full-memory creep (the plant's) and each truncated one
    (L past samples, the short-memory principle).

    Parameters
    ----------
    model : Fckp
        A :class:`hystmpc.models.fckp.Fckp`.
    inputs : array_like
        Input sequence.
    windows : iterable of int or None
        Memory windows L (samples) to compare; None is the full memory.

    Returns
    -------
    dict
        Per window (its number as a string, ``"full"`` for None): ``max`` and ``rms``, the max
        and RMS difference in W, and ``relative_rms``, the RMS difference against the RMS of W.
    """
    inputs = np.asarray(inputs, float)
    state = model.initial_state()
    w = np.empty(len(inputs))
    for k, u in enumerate(inputs):
        state, w[k] = model.step(state, u)
    full_memory = model.creep(None)
    full = np.array([full_memory.push(v) for v in w])
    out = {}
    for window in windows:
        memory = model.creep(window)
        diff = np.array([memory.push(v) for v in w]) - full
        out["full" if window is None else str(window)] = {
            "max": float(np.max(np.abs(diff))), "rms": float(np.sqrt(np.mean(diff**2))),
            "relative_rms": float(np.sqrt(np.mean(diff**2)) / np.sqrt(np.mean(full**2)))}
    return out
