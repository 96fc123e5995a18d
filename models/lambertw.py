"""Principal branch of the Lambert W function for CasADi (which has none) and NumPy.

W(x) solves w·e^w = x, w >= -1, for x >= -1/e. The CasADi version starts from a
piecewise initial guess (a branch-point series near -1/e, Winitzki's approximation in
between, the asymptotic series for large x) and refines it with a fixed number of Halley
steps, all symbolic, so CasADi differentiates it like any other expression. Halley's
method converges cubically, so the derivative of the iteration converges to the exact
derivative W'(x) = W / (x (1 + W)) as well.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

INV_E = float(np.exp(-1.0))
HALLEY_STEPS = 3
"""Three steps from the initial guess reach the double-precision value over the whole
domain, for W and its derivative (checked against SciPy; two steps do not); more only cost
time in every prediction that calls W."""


def _initial_guess(x, lib):
    if_else = ca.if_else if lib is ca else (lambda c, a, b: np.where(c, a, b))
    # near the branch point: W = -1 + p - p²/3 + 11/72 p³, p = sqrt(2(e x + 1))
    p = lib.sqrt(2.0 * (np.e * x + 1.0) * ((np.e * x + 1.0) > 0))
    branch = -1.0 + p - p**2 / 3.0 + 11.0 / 72.0 * p**3
    # Winitzki: W ≈ ln(1+x) (1 − ln(1 + ln(1+x)) / (2 + ln(1+x))), good for x > -0.3
    lx = lib.log(1.0 + lib.fmax(x, -0.3) if lib is ca else 1.0 + np.maximum(x, -0.3))
    middle = lx * (1.0 - lib.log(1.0 + lx) / (2.0 + lx))
    # asymptotic: W ≈ L1 − L2 + L2/L1, L1 = ln x, L2 = ln L1, for large x
    l1 = lib.log(lib.fmax(x, 3.0) if lib is ca else np.maximum(x, 3.0))
    l2 = lib.log(l1)
    large = l1 - l2 + l2 / l1
    return if_else(x < -0.25, branch, if_else(x < 20.0, middle, large))


def _halley(w, x, lib):
    ew = lib.exp(w)
    f = w * ew - x
    wp1 = w + 1.0
    return w - f / (ew * wp1 - (w + 2.0) * f / (2.0 * wp1))


def lambertw_expr(x):
    """Symbolic W(x) for a CasADi expression ``x`` (x >= -1/e).

    Parameters
    ----------
    x : casadi.SX or casadi.MX
        The argument.

    Returns
    -------
    casadi.SX or casadi.MX
        W(x) after ``HALLEY_STEPS`` Halley steps from the initial guess.
    """
    w = _initial_guess(x, ca)
    for _ in range(HALLEY_STEPS):
        w = _halley(w, x, ca)
    return w


def lambertw_function() -> ca.Function:
    """W as a CasADi Function ``lambertw(x) -> w``.

    Returns
    -------
    casadi.Function
        ``lambertw(x) -> w`` on a scalar SX.
    """
    x = ca.SX.sym("x")
    return ca.Function("lambertw", [x], [lambertw_expr(x)], ["x"], ["w"])


def _lambertw_scalar(x: float) -> float:
    """:func:`lambertw` of one float with ``math``, ~35 × faster than on a 0-d array.

    The same operations in the same order, so the same double where ``math`` and NumPy share
    the C library's exp, log and pow. Raises ArithmeticError where NumPy would return inf or NaN.
    """
    if x == 0.0:
        return 0.0
    if x < -0.25:
        t = math.e * x + 1.0
        p = math.sqrt(2.0 * t) if t > 0 else 0.0
        w = -1.0 + p - p * p / 3.0 + 11.0 / 72.0 * p**3
    elif x < 20.0:
        lx = math.log(1.0 + max(x, -0.3))
        w = lx * (1.0 - math.log(1.0 + lx) / (2.0 + lx))
    else:
        l1 = math.log(x)
        l2 = math.log(l1)
        w = l1 - l2 + l2 / l1
    for _ in range(HALLEY_STEPS):
        ew = math.exp(w)
        f = w * ew - x
        wp1 = w + 1.0
        w = w - f / (ew * wp1 - (w + 2.0) * f / (2.0 * wp1))
    return w


def lambertw(x):
    """W(x) on NumPy values with the same algorithm (real result, x >= -1/e).

    Parameters
    ----------
    x : float or array_like
        The argument (a ``ValueError`` below -1/e).

    Returns
    -------
    float or ndarray
        W(x): a float for a float ``x``, else an array of the shape of ``x``.
    """
    if isinstance(x, float) and x >= -INV_E - 1e-15:  # np.float64 is a float too
        try:
            return _lambertw_scalar(float(x))  # Python floats: ArithmeticError, not NumPy's warnings
        except ArithmeticError:  # W's branch point or an overflow: NumPy's inf/NaN rules below
            pass
    x = np.asarray(x, float)
    if np.any(x < -INV_E - 1e-15):
        raise ValueError(f"Lambert W (principal branch) needs x >= -1/e, got min {x.min()}")
    w = _initial_guess(x, np)
    with np.errstate(invalid="ignore", divide="ignore"):
        for _ in range(HALLEY_STEPS):
            w = np.where(x == 0.0, 0.0, _halley(w, x, np))
    return w
