"""Fit problems of the families with their own operators.

These families are Bouc–Wen, the parametric operator (katalenic2013), KP and FCKP (wang2025)
and the power-function model (zhou2024).

As in :mod:`hystmpc.models.fit_plays`, each returns a
:class:`~hystmpc.models.record_fit.Problem` for the record; the output's scale (a gain, a
stroke, Bouc–Wen's ``k`` and ``A``) is projected, the shape parameters are moved:

* ``bouc-wen``: β, γ/β and the exponent n, from the best of a small grid;
* ``parametric``: log p1 and log p2, from the best of a grid over the input span;
* ``kp``, ``fckp``: the density's ``c`` and ``σ``, both ends of the input range the threshold
  grid is laid on (unless given), and the creep order α (fckp);
* ``power-function``: the two polylines' torques at their knots (increasing by construction)
  and the knot grid's ends, the transition widths (Table VI) and exponents (Table VII),
  started from polylines fitted to the rising and falling samples and the best of a grid of
  constant widths and exponents.
"""

from __future__ import annotations

import numpy as np

from hystmpc.models.bouc_wen import MAX_EXPONENT, SUBSTEPS
from hystmpc.models.fractional import creep_integral
from hystmpc.models.kp import paper_density, ridge, threshold_grid
from hystmpc.models.linear_dynamics import LinearDynamics
from hystmpc.models.power_function import PowerFunctionHysteresis
from hystmpc.models.record_fit import Problem, Record, evaluate


def _best_start(problem: Problem, record: Record, starts) -> np.ndarray:
    """The start of ``starts`` with the least static simulation error."""
    costs = []
    for theta in starts:
        with np.errstate(all="ignore"):
            costs.append(evaluate(problem, np.asarray(theta, float), LinearDynamics(), record).rmse)
    return np.asarray(starts[int(np.argmin(costs))], float)


def bouc_wen_problem(record: Record) -> Problem:
    """``y = k·u + A·ζ(u; β, γ, n)``: ``log β^(1/n)``, ``γ/β`` and ``n`` moved.

    ``β^(1/n)`` (1 / input unit) sets the loop's width whatever ``n``, so moving ``n`` keeps the
    width. ``k`` and ``A`` (either sign, the output monotone) projected on the columns ``u``,
    ``ζ`` and ``m·u − ζ`` with non-negative weights, ``m = 2β/(β+γ)`` the largest ``dζ/du``.

    Parameters
    ----------
    record : Record
        The record.

    Returns
    -------
    Problem
        The fit problem, started at the best of a grid of β, γ/β and n; its parameters are
        ``linear_gain``, ``a``, ``beta``, ``gamma`` and ``exponent``.
    """
    u = record.u
    span = float(np.ptp(u))

    def steepest(theta):
        return 2.0 / (1.0 + float(theta[1]))

    def shape(theta):
        n = float(theta[2])
        beta = float(np.exp(theta[0] * n))
        return beta, beta * float(theta[1]), n

    def columns(theta):
        from hystmpc.models.compiled import bouc_wen_states
        beta, gamma, n = shape(theta)
        zeta = bouc_wen_states(u, 1.0, beta, gamma, 0.0, n, SUBSTEPS)
        return np.column_stack((u, zeta, steepest(theta) * u - zeta))

    def parameters(theta, w):
        beta, gamma, n = shape(theta)
        n = 1.0 if n < 1.0 + 1e-6 else n  # at its lower limit: the classical model, in closed form
        a = float(w[1] - w[2])
        if a == 0:  # no loop at all: the smallest one the model takes
            a = 1e-12 * max(float(np.max(w)), 1e-300)
        return {"linear_gain": float(w[0] + w[2] * steepest(theta)), "a": a, "beta": beta, "gamma": gamma,
                "exponent": n}
    problem = Problem([(np.arange(3), columns)], np.zeros(3), np.array([np.log(0.01 / span), -0.95, 1.0]),
                      np.array([np.log(1e4 / span), 0.95, MAX_EXPONENT]), np.ones(3, bool), parameters,
                      names=("beta^(1/n)", "gamma / beta", "exponent"), lower_is_limit=(2,))
    problem.theta = _best_start(problem, record, [(np.log(b / span), g, n) for b in (1.0, 3.0, 10.0, 30.0, 100.0)
                                                  for g in (-0.5, 0.0, 0.5) for n in (1.0, 2.0)])
    return problem


