"""Grünwald–Letnikov fractional operator (wang2025 eq. (4)/(9)) and the creep inverse (Section 2.3).

``D^q f(t_k) ≈ h^(−q) Σ_{j=0}^{k} w_j f(t_{k−j})`` with the weights
``w_0 = 1, w_j = w_{j−1} (1 − (q + 1)/j)`` (the generalised binomial coefficients
``(−1)^j C(q, j)``). ``q < 0`` is a fractional integral: the FCKP creep of wang2025 is
``q = −α`` with α = 0.02, so a constant input gives a slow rise ∝ t^α (benches.md).

For a window ``L`` only the last ``L`` past samples enter the sum (the short-memory
principle); ``None`` keeps the full memory.
"""

from __future__ import annotations

import casadi as ca
import numpy as np


def gl_weights(order: float, n: int) -> np.ndarray:
    """The first ``n`` Grünwald–Letnikov weights of ``order``.

    Parameters
    ----------
    order : float
        Fractional order q (finite; negative: integral).
    n : int
        Number of weights, >= 1.

    Returns
    -------
    ndarray
        ``w_0 = 1, w_1, …, w_{n−1}``.
    """
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    if not np.isfinite(order):
        raise ValueError(f"order must be finite, got {order}")
    w = np.empty(n)
    w[0] = 1.0
    for j in range(1, n):
        w[j] = w[j - 1] * (1.0 - (order + 1.0) / j)
    return w


def gl_apply(order: float, h: float, values, window: int | None = None) -> np.ndarray:
    """``D^order`` of a sampled signal at every sample (memory from the first sample).

    Parameters
    ----------
    order : float
        Fractional order (negative: integral).
    h : float
        Sample period (s).
    values : array_like, shape (n,)
        ``f(t_0), …, f(t_{n−1})``; ``f`` is taken as zero before ``t_0``.
    window : int, optional
        Keep only the current sample and the last ``window`` past samples (None: all).

    Returns
    -------
    ndarray, shape (n,)
        ``D^order f`` at each sample.
    """
    if not h > 0:
        raise ValueError(f"h must be > 0, got {h}")
    f = np.asarray(values, float)
    n = len(f)
    w = gl_weights(order, n)
    if window is not None:
        if window < 0:
            raise ValueError(f"window must be >= 0 or None, got {window}")
        w[window + 1:] = 0.0
    return h ** (-order) * np.convolve(f, w)[:n]


def creep_integral(w, order: float, sample_period: float) -> np.ndarray:
    """``D^(−order)`` of ``w`` along its first axis (zero before the first sample) by FFT.

    The GL sum of :func:`gl_apply` in O(n log n).

    Parameters
    ----------
    w : array_like
        Signal, one sample (or row of signals) per entry of the first axis.
    order : float
        Creep order α; ``w`` is returned unchanged when it is 0 or below.
    sample_period : float
        Sample period h (s).

    Returns
    -------
    ndarray
        ``D^(−order) w``, of the shape of ``w``.
    """
    from scipy.signal import fftconvolve
    w = np.asarray(w, float)
    if order <= 0:
        return w
    n = len(w)
    weights = np.concatenate(([1.0], np.cumprod(1.0 - (1.0 - order) / np.arange(1, n))))  # gl_weights(-order, n)
    kernel = weights if w.ndim == 1 else weights[:, None]
    return sample_period ** order * fftconvolve(w, kernel, axes=0)[:n]


