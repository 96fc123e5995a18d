"""The one integrator: classic Runge–Kutta 4, on NumPy arrays and CasADi expressions alike."""

from __future__ import annotations


def rk4(rhs, x, h: float, substeps: int = 1, t: float = 0.0):
    """Integrate ``x' = rhs(x, t)`` over ``substeps`` RK4 steps of length ``h``.

    Works on anything with ``+`` and ``*`` (NumPy arrays for the plants, CasADi SX for the
    prediction models), so simulated plants and NMPC models integrate the same way.

    Parameters
    ----------
    rhs : callable
        ``(x, t) -> x'`` of the same type and shape as ``x``.
    x : array_like or casadi.SX
        State at ``t``.
    h : float
        Step length (s).
    substeps : int, optional
        Number of steps (at least 1).
    t : float, optional
        Time at the start (only passed on to ``rhs``).

    Returns
    -------
    array_like or casadi.SX
        The state at ``t + substeps·h``, of the type of ``x``.
    """
    if substeps < 1:
        raise ValueError(f"substeps must be >= 1, got {substeps}")
    for _ in range(substeps):
        k1 = rhs(x, t)
        k2 = rhs(x + h / 2 * k1, t + h / 2)
        k3 = rhs(x + h / 2 * k2, t + h / 2)
        k4 = rhs(x + h * k3, t + h)
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        t = t + h
    return x