def parametric_problem(record: Record) -> Problem:
    """``y = gain · H_{p1,p2}[u]``: the gain projected (>= 0), log p1 and log p2 moved.

    Parameters
    ----------
    record : Record
        The record.

    Returns
    -------
    Problem
        The fit problem, started at the best of a grid over the input span; its parameters are
        ``p1``, ``p2`` and ``gain``.
    """
    u = record.u
    span = float(np.ptp(u))

    def parameters(theta, w):
        return {"p1": float(np.exp(theta[0])), "p2": float(np.exp(theta[1])), "gain": float(w[0])}
    def columns(theta):
        from hystmpc.models.compiled import parametric_outputs
        return parametric_outputs(u, *np.exp(theta))[:, None]
    problem = Problem([(np.arange(2), columns)], np.zeros(2),
                      np.log([1e-4 * span, 1e-3 / span]), np.log([span, 1e4 / span]), np.ones(1, bool), parameters,
                      names=("p1", "p2"))
    problem.theta = _best_start(problem, record, [np.log([span * a, b / span]) for a in (0.003, 0.01, 0.03, 0.1, 0.3)
                                                  for b in (0.3, 1, 3, 10, 30, 100)])
    return problem


def kp_problem(record: Record, creep: bool, levels: int = 12, max_span: int = 2, delta: float = 0.15,
               u_max: float = 0.0, u_min: float = float("nan")) -> Problem:
    """KP (and FCKP with ``creep``) with the density of wang2025 Fig. 3 on a threshold grid.

    The grid spans ``[u_min, u_max]``. The stroke and the output offset are projected (the
    offset inside the creep, where the models put it); ``c``, ``σ``, the range's free ends and α
    are moved.

    Parameters
    ----------
    record : Record
        The record.
    creep : bool
        Fit FCKP's creep order α; without it α stays 0 (KP).
    levels : int, optional
        Levels of the threshold grid.
    max_span : int, optional
        Widest kernel of the threshold grid (levels).
    delta : float, optional
        Width of the kernels' ridges.
    u_max : float, optional
        Upper end of the input range; 0: fitted.
    u_min : float, optional
        Lower end of the input range; NaN: fitted.

    Returns
    -------
    Problem
        The fit problem, started at the best of a grid of densities and ranges; its parameters
        are the grid's and ``density_c``, ``density_sigma``, ``stroke``, ``output_offset`` (and
        ``creep_order`` with ``creep``).
    """
    u = record.u
    lo_u, hi_u, span = float(np.min(u)), float(np.max(u)), float(np.ptp(u))
    given_hi, given_lo = u_max != 0, np.isfinite(u_min)
    if given_lo and given_hi and not u_min < u_max:
        raise ValueError(f"u_min = {u_min:g} must be below u_max = {u_max:g}")
    rho1, rho2 = threshold_grid(levels, delta, max_span)
    kernels_at: dict = {}

    def ends(theta):
        return (u_min if given_lo else theta[2]), (u_max if given_hi else theta[3])

    def kernels(lo, hi):
        from hystmpc.models.compiled import kp_kernel_outputs
        if (lo, hi) not in kernels_at:
            kernels_at.clear()
            p = 2.0 * (u - lo) / (hi - lo) - 1.0
            kernels_at[lo, hi] = kp_kernel_outputs(p, p[0], rho1, rho2, delta, ridge(p[0] - rho2, delta))
        return kernels_at[lo, hi]

    def columns(theta):  # the unit stroke's output and a constant, both through the creep
        mu = paper_density(rho1, rho2, theta[0], theta[1])
        w = 0.5 * (kernels(*ends(theta)) @ mu / mu.sum() + 1.0)
        return creep_integral(np.column_stack((w, np.ones(len(u)))), float(theta[4]), record.sample_period)

    def parameters(theta, w):
        lo, hi = ends(theta)
        doc = {"levels": levels, "max_span": max_span, "delta": delta, "u_max": float(hi), "u_min": float(lo),
               "density_c": float(theta[0]), "density_sigma": float(theta[1]),
               "stroke": float(max(w[0], 1e-12 * max(abs(float(w[1])), 1e-300))),  # no loop: the smallest
               "output_offset": float(w[1])}
        return doc | ({"creep_order": float(theta[4])} if creep else {})
    lower = np.array([0.05, 0.05, lo_u - 0.5 * span, hi_u - 0.25 * span, 0.0])
    upper = np.array([20.0, 20.0, lo_u + 0.25 * span, hi_u + 0.5 * span, 0.5 if creep else 1e-12])
    theta0 = np.array([2.0, 1.0, u_min if given_lo else lo_u, u_max if given_hi else hi_u, 0.02 if creep else 0.0])
    fixed = [given_lo, given_hi]
    for i, is_fixed in zip((2, 3), fixed, strict=True):
        if is_fixed:  # a given end stays: a zero-width search
            lower[i] = upper[i] = theta0[i]
    if not creep:
        lower[4] = upper[4] = 0.0
    problem = Problem([(np.arange(5), columns)], theta0, lower, upper, np.array([True, False]), parameters,
                      names=("density_c", "density_sigma", "u_min", "u_max", "creep_order"), intercept=False)
    starts = []
    for extend in (0.0, 0.1, 0.25):  # the grid on the data's range, and a little wider
        lo, hi = (theta0[2] if given_lo else lo_u - extend * span), (theta0[3] if given_hi else hi_u + extend * span)
        starts += [np.array([c, s, lo, hi, theta0[4]]) for c, s in
                   ((2.0, 1.0), (1.0, 0.5), (4.0, 2.0), (0.5, 0.3), (8.0, 4.0), (2.0, 0.3), (0.5, 2.0))]
    problem.theta = _best_start(problem, record, starts)
    return problem


