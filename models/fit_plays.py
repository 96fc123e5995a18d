"""Fit problems of the families built on play operators, and of a naive linear model.

The families are Prandtl–Ishlinskii, Maxwell-slip, Preisach and generalised
Prandtl–Ishlinskii; the naive linear model is the one they are measured against.

Each function turns a :class:`~hystmpc.models.record_fit.Record` and the family's fit options
into a :class:`~hystmpc.models.record_fit.Problem` whose start is already a good static fit:

* the thresholds start where non-negative least squares on a dense ladder (five candidates
  per play, evenly spaced in (0, half the input span)) puts weight; the refinement then moves
  each threshold on its own, so a play need not sit on any ladder;
* a Preisach density starts on an even ladder and a knot grid over the input range, and the
  refinement moves the thresholds and both ends of the grid; a smoothness penalty (the
  density's change from cell to cell) gives cells the record barely visits their neighbours'
  values;
* a generalised PI model starts from the PI fit with a straight output curve.
"""

from __future__ import annotations

import numpy as np

from hystmpc.models.preisach import cell_ramps
from hystmpc.models.projection import project
from hystmpc.models.record_fit import Problem, Record, respond

LADDER_DENSITY = 5
"""Candidate thresholds per play of the dense start ladder."""


def _plays(u, thresholds) -> np.ndarray:
    from hystmpc.models.compiled import play_outputs  # numba: imported when a fit first needs it
    thresholds = np.atleast_1d(np.asarray(thresholds, float))
    return play_outputs(u, thresholds, np.full(len(thresholds), u[0]))


def _span(u) -> float:
    return float(np.ptp(u))


