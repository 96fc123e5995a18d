"""Inverses by search along a monotone move, for models without a closed-form inverse.

A model whose output moves monotonically with the input along a monotone move (Preisach,
Bouc–Wen) is inverted by bracketing the target between the last input and a far bound, then
narrowing the bracket: :func:`bisection_inverse` by halvings (any monotone output, kinks
included), :func:`illinois_inverse` by a few halvings and then a modified regula falsi (a
smooth output: far fewer steps). Both run on CasADi expressions as a fold, so a generated controller keeps one loop.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from hystmpc.models.base import symbolic


def bisection_inverse(model, state, y_target, edges: tuple[float, float], reach: float,
                      tail_slopes: tuple[float, float] = (0.0, 0.0), iterations: int = 56):
    """The input that brings ``model``'s output to ``y_target`` from ``state``, and the state after it.

    On CasADi expressions (the arithmetic of a generated controller); returns ``(state, u)``.

    For models whose output moves monotonically with the input along a monotone move, and
    linearly (``tail_slopes``) once the move has gone ``reach`` and past ``edges``.
    ``iterations`` halvings of the move up to that far bound find the input where the
    target is first reached, to ``2^-iterations`` of the move; beyond it the line is followed,
    and a target a flat tail cannot reach gives the far bound. The halvings run as a CasADi
    fold: generated C keeps one loop, not ``iterations`` copies.

    Parameters
    ----------
    model : HysteresisModel
        Its ``step`` and ``output`` must accept CasADi expressions.
    state : array_like or CasADi expression
        State to move from.
    y_target : float or CasADi expression
        Output to reach.
    edges : tuple of float
        Inputs (downwards, upwards) past which the output is linear (input units).
    reach : float
        Input move after which the output is linear (input units).
    tail_slopes : tuple of float, optional
        Output slopes beyond the far bound: downwards, upwards (0: flat).
    iterations : int, optional
        Number of halvings.

    Returns
    -------
    state : CasADi expression
        State after the move (``casadi.DM`` for numeric arguments).
    u : CasADi expression
        The input (``casadi.DM`` for numeric arguments).
    """
    n = len(model.state_names)
    x, target, up = ca.SX.sym("state", n), ca.SX.sym("target"), ca.SX.sym("up")
    near, far = ca.SX.sym("near"), ca.SX.sym("far")

    def reached(u):
        y = model.step(x, u)[1]
        return ca.if_else(up, y >= target, y <= target)
    mid = 0.5 * (near + far)
    halve = ca.Function(f"{type(model).__name__.lower()}_bisect", [ca.vertcat(near, far), ca.vertcat(x, target, up)],
                        [ca.if_else(reached(mid), ca.vertcat(near, mid), ca.vertcat(mid, far))])
    x, target = ca.MX.sym("state", n), ca.MX.sym("target")  # MX: the fold stays a call
    rising = target > model.output(x)
    bound = ca.if_else(rising, ca.fmax(x[0] + reach, edges[1]), ca.fmin(x[0] - reach, edges[0]))
    bracket = halve.fold(iterations)(ca.vertcat(x[0], bound), ca.vertcat(x, target, rising))
    y_bound = model.step(x, bound)[1]
    inside = ca.if_else(rising, y_bound >= target, y_bound <= target)
    slope = ca.if_else(rising, tail_slopes[1], tail_slopes[0])
    beyond = ca.if_else(slope > 0, bound + (target - y_bound) / ca.if_else(slope > 0, slope, 1.0), bound)
    u = ca.if_else(inside, bracket[1], beyond)
    inverse = ca.Function(f"{type(model).__name__.lower()}_inverse", [x, target], [model.step(x, u)[0], u],
                          {"never_inline": True})
    return inverse(state, y_target)


def _illinois_update(bracket, c, fc, select):
    """One Illinois (modified regula falsi) update of ``(a, b, fa, fb, side)`` with the new point ``c``.

    ``b`` is the end where the target is reached (``fb >= 0``, ``fa < 0``, signs set so);
    the end kept twice in a row has its value halved, which keeps the convergence superlinear.
    ``select(condition, if_true, if_false)`` is ``ca.if_else`` or its NumPy twin.
    """
    a, b, fa, fb, side = bracket
    replaces_b = fc >= 0
    return (select(replaces_b, a, c), select(replaces_b, c, b),
            select(replaces_b, select(side < 0, 0.5 * fa, fa), fc),
            select(replaces_b, fc, select(side > 0, 0.5 * fb, fb)),
            select(replaces_b, -1.0, 1.0))


def _halving_update(bracket, c, fc, select):
    """The bracket ``(a, b, fa, fb, side)`` cut at its midpoint ``c`` (the Illinois memory cleared)."""
    a, b, fa, fb, _ = bracket
    replaces_b = fc >= 0
    return (select(replaces_b, a, c), select(replaces_b, c, b), select(replaces_b, fa, fc),
            select(replaces_b, fc, fb), 0.0)


def _secant_point(a, b, fa, fb, select):
    """Where the chord from ``(a, fa)`` to ``(b, fb)`` crosses zero (``b`` when they are equal)."""
    same = fb == fa
    return select(same, b, (a * fb - b * fa) / select(same, 1.0, fb - fa))


def illinois_inverse(model, state, y_target, edges: tuple[float, float], reach: float,
                     tail_slopes: tuple[float, float] = (0.0, 0.0), halvings: int = 8, iterations: int = 10):
    """:func:`bisection_inverse` with fewer steps: ``halvings`` halvings, then the Illinois method.

    For a model whose output along a move is smooth (Bouc–Wen). The halvings bring the far
    bound (tens of loop widths away, where a saturating loop is flat) near the target, where a
    modified regula falsi converges superlinearly: 8 + 10 steps reach 1e-9 of the loop's span
    on 430 random targets (near-saturated ones included) where 12 Illinois steps alone missed
    by up to 2.6 % of it; the bisection takes 56 halvings. NumPy arguments run the same
    arithmetic in NumPy (the generated controller's, to rounding).

    Parameters
    ----------
    model : HysteresisModel
        Its ``step`` and ``output`` must accept CasADi expressions.
    state : array_like or CasADi expression
        State to move from.
    y_target : float or CasADi expression
        Output to reach.
    edges, reach, tail_slopes
        As for :func:`bisection_inverse`.
    halvings : int, optional
        Number of halvings first.
    iterations : int, optional
        Number of Illinois steps after them.

    Returns
    -------
    state : ndarray or CasADi expression
        State after the move.
    u : float or CasADi expression
        The input.
    """
    if not (symbolic(state) or symbolic(y_target)):
        return _illinois_numeric(model, np.asarray(state, float), float(y_target), edges, reach, tail_slopes,
                                 halvings, iterations)
    n = len(model.state_names)
    x, target, sign = ca.SX.sym("state", n), ca.SX.sym("target"), ca.SX.sym("sign")
    a, b, fa, fb, side = (ca.SX.sym(name) for name in ("a", "b", "fa", "fb", "side"))
    c = _secant_point(a, b, fa, fb, ca.if_else)
    fc = sign * (model.step(x, c)[1] - target)
    update = ca.Function(f"{type(model).__name__.lower()}_illinois", [ca.vertcat(a, b, fa, fb, side),
                                                                      ca.vertcat(x, target, sign)],
                         [ca.vertcat(*_illinois_update((a, b, fa, fb, side), c, fc, ca.if_else))])
    mid = 0.5 * (a + b)
    halve = ca.Function(f"{type(model).__name__.lower()}_halve", [ca.vertcat(a, b, fa, fb, side),
                                                                  ca.vertcat(x, target, sign)],
                        [ca.vertcat(*_halving_update((a, b, fa, fb, side), mid,
                                                     sign * (model.step(x, mid)[1] - target), ca.if_else))])
    x, target = ca.MX.sym("state", n), ca.MX.sym("target")  # MX: the fold stays a call
    rising = target > model.output(x)
    sign = ca.if_else(rising, 1.0, -1.0)
    bound = ca.if_else(rising, ca.fmax(x[0] + reach, edges[1]), ca.fmin(x[0] - reach, edges[0]))
    y_bound = model.step(x, bound)[1]
    start = ca.vertcat(x[0], bound, sign * (model.output(x) - target), sign * (y_bound - target), 0.0)
    context = ca.vertcat(x, target, sign)
    last = update.fold(iterations)(halve.fold(halvings)(start, context), context)
    found = _secant_point(last[0], last[1], last[2], last[3], ca.if_else)
    inside = sign * (y_bound - target) >= 0
    slope = ca.if_else(rising, tail_slopes[1], tail_slopes[0])
    beyond = ca.if_else(slope > 0, bound + (target - y_bound) / ca.if_else(slope > 0, slope, 1.0), bound)
    u = ca.if_else(inside, found, beyond)
    inverse = ca.Function(f"{type(model).__name__.lower()}_inverse", [x, target], [model.step(x, u)[0], u],
                          {"never_inline": True})
    return inverse(state, y_target)


def _illinois_numeric(model, state, target, edges, reach, tail_slopes, halvings, iterations):
    """:func:`illinois_inverse` in NumPy."""
    def select(condition, if_true, if_false):
        return if_true if condition else if_false
    y0 = model.output(state)
    if target == y0:
        return state.copy(), float(state[0])
    rising = target > y0
    sign = 1.0 if rising else -1.0
    bound = max(state[0] + reach, edges[1]) if rising else min(state[0] - reach, edges[0])
    y_bound = model.step(state, bound)[1]
    if sign * (y_bound - target) < 0:
        slope = tail_slopes[1] if rising else tail_slopes[0]
        u = bound + (target - y_bound) / slope if slope > 0 else bound
        return model.step(state, u)[0], float(u)
    bracket = (float(state[0]), float(bound), sign * (y0 - target), sign * (y_bound - target), 0.0)
    for _ in range(halvings):
        c = 0.5 * (bracket[0] + bracket[1])
        bracket = _halving_update(bracket, c, sign * (model.step(state, c)[1] - target), select)
    for _ in range(iterations):
        c = _secant_point(*bracket[:4], select)
        bracket = _illinois_update(bracket, c, sign * (model.step(state, c)[1] - target), select)
    u = _secant_point(*bracket[:4], select)
    return model.step(state, u)[0], float(u)