def _polyline_start(s, tau, knots) -> np.ndarray:
    """Torques at ``knots`` of the least-squares polyline through (s, τ), made increasing."""
    knots = np.asarray(knots, float)
    basis = np.column_stack([np.interp(s, knots, np.eye(len(knots))[i]) for i in range(len(knots))])
    values = np.linalg.lstsq(basis, tau, rcond=None)[0]
    step = 1e-3 * max(float(np.ptp(tau)), 1e-12)
    for i in range(1, len(values)):
        values[i] = max(values[i], values[i - 1] + step)
    return values


def power_function_outputs_of(model: PowerFunctionHysteresis, s) -> np.ndarray:
    """The exact response of :meth:`PowerFunctionHysteresis.step` along ``s`` from ``initial_state(s[0])``.

    Parameters
    ----------
    model : PowerFunctionHysteresis
        The model.
    s : array_like
        Input record.

    Returns
    -------
    ndarray
        The output, one value per sample of ``s``.
    """
    from hystmpc.models.compiled import power_function_outputs
    a, d = np.asarray(model.ascending, float), np.asarray(model.descending, float)
    scale = model.torque_scale
    return power_function_outputs(np.asarray(s, float), a[:, 0].copy(), scale * a[:, 1], d[:, 0].copy(),
                                  scale * d[:, 1], model.k11, model.k01, model.k12, model.k02,
                                  np.asarray(model.exponent_positive, float),
                                  np.asarray(model.exponent_negative, float), *model.exponent_range)


