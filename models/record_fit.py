"""Simulation-error least squares on a measured record: the engine every family's fit shares.

A candidate model predicts the record as

    ŷ = A(L[Σ_j w_j φ_j(θ)]) + c = Σ_j w_j A(L[φ_j(θ)]) + c,

where the ``φ_j`` are hysteresis-output columns that depend on nonlinear parameters ``θ``
(thresholds, grid ends, exponents), ``w`` their weights (linear: a PI model's play weights, a
Preisach density, a stroke), ``L`` the linear block with its dead time (started at its steady
state, so it passes constants), ``A`` the record's row alignment and ``c`` the output offset.
Because ``L`` and ``A`` are linear, for given ``θ`` and block the best ``w`` (non-negative where
the family says) and ``c`` follow from a small constrained least-squares problem; scipy's
``least_squares`` then moves ``θ`` and the block's parameters on that *projected* residual
(variable projection). Columns are computed in groups, each depending on a few entries of
``θ`` (one play's threshold), and cached, so a finite-difference step re-simulates one group.

The block's parameter vector and its creep are in :mod:`hystmpc.models.block_parameters`, the
projection in :mod:`hystmpc.models.projection`, the search for a block and dead time behind
one hysteresis output in :mod:`hystmpc.models.block_fit`.

Row alignment: ``next`` (a sampled control loop: ``y_k`` is measured before ``u_k`` acts, so a
static model gives ``y_{k+1} = H[u]_k``) or ``same`` (a quasi-static loop tracer: ``y_k = H[u]_k``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from hystmpc.models.block_parameters import MOST_CREEP, block_bounds, block_of, block_theta
from hystmpc.models.fractional import creep_integral
from hystmpc.models.linear_dynamics import LinearDynamics
from hystmpc.models.projection import project_normal

ALIGNMENTS = ("next", "same")
COST_ROWS = 6_000
"""At most this many evenly spaced samples enter the refinement's cost (every sample is
simulated); the final weights use every sample."""


@dataclass(frozen=True)
class Record:
    """A measured record as a fit sees it."""

    u: np.ndarray
    y: np.ndarray
    sample_period: float
    alignment: str = "next"
    """``next`` or ``same`` (module docstring)."""
    warm_up: int = 0
    """Leading samples simulated but left out of the cost (an unknown initial state)."""

    def __post_init__(self):
        if self.alignment not in ALIGNMENTS:
            raise ValueError(f"alignment {self.alignment!r}; allowed: {', '.join(ALIGNMENTS)}")
        if not 0 <= self.warm_up < len(self.u) - 10:
            raise ValueError(f"warm-up of {self.warm_up} samples leaves fewer than 10 of the {len(self.u)} to fit")

    def rows(self, limit: int | None = COST_ROWS) -> np.ndarray:
        """The samples of the cost: after the warm-up, at most ``limit`` evenly spaced.

        Parameters
        ----------
        limit : int or None, optional
            Most samples kept (default: :data:`COST_ROWS`); None keeps every one.

        Returns
        -------
        ndarray
            Indices of the samples, increasing.
        """
        rows = np.arange(self.warm_up, len(self.u))
        if limit is not None and len(rows) > limit:
            rows = rows[np.round(np.linspace(0, len(rows) - 1, limit)).astype(int)]
        return rows


def respond(columns: np.ndarray, block: LinearDynamics, record: Record) -> np.ndarray:
    """What the sensor reads, row by row, for hysteresis outputs ``columns`` (one signal per column).

    The outputs go through the block (from its steady state at each column's first value), the
    dead time, then the record's row alignment.

    Parameters
    ----------
    columns : ndarray
        Hysteresis outputs, one per sample: a vector or one signal per column.
    block : LinearDynamics
        The linear block with its dead time.
    record : Record
        The record (its sample period and alignment).

    Returns
    -------
    ndarray
        The sensor readings, of the shape of ``columns``.
    """
    columns = np.asarray(columns, float)
    flat = columns.ndim == 1
    h = columns[:, None] if flat else columns
    if record.alignment == "same":
        h = np.vstack((h, h[-1:]))
    out = block.response(h, record.sample_period, from_steady_state=True)
    if record.alignment == "same":
        out = out[1:]
    return out[:, 0] if flat else out


# ----- a family's problem -----------------------------------------------------------------------------

@dataclass
class Problem:
    """What a family gives the engine: grouped columns, their constraints and its parameters.

    ``groups[g] = (indices, columns)``: ``columns(theta[indices]) -> (n_samples, p_g)``.
    """

    groups: Sequence[tuple[np.ndarray, Callable[[np.ndarray], np.ndarray]]]
    theta: np.ndarray
    """The nonlinear parameters' start."""
    lower: np.ndarray
    upper: np.ndarray
    nonneg: np.ndarray
    """Per column: weight constrained to >= 0."""
    parameters: Callable[[np.ndarray, np.ndarray], dict]
    """``(theta, w) -> the document's parameters``."""
    penalty: Callable[[np.ndarray], np.ndarray] | None = None
    """``theta -> rows`` added to the weights' least squares (smoothness), or None."""
    fixed_weights: np.ndarray | None = None
    """Weights held at these values (only the offset is projected)."""
    names: tuple[str, ...] = ()
    """Names of the entries of ``theta`` (for the bound warning)."""
    intercept: bool = True
    """The output offset is a constant added to the prediction; False: a family's own column
    carries it (fckp's, inside the creep)."""
    iterations: int = 30
    """Gauss–Newton steps a refinement takes at most."""
    lower_is_limit: tuple[int, ...] = ()
    """Entries of ``theta`` whose lower bound is the model's own limit, not a search bound
    (Bouc–Wen's ``n = 1``, the classical model): no at-a-bound warning there."""
    joint_hold: tuple[int, ...] = ()
    """Entries of ``theta`` the joint refinement with a linear block leaves where the static one
    put them (every group depends on them: a Preisach grid's ends)."""
    _cache: dict = field(default_factory=dict, repr=False)
    _creep_parts: dict = field(default_factory=dict, repr=False)
    _last: tuple | None = field(default=None, repr=False)
    _y_rows: tuple | None = field(default=None, repr=False)

    def columns(self, theta: np.ndarray) -> np.ndarray:
        """Every hysteresis-output column at ``theta`` (unfiltered).

        Parameters
        ----------
        theta : ndarray
            The nonlinear parameters.

        Returns
        -------
        ndarray
            ``(n_samples, p)``: the groups' columns side by side.
        """
        return np.hstack([fn(np.asarray(theta)[idx]) for idx, fn in self.groups])

    def _group(self, g: int, theta, block: LinearDynamics, record: Record, rows: np.ndarray):
        """``(key, filtered columns on rows)`` of group ``g``, cached."""
        idx, fn = self.groups[g]
        key = (g, tuple(np.asarray(theta)[idx]), block.kind, *block_theta(block), block.creep_times,
               block.delay_samples, record.alignment, len(rows), int(rows[0]), int(rows[-1]))
        if key not in self._cache:
            if len(self._cache) > 3 * len(self.groups) + 8:
                self._cache.clear()
            if block.creep:
                filtered = self._through_creep(g, theta, block, record)
            else:
                filtered = respond(fn(np.asarray(theta)[idx]), block, record)
            self._cache[key] = np.ascontiguousarray(filtered[rows])
        return key, self._cache[key]

    def _through_creep(self, g: int, theta, block: LinearDynamics, record: Record) -> np.ndarray:
        """:func:`respond` of group ``g`` through a block with creep.

        Each creep element's response to the group's latest columns is kept, so a step in a
        creep share only recombines them and a step in a time constant filters for that one.
        """
        idx, fn = self.groups[g]
        key = (tuple(np.asarray(theta)[idx]), record.alignment, len(record.u))
        kept = self._creep_parts.get(g)
        if kept is None or kept[0] != key:
            h = np.asarray(fn(np.asarray(theta)[idx]), float)
            if record.alignment == "same":
                h = np.vstack((h, h[-1:]))
            start = h[:1]
            kept = (key, start, h - start, {})
            self._creep_parts[g] = kept
        _, start, moved, responses = kept
        if len(responses) > 4 * len(block.creep) + 4:
            responses.clear()
        for tau in block.creep_times:
            if tau not in responses:
                responses[tau] = LinearDynamics(creep=((0.0, tau),)).creep_elements(moved, record.sample_period)[0]
        shares = [share for share, _ in block.creep]
        crept = start + (1.0 - sum(shares)) * moved + sum(share * responses[tau] for share, tau in block.creep)
        out = replace(block, creep=()).response(crept, record.sample_period, from_steady_state=True)
        return out[1:] if record.alignment == "same" else out

    def responses(self, theta: np.ndarray, block: LinearDynamics, record: Record) -> np.ndarray:
        """The filtered, aligned columns on every sample (not cached).

        Parameters
        ----------
        theta : ndarray
            The nonlinear parameters.
        block : LinearDynamics
            The linear block with its dead time.
        record : Record
            The record.

        Returns
        -------
        ndarray
            ``(n_samples, p)``: :meth:`columns` through :func:`respond`.
        """
        return respond(self.columns(theta), block, record)

    def _normal_equations(self, parts, y: np.ndarray):
        """``(F, FᵀF, Fᵀy, Σ F)`` for the groups ``parts``.

        Updates the last call's in the columns of the groups that changed (a finite-difference step
        changes one or two).
        """
        keys = [key for key, _ in parts]
        widths = [block.shape[1] for _, block in parts]
        last = self._last
        if last is None or len(last[0]) != len(keys) or last[1].shape[1] != sum(widths):
            F = np.hstack([block for _, block in parts])
            FtF, Fty, sums = F.T @ F, F.T @ y, F.sum(axis=0)
        else:
            F, FtF, Fty, sums = (a.copy() for a in last[1:5])
            edges = np.concatenate(([0], np.cumsum(widths)))
            changed = [g for g, (old, new) in enumerate(zip(last[0], keys, strict=True)) if old != new]
            cols = np.concatenate([np.arange(edges[g], edges[g + 1]) for g in changed]) if changed else []
            for g in changed:
                F[:, edges[g]:edges[g + 1]] = parts[g][1]
            if len(cols):
                rows_block = F[:, cols].T @ F
                FtF[cols, :] = rows_block
                FtF[:, cols] = rows_block.T
                Fty[cols] = F[:, cols].T @ y
                sums[cols] = F[:, cols].sum(axis=0)
        self._last = (keys, F, FtF, Fty, sums)
        return F, FtF, Fty, sums

    def solve(self, theta, block: LinearDynamics, record: Record, rows: np.ndarray):
        """``(weights, offset, prediction on rows)`` at ``theta`` and ``block``.

        Parameters
        ----------
        theta : ndarray
            The nonlinear parameters.
        block : LinearDynamics
            The linear block with its dead time.
        record : Record
            The record.
        rows : ndarray
            Indices of the samples the weights are projected on.

        Returns
        -------
        tuple
            ``(w, c, prediction)``: the weights (``fixed_weights`` if set), the offset and the
            prediction on ``rows``.
        """
        parts = [self._group(g, theta, block, record, rows) for g in range(len(self.groups))]
        y = record.y[rows]
        if self.fixed_weights is not None:
            F = np.hstack([part[1] for part in parts])
            w = self.fixed_weights
            c = float(np.mean(y - F @ w)) if self.intercept else 0.0
        else:
            if self._y_rows is None or self._y_rows[0] is not record or not np.array_equal(self._y_rows[1], rows):
                self._y_rows = (record, rows, y)
                self._last = None
            y = self._y_rows[2]
            F, FtF, Fty, sums = self._normal_equations(parts, y)
            w, c = project_normal(FtF, Fty, sums, float(np.sum(y)), len(rows), self.nonneg,
                                  None if self.penalty is None else self.penalty(theta), self.intercept)
        return w, c, F @ w + c


def with_creep(problem: Problem, record: Record) -> Problem:
    """``problem`` with a Grünwald–Letnikov creep ``D^(−α)`` after its hysteresis output.

    Every group goes through the creep, α is a new last entry of ``theta`` (in [0, 0.5)), and the
    output offset is a column of ones through the creep (where a model with creep carries it).

    Parameters
    ----------
    problem : Problem
        A problem with an intercept and free weights (``ValueError`` otherwise).
    record : Record
        The record (its length and sample period).

    Returns
    -------
    Problem
        The new problem; its parameters add ``creep_order`` and ``output_offset``.
    """
    if problem.fixed_weights is not None or not problem.intercept:
        raise ValueError("this family takes no creep of this kind (its scale or offset is its own parameter)")
    a, n, period = len(problem.theta), len(record.u), record.sample_period

    def through(indices, fn):
        return np.append(indices, a), lambda t: creep_integral(fn(t[:-1]), float(t[-1]), period)
    groups = [through(idx, fn) for idx, fn in problem.groups]
    groups.append((np.array([a]), lambda t: creep_integral(np.ones((n, 1)), float(t[0]), period)))

    def parameters(theta, w):
        return {**problem.parameters(theta[:-1], w[:-1]), "creep_order": float(theta[-1]),
                "output_offset": float(w[-1])}
    return Problem(groups, np.append(problem.theta, 0.01), np.append(problem.lower, 0.0), np.append(problem.upper, 0.5),
                   np.append(problem.nonneg, False), parameters, problem.penalty and (lambda t: np.hstack((
                       problem.penalty(t[:-1]), np.zeros((len(problem.penalty(t[:-1])), 1))))),
                   names=(*problem.names, "creep_order"), intercept=False, iterations=problem.iterations,
                   joint_hold=problem.joint_hold, lower_is_limit=problem.lower_is_limit)


@dataclass
class Fit:
    """A fitted candidate: parameters, block, offset and how well it fits."""

    theta: np.ndarray
    block: LinearDynamics
    weights: np.ndarray
    offset: float
    rmse: float
    at_bounds: tuple[str, ...] = ()


def evaluate(problem: Problem, theta, block: LinearDynamics, record: Record) -> Fit:
    """The fit at ``theta`` and ``block`` with the weights projected on every cost sample.

    Parameters
    ----------
    problem : Problem
        The family's problem.
    theta : array_like
        The nonlinear parameters.
    block : LinearDynamics
        The linear block with its dead time.
    record : Record
        The record; every sample after the warm-up counts.

    Returns
    -------
    Fit
        The fit; its RMSE is infinite where the prediction is not finite.
    """
    rows = record.rows(None)
    w, c, pred = problem.solve(theta, block, record, rows)
    rmse = float(np.sqrt(np.mean((pred - record.y[rows]) ** 2)))
    return Fit(np.asarray(theta, float), block, w, c, rmse if np.isfinite(rmse) else np.inf)


def refine(problem: Problem, record: Record, block: LinearDynamics, move_block: bool = True,
           iterations: int | None = None, hold: tuple[int, ...] = ()) -> Fit:
    """Move ``theta`` (and the block's parameters if ``move_block``) to the least simulation error.

    The weights and offset are projected at each step, each Gauss–Newton step one
    finite-difference Jacobian; the dead time stays. Entries whose bounds coincide stay where
    they are.

    Parameters
    ----------
    problem : Problem
        The family's problem, started at its ``theta``.
    record : Record
        The record.
    block : LinearDynamics
        The linear block: its parameters are the start, its dead time stays.
    move_block : bool, optional
        Move the block's parameters too.
    iterations : int, optional
        Most Gauss–Newton steps (default: the problem's ``iterations``).
    hold : tuple of int, optional
        Entries of ``theta`` that stay where they are.

    Returns
    -------
    Fit
        The fit on every sample after the warm-up, with the names of the entries that ended at a bound.
    """
    from scipy.optimize import least_squares

    kind, delay = block.kind, block.delay_samples
    n_h = len(problem.theta)
    z0 = np.concatenate((problem.theta, block_theta(block) if move_block else []))
    lo_d, hi_d = block_bounds(kind, record.sample_period, len(block.creep)) if move_block else ([], [])
    lower, upper = np.concatenate((problem.lower, lo_d)), np.concatenate((problem.upper, hi_d))
    free = lower < upper
    free[list(hold)] = False
    width = np.where(np.isfinite(upper - lower), upper - lower, 0.0)
    z0 = np.where(free, np.clip(z0, lower + 1e-9 * width, upper - 1e-9 * width), z0)
    rows = record.rows()
    y = record.y[rows]
    scale = max(float(np.std(y)), 1e-300)

    def split(z_free):
        z = z0.copy()
        z[free] = z_free
        return z[:n_h], (block_of(kind, z[n_h:], delay, len(block.creep)) if move_block else block)

    def residual(z_free):
        theta, blk = split(z_free)
        with np.errstate(all="ignore"):
            r = (problem.solve(theta, blk, record, rows)[2] - y) / scale
        return np.where(np.isfinite(r), r, 1e3)

    z_free = z0[free]
    if len(z_free):
        result = least_squares(residual, z_free, bounds=(lower[free], upper[free]), x_scale="jac", xtol=1e-8,
                               ftol=1e-8, max_nfev=iterations or problem.iterations)
        z_free = result.x
    theta, blk = split(z_free)
    fit = evaluate(problem, theta, blk, record)
    z = z0.copy()
    z[free] = z_free
    at_lower = np.abs(z - lower) < 1e-6 * width
    at_lower[list(problem.lower_is_limit)] = False
    near = free & (at_lower | (np.abs(upper - z) < 1e-6 * width)) & (width > 0)
    m = len(block.creep) if move_block else 0
    if m:  # an element with no share is simply not there, and its time constant means nothing
        unused = np.array([share < 1e-6 for share, _ in blk.creep])
        near[len(z) - 2 * m:len(z) - m] &= ~at_lower[len(z) - 2 * m:len(z) - m]
        near[len(z) - m:] &= ~unused
    names = list(problem.names) + (["time_constant"] if kind == "first-order" else
                                   ["natural_frequency_hz", "damping"] if kind == "second-order" else []) + \
        [f"creep share ({tau:.3g} s)" for tau in blk.creep_times] + \
        [f"creep time constant ({tau:.3g} s)" for tau in blk.creep_times]
    fit.at_bounds = tuple(names[i] if i < len(names) else f"parameter {i}" for i in np.flatnonzero(near))
    if move_block and sum(share for share, _ in fit.block.creep) > (1 - 1e-3) * MOST_CREEP:
        fit.at_bounds += (f"creep shares (together at their most, {MOST_CREEP})",)
    return fit
