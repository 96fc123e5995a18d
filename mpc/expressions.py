"""Small CasADi helpers of the generated controller (:mod:`hystmpc.mpc.embedded`), and its refusal."""

from __future__ import annotations

import warnings

import casadi as ca
import numpy as np


class NotGeneratable(ValueError):
    """The controller has a part without a CasADi form yet (the message says which)."""


def rows(v, start: int, stop: int) -> ca.MX:
    """``v[start:stop]`` as a column.

    Also for a 1x1 ``v`` and an empty range (where CasADi's slicing gives a 1x0 row that will
    not stack).

    Parameters
    ----------
    v : casadi.MX
        A column.
    start, stop : int
        The rows, as a Python slice.

    Returns
    -------
    casadi.MX
        The rows, a column (0 x 1 when empty).
    """
    return ca.vertcat(*[v[i] for i in range(start, stop)]) if stop > start else ca.MX(0, 1)


def all_finite(v) -> ca.MX:
    """1 when every entry of ``v`` is finite (NaN and ±inf give 0).

    Parameters
    ----------
    v : casadi.MX
        Any matrix.

    Returns
    -------
    casadi.MX
        A 0/1 scalar.
    """
    return ca.sum1(ca.fabs(ca.vec(v))) < ca.inf


def is_nan(x) -> ca.MX:
    """1 where ``x`` is NaN: it fails every comparison (``x != x`` is simplified away).

    Parameters
    ----------
    x : casadi.MX
        Any matrix.

    Returns
    -------
    casadi.MX
        0/1 entry by entry.
    """
    return ca.logic_not(ca.logic_or(x <= 0, x > 0))


def clip(v, lower, upper):
    """``v`` inside ``[lower, upper]``, entry by entry.

    Parameters
    ----------
    v : casadi.MX
        Values.
    lower, upper : float or casadi.MX
        Bounds.

    Returns
    -------
    casadi.MX
        ``min(max(v, lower), upper)``.
    """
    return ca.fmin(ca.fmax(v, lower), upper)


def symbolic(fun, what: str, arg, size: int,
             advice: str = "write it with casadi operations for a generated controller"):
    """``fun(arg)`` on a CasADi symbol as a column of ``size`` entries.

    A NumPy array of CasADi entries (``np.array([z[0], 0.0])``) is stacked.

    Parameters
    ----------
    fun : callable
        The function.
    what : str
        Its name in the error.
    arg : casadi.MX
        The symbol it is called on.
    size : int
        The number of values it must give.
    advice : str, optional
        The end of the error.

    Returns
    -------
    casadi.MX
        ``fun(arg)``, a column.

    Raises
    ------
    NotGeneratable
        Saying ``what`` has no CasADi form (then ``advice``) or gives the wrong length.
    """
    try:
        with warnings.catch_warnings():  # a NumPy-only function on a CasADi symbol warns before it fails
            warnings.simplefilter("ignore")
            out = fun(arg)
            if isinstance(out, np.ndarray) and out.dtype == object:
                out = ca.vertcat(*[ca.MX(v) if isinstance(v, (int, float)) else v for v in out.ravel()])
        if not isinstance(out, (ca.MX, ca.SX, ca.DM)):
            raise TypeError(f"returned {type(out).__name__}")
    except Exception as exc:  # noqa: BLE001 - any failure means the same thing here
        raise NotGeneratable(f"{what} does not accept CasADi expressions ({type(exc).__name__}: {exc}); "
                             f"{advice}") from None
    if out.numel() != size:
        raise NotGeneratable(f"{what} gives {out.numel()} values on CasADi expressions, {size} expected")
    return ca.vec(out)
