"""Smooth replacements for switching primitives, usable on CasADi and NumPy values.

Each has width ``eps`` and converges uniformly to its exact counterpart as ``eps -> 0``;
the bounds are stated per function and used by the tests.
"""

from __future__ import annotations

import casadi as ca
import numpy as np


def _sqrt(x):
    return np.sqrt(x) if isinstance(x, (float, int, np.ndarray, np.floating)) else ca.sqrt(x)


def smooth_abs(x, eps: float):
    """Smooth ``|x|``: ``sqrt(x² + eps²) - eps``; ``0 <= |x| - smooth_abs(x) <= eps``.

    Parameters
    ----------
    x : float, ndarray or casadi.SX
        The argument.
    eps : float
        Smoothing width.

    Returns
    -------
    float, ndarray or casadi.SX
        The smooth absolute value, of the type of ``x``.
    """
    return _sqrt(x * x + eps * eps) - eps


def smooth_max(a, b, eps: float):
    """Smooth ``max(a, b)``: ``(a + b + sqrt((a-b)² + eps²)) / 2``; error in ``[0, eps/2]``.

    Parameters
    ----------
    a, b : float, ndarray or casadi.SX
        The two arguments.
    eps : float
        Smoothing width.

    Returns
    -------
    float, ndarray or casadi.SX
        The smooth maximum.
    """
    d = a - b
    return 0.5 * (a + b + _sqrt(d * d + eps * eps))


def smooth_min(a, b, eps: float):
    """Smooth ``min(a, b)``: ``(a + b - sqrt((a-b)² + eps²)) / 2``; error in ``[-eps/2, 0]``.

    Parameters
    ----------
    a, b : float, ndarray or casadi.SX
        The two arguments.
    eps : float
        Smoothing width.

    Returns
    -------
    float, ndarray or casadi.SX
        The smooth minimum.
    """
    d = a - b
    return 0.5 * (a + b - _sqrt(d * d + eps * eps))


def smooth_clip(x, limit, eps: float):
    """Smooth ``clip(x, -limit, limit)`` for ``limit > 0``.

    ``(sqrt((x+limit)² + eps²) - sqrt((x-limit)² + eps²)) / 2``: odd in ``x``, slope in
    ``[0, 1]``, tends to ``±limit`` exactly as ``|x| -> inf``, and
    ``|smooth_clip(x) - clip(x)| <= eps/2`` for every ``x``.

    Parameters
    ----------
    x : float, ndarray or casadi.SX
        The argument.
    limit : float
        Half-width of the clipping interval (``> 0``).
    eps : float
        Smoothing width.

    Returns
    -------
    float, ndarray or casadi.SX
        The smoothly clipped value.
    """
    p = x + limit
    m = x - limit
    return 0.5 * (_sqrt(p * p + eps * eps) - _sqrt(m * m + eps * eps))