class GrunwaldLetnikov:
    """Streaming GL operator: push one sample, get ``D^order`` at that sample.

    Parameters
    ----------
    order : float
        Fractional order (``−α`` for the FCKP creep integral).
    h : float
        Sample period (s).
    window : int, optional
        Memory window L in past samples; None keeps the full memory.
    capacity : int, optional
        Samples to pre-allocate (grows when exceeded).
    """

    def __init__(self, order: float, h: float, window: int | None = None, capacity: int = 8192):
        if not h > 0:
            raise ValueError(f"h must be > 0, got {h}")
        if window is not None and window < 0:
            raise ValueError(f"window must be >= 0 or None, got {window}")
        self.order, self.h, self.window = float(order), float(h), window
        self._scale = h ** (-order)
        self._w = gl_weights(order, max(capacity, 2))
        self.reset()

    def reset(self) -> None:
        """Forget the memory."""
        self._hist = np.empty(len(self._w))
        self._n = 0

    @property
    def history(self) -> np.ndarray:
        """Samples pushed so far, oldest first."""
        return self._hist[: self._n].copy()

    def _grow(self, n: int) -> None:
        if n > len(self._w):
            size = max(n, 2 * len(self._w))
            self._w = gl_weights(self.order, size)
            hist = np.empty(size)
            hist[: self._n] = self._hist[: self._n]
            self._hist = hist

    def push(self, value: float) -> float:
        """Append ``f(t_k)`` and return ``D^order f(t_k)``.

        Parameters
        ----------
        value : float
            The new sample ``f(t_k)``.

        Returns
        -------
        float
            ``D^order f(t_k)`` (as :meth:`value`).
        """
        self._grow(self._n + 1)
        self._hist[self._n] = value
        self._n += 1
        return self.value()

    def value(self) -> float:
        """``D^order f`` at the last pushed sample.

        Returns
        -------
        float
            The GL sum over the memory (within the window, if any); 0 before the first push.
        """
        n = self._n if self.window is None else min(self._n, self.window + 1)
        recent = self._hist[self._n - n: self._n][::-1]
        return float(self._scale * (self._w[:n] @ recent))

    def history_terms(self, horizon: int) -> np.ndarray:
        """The part of ``D^order f(t_{k+i})``, i = 1..horizon, that the past fixes.

        ``D^order f(t_{k+i}) = h^(−order) [Σ_{j<i} w_j f_{k+i−j} + Σ_{j≥i} w_j f_{k+i−j}]``:
        the first sum holds the future samples (decisions of a predictive controller), the
        second only pushed ones.

        Parameters
        ----------
        horizon : int
            Number of future samples.

        Returns
        -------
        ndarray, shape (horizon,)
            ``h^(−order)`` times the second sum for each ``i`` (within the window, if any).
        """
        self._grow(self._n + horizon + 1)
        out = np.empty(horizon)
        past = self._hist[: self._n][::-1]  # f_k, f_{k−1}, ...
        for i in range(1, horizon + 1):
            n = len(past) if self.window is None else max(0, min(len(past), self.window + 1 - i))
            out[i - 1] = self._scale * (self._w[i: i + n] @ past[:n])
        return out


def window_functions(order: float, h: float, window: int, horizon: int) -> tuple[ca.Function, ca.Function]:
    """The streaming GL operator with memory window ``window`` as two CasADi Functions.

    They work over a buffer of the last ``window + 1`` samples (oldest first, zeros before the
    first push):

    * ``push(buffer, f) -> (buffer_next, value)``: :meth:`GrunwaldLetnikov.push`;
    * ``history(buffer) -> terms``: :meth:`GrunwaldLetnikov.history_terms` over ``horizon``.

    Fixed size and plain sums (newest sample first), so generated C and a Python controller
    that call them compute the same numbers to the last bit.

    Parameters
    ----------
    order : float
        Fractional order (``−α`` for the FCKP creep integral).
    h : float
        Sample period (s).
    window : int
        Memory window L in past samples, >= 0.
    horizon : int
        Number of future samples of ``history``, >= 1.

    Returns
    -------
    push : casadi.Function
        ``(buffer, f) -> (buffer_next, value)``.
    history : casadi.Function
        ``(buffer) -> terms``, ``horizon`` terms.
    """
    if window < 0 or horizon < 1:
        raise ValueError(f"window must be >= 0 and horizon >= 1, got {window}, {horizon}")
    L = window
    w = gl_weights(order, L + horizon + 1)
    scale = h ** (-order)
    buffer, f = ca.MX.sym("buffer", L + 1), ca.MX.sym("f")
    shifted = ca.vertcat(buffer[1:], f) if L else f
    newest_first = shifted[::-1]
    push = ca.Function("gl_push", [buffer, f], [shifted, scale * ca.dot(ca.DM(w[: L + 1]), newest_first)],
                       ["buffer", "f"], ["buffer_next", "value"])
    toeplitz = np.zeros((horizon, L + 1))  # row i-1: w_{i+m} on the m-th newest sample, m <= L - i
    for i in range(1, horizon + 1):
        n = max(0, L + 1 - i)
        toeplitz[i - 1, :n] = w[i: i + n]
    history = ca.Function("gl_history", [buffer], [scale * ca.mtimes(ca.DM(toeplitz), buffer[::-1])],
                          ["buffer"], ["terms"])
    return push, history