def power_function_problem(record: Record, knots: int = 10, ascending_s: tuple = (),
                           descending_s: tuple = ()) -> Problem:
    """Polyline torques, transition widths and exponents moved; nothing projected.

    The torques carry the scale and an output offset.

    When both polylines span the same knots at their ends, they are made to meet there (a major
    loop closes at its tips, as Table V's points E and R): the descending polyline is never
    followed near the tips, so its ends could not be told from the data otherwise.

    Parameters
    ----------
    record : Record
        The record.
    knots : int, optional
        Number of evenly spaced knots of both polylines, started on the input's range with the
        grid's ends fitted too (when neither ``ascending_s`` nor ``descending_s`` is given).
    ascending_s : tuple of float, optional
        Fixed knots of the ascending polyline (at least two, increasing).
    descending_s : tuple of float, optional
        Fixed knots of the descending polyline (at least two, increasing).

    Returns
    -------
    Problem
        The fit problem with fixed unit weight and no intercept; its parameters are those of
        :class:`PowerFunctionHysteresis`.
    """
    u = record.u
    lo, hi = float(np.min(u)), float(np.max(u))
    span = hi - lo
    even = not len(ascending_s) and not len(descending_s)  # the grid's ends are fitted too
    s_a = np.asarray(ascending_s, float) if len(ascending_s) else np.linspace(lo, hi, knots)
    s_d = np.asarray(descending_s, float) if len(descending_s) else np.linspace(lo, hi, knots)
    for name, s in (("ascending_s", s_a), ("descending_s", s_d)):
        if len(s) < 2 or np.any(np.diff(s) <= 0):
            raise ValueError(f"{name} must be at least two increasing knots, got {[float(v) for v in s]}")
    na, nd = len(s_a), len(s_d)
    tied = s_a[0] == s_d[0] and s_a[-1] == s_d[-1] and nd >= 3
    shift = 1 if record.alignment == "next" else 0
    u_in, y_out = u[: len(u) - shift], record.y[shift:]
    rising = np.concatenate(([True], np.diff(u_in) > 0))
    tau_scale = max(float(np.ptp(y_out)), 1e-12)
    n_d = nd - 2 if tied else nd

    def grids(z):
        if not even:
            return s_a, s_d
        grid = z[-2] + np.exp(z[-1]) * np.linspace(0.0, 1.0, knots)
        return grid, grid

    def unpack(z):
        g_a, g_d = grids(z)
        a = z[0] + np.concatenate(([0.0], np.cumsum(np.exp(z[1:na]))))
        if tied:
            share = np.exp(np.concatenate(([0.0], z[na: na + n_d])))
            d = a[0] + (a[-1] - a[0]) * np.concatenate(([0.0], np.cumsum(share / share.sum())))
        else:
            d = z[na] + np.concatenate(([0.0], np.cumsum(np.exp(z[na + 1: na + nd]))))
        rest = z[na + n_d:]
        return PowerFunctionHysteresis(tuple(zip(g_a, a * tau_scale, strict=True)),
                                       tuple(zip(g_d, d * tau_scale, strict=True)),
                                       k11=rest[0], k01=rest[1] * span, k12=rest[2], k02=rest[3] * span,
                                       exponent_positive=(rest[4] / span**2, rest[5] / span, rest[6]),
                                       exponent_negative=(rest[7] / span**2, rest[8] / span, rest[9]))

    def pack(a, d, width=0.05, exponent=2.0, grid=(lo, hi)):
        a, d = np.asarray(a) / tau_scale, np.asarray(d) / tau_scale
        if tied:
            inc = np.maximum(np.diff(d), 1e-6)
            falling = np.log(inc[1:] / inc[0])
        else:
            falling = np.concatenate(([d[0]], np.log(np.diff(d))))
        transitions = [0.0, width, 0.0, width, 0.0, 0.0, exponent, 0.0, 0.0, exponent]  # Δs, b constant
        ends = [grid[0], np.log(grid[1] - grid[0])] if even else []
        return np.concatenate(([a[0]], np.log(np.diff(a)), falling, transitions, ends))

    def columns(z):
        try:
            out = power_function_outputs_of(unpack(z), u)
        except (ValueError, FloatingPointError, OverflowError, ZeroDivisionError):
            return np.full((len(u), 1), np.nan)
        return out[:, None]

    def parameters(z, w):
        model = unpack(z)
        return {"ascending": [list(map(float, p)) for p in model.ascending],
                "descending": [list(map(float, p)) for p in model.descending],
                "k11": float(model.k11), "k01": float(model.k01), "k12": float(model.k12), "k02": float(model.k02),
                "exponent_positive": [float(v) for v in model.exponent_positive],
                "exponent_negative": [float(v) for v in model.exponent_negative]}
    starts = []
    for extend in (0.0, 0.05, 0.1) if even else (0.0,):  # grids a little wider than the data, too
        grid = (lo - extend * span, hi + extend * span)
        g_a = np.linspace(*grid, knots) if even else s_a
        g_d = np.linspace(*grid, knots) if even else s_d
        polylines = _polyline_start(u_in[rising], y_out[rising], g_a), _polyline_start(u_in[~rising], y_out[~rising],
                                                                                       g_d)
        starts += [pack(*polylines, width, exponent, grid) for width in (0.02, 0.05, 0.12, 0.25)
                   for exponent in (1.3, 2.0, 3.0)]
    lower, upper = np.full(len(starts[0]), -np.inf), np.full(len(starts[0]), np.inf)
    first = na + n_d + 4  # the exponents' (g2·span², g1·span, g0), both signs: kept inside the clamp of
    for i in (first, first + 3):  # PowerFunctionHysteresis.exponent_range, where they have a gradient
        lower[i: i + 3], upper[i: i + 3] = (-30.0, -30.0, 1.0), (30.0, 30.0, 4.0)
    if even:  # the grid may move by half the span and stretch between a half and twice the span
        lower[-2:], upper[-2:] = (lo - 0.5 * span, np.log(0.5 * span)), (lo + 0.5 * span, np.log(2.0 * span))
    problem = Problem([(np.arange(len(starts[0])), columns)], starts[0], lower, upper, np.zeros(1, bool), parameters,
                      fixed_weights=np.ones(1), intercept=False)
    problem.theta = _best_start(problem, record, starts)
    return problem