def _log_bounds(u, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Thresholds from 1e-4 to half the input span (a wider play moves only on the record's first swing)."""
    span = _span(u)
    return np.full(n, np.log(1e-4 * span)), np.full(n, np.log(0.5 * span))


def _start_thresholds(record: Record, plays: int, column) -> np.ndarray:
    """The thresholds a dense ladder's non-negative fit (static, no block) gives weight to.

    At most ``plays`` of them, the heaviest.
    """
    from hystmpc.models.linear_dynamics import LinearDynamics
    u = record.u
    ladder = 0.5 * _span(u) * np.arange(1, LADDER_DENSITY * plays + 1) / (LADDER_DENSITY * plays + 1)
    columns = column(u, _plays(u, ladder))
    rows = record.rows()
    F = respond(columns, LinearDynamics(), record)[rows]
    w, _ = project(F, record.y[rows], np.ones(F.shape[1], bool))
    w = w[-len(ladder):]
    order = np.argsort(-w)[:plays]
    kept = np.sort(ladder[order[w[order] > 1e-9 * max(w.max(), 1e-300)]])
    return kept if len(kept) else ladder[[len(ladder) // 2]]


def _play_groups(u, n: int, transform):
    """One group per threshold: ``transform(u, plays)`` of its play's output."""
    def group(i):
        return (np.array([i]), lambda theta: transform(u, _plays(u, np.exp(theta))))
    return [group(i) for i in range(n)]


def prandtl_ishlinskii_problem(record: Record, plays: int = 10) -> Problem:
    """``y = p0·u + Σ p_i Play_{r_i}[u]``: the thresholds nonlinear, ``p0`` and ``p_i >= 0`` projected.

    Parameters
    ----------
    record : Record
        The record.
    plays : int, optional
        Most play operators (the start keeps the heaviest of the ladder's).

    Returns
    -------
    Problem
        The fit problem; its parameters are ``linear_gain``, ``thresholds`` and ``weights``.
    """
    u = record.u
    r0 = _start_thresholds(record, plays, lambda u, p: np.column_stack((u, p)))
    lower, upper = _log_bounds(u, len(r0))

    def parameters(theta, w):
        keep = w[1:] > 1e-12 * max(float(np.max(w)), 1e-300)
        return {"linear_gain": float(w[0]), "thresholds": [float(v) for v in np.exp(theta)[keep]],
                "weights": [float(v) for v in w[1:][keep]]}
    groups = [(np.zeros(0, int), lambda theta: u[:, None]), *_play_groups(u, len(r0), lambda u, p: p)]
    return Problem(groups, np.log(r0), lower, upper, np.ones(len(r0) + 1, bool), parameters,
                   names=tuple(f"thresholds[{i}]" for i in range(len(r0))))


def maxwell_slip_problem(record: Record, elements: int = 10) -> Problem:
    """``y = Σ k_i (u − Play_{r_i}[u])``: the thresholds nonlinear, ``k_i >= 0`` projected; ``w_i = k_i r_i``.

    Parameters
    ----------
    record : Record
        The record.
    elements : int, optional
        Most elasto-slide elements (the start keeps the heaviest of the ladder's).

    Returns
    -------
    Problem
        The fit problem; its parameters are ``stiffness`` and ``breakaway``.
    """
    u = record.u
    r0 = _start_thresholds(record, elements, lambda u, p: u[:, None] - p)
    lower, upper = _log_bounds(u, len(r0))

    def parameters(theta, w):
        keep = w > 1e-12 * max(float(np.max(w)), 1e-300)
        if not keep.any():
            raise ValueError("no Maxwell-slip element carries the data (every stiffness fitted to zero)")
        return {"stiffness": [float(v) for v in w[keep]], "breakaway": [float(v) for v in (w * np.exp(theta))[keep]]}
    return Problem(_play_groups(u, len(r0), lambda u, p: u[:, None] - p), np.log(r0), lower, upper,
                   np.ones(len(r0), bool), parameters, names=tuple(f"thresholds[{i}]" for i in range(len(r0))))


def _knots(theta_lo, theta_width, cells: int) -> np.ndarray:
    return theta_lo + np.exp(theta_width) * np.linspace(0.0, 1.0, cells + 1)


def _differences(rows: int, cols: int) -> np.ndarray:
    """Smoothness-penalty rows for a density on a ``rows × cols`` grid.

    Rows of first differences along each row of a ``rows × cols`` grid (flattened row-wise),
    and second differences down the columns of the plays' rows (row 0, the reversible part,
    stands apart): a density that changes little from cell to cell, so that cells a record
    barely visits take their neighbours' values (a Prandtl–Ishlinskii model in the limit).
    """
    out = []
    for i in range(rows):
        for j in range(cols - 1):
            d = np.zeros((rows, cols))
            d[i, j: j + 2] = (-1.0, 1.0)
            out.append(d.ravel())
    for j in range(cols):
        for i in range(2, rows - 1):
            d = np.zeros((rows, cols))
            d[i - 1: i + 2, j] = (1.0, -2.0, 1.0)
            out.append(d.ravel())
    return np.array(out).reshape(-1, rows * cols)


def preisach_problem(record: Record, plays: int = 8, cells: int = 8, smoothing: float = 1e-6) -> Problem:
    """A Preisach density on ``plays`` thresholds (and the reversible part) × ``cells`` knot cells.

    Parameters
    ----------
    record : Record
        The record.
    plays : int, optional
        Number of play thresholds, in [0, 50].
    cells : int, optional
        Number of knot cells, in [1, 50].
    smoothing : float, optional
        Weight of the smoothness penalty (0: none).

    Returns
    -------
    Problem
        The fit problem; its parameters are ``thresholds``, ``knots`` and ``density``.
    """
    if not (isinstance(cells, int) and 1 <= cells <= 50):
        raise ValueError(f"cells must be an integer in [1, 50], got {cells}")
    if not (isinstance(plays, int) and 0 <= plays <= 50):
        raise ValueError(f"plays must be an integer in [0, 50], got {plays}")
    if not (np.isfinite(smoothing) and smoothing >= 0):
        raise ValueError(f"smoothing must be >= 0, got {smoothing}")
    u = record.u
    span, lo = _span(u), float(np.min(u))
    r0 = 0.5 * span * np.arange(1, plays + 1) / (plays + 1)
    theta0 = np.concatenate((np.log(r0), [lo, np.log(span)]))
    lower_r, upper_r = _log_bounds(u, plays)
    lower = np.concatenate((lower_r, [lo - span, np.log(0.25 * span)]))
    upper = np.concatenate((upper_r, [lo + 0.5 * span, np.log(4.0 * span)]))
    k = np.array([plays, plays + 1])  # the grid's entries of theta

    groups = [(k, lambda t: cell_ramps(u, _knots(t[0], t[1], cells), True))]
    for i in range(plays):
        groups.append((np.array([i, *k]), lambda t: cell_ramps(_plays(u, np.exp(t[0]))[:, 0],
                                                               _knots(t[1], t[2], cells), False)))
    difference = _differences(plays + 1, cells)
    weight = np.sqrt(smoothing * len(record.rows()))

    def penalty(theta):  # on the shape's change per cell, in output units
        return weight * difference * np.tile(np.diff(_knots(theta[-2], theta[-1], cells)), plays + 1)

    def parameters(theta, w):
        return {"thresholds": [float(v) for v in np.exp(theta[:plays])],
                "knots": [float(v) for v in _knots(theta[-2], theta[-1], cells)],
                "density": [[float(v) for v in row] for row in w.reshape(plays + 1, cells)]}
    names = (*(f"thresholds[{i}]" for i in range(plays)), "knots[0]", "knot span")
    return Problem(groups, theta0, lower, upper, np.ones((plays + 1) * cells, bool), parameters,
                   penalty=penalty if smoothing > 0 else None, names=names, joint_hold=(plays, plays + 1))


def generalised_pi_problem(record: Record, plays: int = 8, cells: int = 6, start: dict | None = None) -> Problem:
    """``y = Γ(PI[u])``, started from a PI fit (``start``, fitted here when not given).

    The PI part's weights (normalised to unit gain), its thresholds and Γ's knots nonlinear,
    Γ's slopes projected (>= 0).

    Parameters
    ----------
    record : Record
        The record.
    plays : int, optional
        Most play operators of the PI fit made when ``start`` is not given.
    cells : int, optional
        Number of Γ's cells over the PI output's range, in [1, 50].
    start : dict, optional
        Parameters of a PI fit (``linear_gain``, ``thresholds``, ``weights``).

    Returns
    -------
    Problem
        The fit problem; its parameters are ``linear_gain``, ``thresholds``, ``weights``,
        ``output_knots`` and ``output_values``.
    """
    if not (isinstance(cells, int) and 1 <= cells <= 50):
        raise ValueError(f"cells must be an integer in [1, 50], got {cells}")
    u = record.u
    if start is None:
        from hystmpc.models.linear_dynamics import LinearDynamics
        from hystmpc.models.record_fit import refine
        pi = prandtl_ishlinskii_problem(record, plays)
        fit = refine(pi, record, LinearDynamics(), move_block=False)
        start = pi.parameters(fit.theta, fit.weights)
    weights = np.concatenate(([max(start["linear_gain"], 1e-6 * sum(start["weights"]) + 1e-300)], start["weights"]))
    n = len(start["thresholds"])
    theta0 = np.concatenate((np.log(weights / weights.sum()), np.log(start["thresholds"]), np.zeros(cells)))
    lower_r, upper_r = _log_bounds(u, n)
    lower = np.concatenate((np.full(n + 1, -30.0), lower_r, np.full(cells, -5.0)))
    upper = np.concatenate((np.full(n + 1, 5.0), upper_r, np.full(cells, 5.0)))

    def pi_output(theta):
        p = np.exp(theta[: n + 1])
        p = p / p.sum()
        return p[0] * u + (_plays(u, np.exp(theta[n + 1: 2 * n + 1])) @ p[1:] if n else 0.0)

    def knots(v, theta):  # over the PI output's range, the cells' shares of it moved too
        lo, hi = float(np.min(v)), float(np.max(v)) + 1e-12 * (1 + abs(float(np.max(v))))
        share = np.exp(theta[2 * n + 1:])
        return lo + (hi - lo) * np.concatenate(([0.0], np.cumsum(share) / share.sum()))

    def columns(theta):
        v = pi_output(theta)
        return cell_ramps(v, knots(v, theta), True)

    def parameters(theta, w):
        p = np.exp(theta[: n + 1])
        p = p / p.sum()
        v_knots = knots(pi_output(theta), theta)
        slopes = np.maximum(w, 1e-9 * max(float(np.max(w)), 1e-300))
        values = np.concatenate(([0.0], np.cumsum(slopes * np.diff(v_knots))))
        return {"linear_gain": float(p[0]), "thresholds": [float(v) for v in np.exp(theta[n + 1: 2 * n + 1])],
                "weights": [float(v) for v in p[1:]], "output_knots": [float(v) for v in v_knots],
                "output_values": [float(v) for v in values]}
    names = (*(f"weights[{i}]" for i in range(n + 1)), *(f"thresholds[{i}]" for i in range(n)),
             *(f"output cell {j}" for j in range(cells)))
    return Problem([(np.arange(2 * n + 1 + cells), columns)], theta0, lower, upper, np.ones(cells, bool),
                   parameters, names=names, iterations=80)  # the curve and the plays trade off: slow to settle


def linear_problem(record: Record) -> Problem:
    """The naive model: ``y = k·u`` (any sign) and an offset, no memory.

    Parameters
    ----------
    record : Record
        The record.

    Returns
    -------
    Problem
        The fit problem; its parameter is ``gain``.
    """
    u = record.u
    return Problem([(np.zeros(0, int), lambda theta: u[:, None])], np.zeros(0), np.zeros(0), np.zeros(0),
                   np.array([False]), lambda theta, w: {"gain": float(w[0])})
