"""Preisach hysteresis with a discretised density, written as a sum of shaped play operators.

A Preisach relay switches up at ``α`` and down at ``β <= α``; in the coordinates
``r = (α − β)/2`` (half-width) and ``s = (α + β)/2`` (centre) it is "up" exactly when the
play operator of threshold ``r`` has its output above ``s``. So a Preisach model with
density ``μ(r, s) >= 0`` is ``y = ∫ ψ_r(Play_r[u]) dr`` with ``ψ_r(z) = ∫ μ(r, s) sgn(z − s) ds``
nondecreasing in ``z`` (Brokate and Sprekels' representation). Discretised: ``n`` thresholds
``r_i`` (each a band of half-widths) plus the reversible part ``r_0 = 0`` (``Play_0[u] = u``),
and a density constant on each cell ``[s_j, s_{j+1}]`` of a knot grid, so every ``ψ_i`` is
piecewise linear with slopes ``μ_ij >= 0``::

    y = Σ_i Σ_j μ_ij · clip(z_i − s_j, 0, s_{j+1} − s_j),     z_0 = u,  z_i = Play_{r_i}[u].

The reversible part continues beyond the grid with its end slopes (``min(u − s_0, Δ_0)`` and
``max(u − s_{m−1}, 0)``), so the output is not clipped where the record's input ended.
Prandtl–Ishlinskii (``μ_ij`` constant in ``j``) and Krasnoselskii–Pokrovskii (smooth relays on a
grid) are special cases. The output is continuous, piecewise linear in ``u`` and monotone along
a monotone input path, so the inverse is exact.

State: ``[u_last, z_1, …, z_n]``; the relaxed state at ``u0`` has every play centred there.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from hystmpc.models.base import (
    SteppedModel,
    builtin_max,
    builtin_min,
    check_smoothing,
    clip,
    smooth_function,
    symbolic,
)
from hystmpc.models.inverse_search import bisection_inverse
from hystmpc.models.smooth import smooth_clip, smooth_max, smooth_min


def cell_ramps(z, knots, reversible: bool) -> np.ndarray:
    """``clip(z − s_j, 0, s_{j+1} − s_j)`` for every cell of ``knots`` (a new last axis).

    Parameters
    ----------
    z : array_like
        Play outputs, any shape.
    knots : array_like
        Cell bounds ``s_0 < … < s_m``.
    reversible : bool
        Whether the end cells continue beyond the grid (the reversible part's shape).

    Returns
    -------
    ndarray
        Shape ``z.shape + (m,)``: the ramp of each cell.
    """
    s = np.asarray(knots, float)
    width = np.diff(s)
    z = np.asarray(z, float)[..., None]
    ramps = np.clip(z - s[:-1], 0.0, width)
    if reversible:
        ramps[..., 0] = np.minimum(z[..., 0] - s[0], width[0])
        ramps[..., -1] = np.maximum(z[..., 0] - s[-2], 0.0) if len(width) > 1 else z[..., 0] - s[0]
    return ramps


@dataclass(frozen=True)
class Preisach(SteppedModel):
    """Preisach model ``y = Σ_i ψ_i(Play_{r_i}[u])`` with piecewise-linear ``ψ_i`` (see the module)."""

    thresholds: tuple[float, ...]
    """Play half-widths ``r_1..r_n > 0`` (input units); the reversible part ``r_0 = 0`` is implied."""
    knots: tuple[float, ...]
    """Relay centres ``s_0 < … < s_m`` (input units) bounding the density's cells."""
    density: tuple[tuple[float, ...], ...]
    """``(n + 1) × m`` slopes ``μ_ij >= 0`` (output per input unit); row 0 is the reversible part."""

    def __post_init__(self):
        thresholds = tuple(float(r) for r in self.thresholds)
        knots = tuple(float(s) for s in self.knots)
        density = tuple(tuple(float(v) for v in row) for row in self.density)
        object.__setattr__(self, "thresholds", thresholds)
        object.__setattr__(self, "knots", knots)
        object.__setattr__(self, "density", density)
        if not all(np.isfinite(r) and r > 0 for r in thresholds):
            raise ValueError(f"thresholds must be finite and > 0, got {thresholds}")
        if len(knots) < 2 or not np.all(np.isfinite(knots)) or np.any(np.diff(knots) <= 0):
            raise ValueError(f"knots must be at least two finite, increasing values, got {knots}")
        if len(density) != len(thresholds) + 1 or any(len(row) != len(knots) - 1 for row in density):
            raise ValueError(f"density must have {len(thresholds) + 1} rows (the reversible part, then one per "
                             f"threshold) of {len(knots) - 1} slopes (one per knot cell)")
        values = np.asarray(density)
        if not (np.all(np.isfinite(values)) and np.all(values >= 0)):
            raise ValueError("density slopes must be finite and >= 0")
        if not np.any(values > 0):
            raise ValueError("a Preisach model needs a positive density somewhere")

    @property
    def n_plays(self) -> int:
        """Number of play operators (thresholds), the reversible part not counted."""
        return len(self.thresholds)

    @property
    def state_names(self) -> tuple[str, ...]:
        """``u_last`` and the play outputs ``z_1..z_n``."""
        return ("u_last", *(f"play_{i + 1}" for i in range(self.n_plays)))

    def initial_state(self, u0: float = 0.0) -> np.ndarray:
        """Relaxed at ``u0``: every play centred on the input.

        Parameters
        ----------
        u0 : float, optional
            Input.

        Returns
        -------
        ndarray
            ``[u0, u0, …, u0]`` (``n + 1`` entries).
        """
        return np.full(self.n_plays + 1, float(u0))

    # ----- the shape functions ψ_i --------------------------------------------------------------------
    def _shape(self, i: int, z, eps: float | None = None):
        """ψ_i(z) on CasADi or NumPy values; ``eps`` smooths its kinks."""
        s, mu = self.knots, self.density[i]
        last = len(mu) - 1
        total = 0.0
        for j, slope in enumerate(mu):
            if slope == 0:
                continue
            lo, hi = s[j], s[j + 1]
            half = 0.5 * (hi - lo)
            if i == 0 and last == 0:
                ramp = z - lo
            elif i == 0 and j == 0:
                ramp = smooth_min(z - lo, hi - lo, eps) if eps else _min(z - lo, hi - lo)
            elif i == 0 and j == last:
                ramp = smooth_max(z - lo, 0.0, eps) if eps else _max(z - lo, 0.0)
            elif eps:
                ramp = half + smooth_clip(z - lo - half, half, eps)
            else:
                ramp = clip(z - lo, 0.0, hi - lo) if symbolic(z) else min(max(z - lo, 0.0), hi - lo)
            total = total + slope * ramp
        return total

    def output(self, state):
        """Output of a state (NumPy or CasADi).

        Parameters
        ----------
        state : ndarray or CasADi expression
            ``[u_last, z_1, …, z_n]``.

        Returns
        -------
        float or CasADi expression
            The output.
        """
        if symbolic(state):
            return sum((self._shape(i, state[i]) for i in range(self.n_plays + 1)), 0)
        state = np.asarray(state, float)
        return float(sum(self._shape(i, state[i]) for i in range(self.n_plays + 1)))

    def outputs(self, states) -> np.ndarray:
        """Outputs of many states (rows), vectorised.

        Parameters
        ----------
        states : array_like, shape (k, n + 1)
            One state per row (a single state counts as one row).

        Returns
        -------
        ndarray, shape (k,)
            The output of each state.
        """
        states = np.atleast_2d(np.asarray(states, float))
        mu = np.asarray(self.density)
        total = np.einsum("kj,j->k", cell_ramps(states[:, 0], self.knots, True), mu[0])
        if self.n_plays:
            total += np.einsum("kij,ij->k", cell_ramps(states[:, 1:], self.knots, False), mu[1:])
        return total

    # ----- steps --------------------------------------------------------------------------------------
    def step(self, state, u: float) -> tuple[np.ndarray, float]:
        """Exact step to input ``u``: ``(state, y)`` (CasADi expressions when ``state`` or ``u`` is one).

        Parameters
        ----------
        state : ndarray or CasADi expression
            State before the step.
        u : float or CasADi expression
            New input; a NumPy one must be finite (else ``ValueError``).

        Returns
        -------
        state : ndarray or CasADi expression
            State after the step.
        y : float or CasADi expression
            Output after the step.
        """
        r = np.asarray(self.thresholds)
        if symbolic(state) or symbolic(u):
            z = clip(state[1:], u - ca.DM(r), u + ca.DM(r)) if self.n_plays else ca.SX(0, 1)
            nxt = ca.vertcat(u, z)
            return nxt, self.output(nxt)
        if not np.isfinite(u):
            raise ValueError(f"u must be finite, got {u}")
        z = np.clip(np.asarray(state, float)[1:], u - r, u + r)
        nxt = np.concatenate(([float(u)], z))
        return nxt, self.output(nxt)

    def smooth_step(self, eps: float, direction_eps: float | None = None) -> ca.Function:
        """Smooth step ``(state, u) -> (state_next, y)``.

        Each play's clip and each kink of the shape functions are smoothed over ``eps``.

        A smoothed play errs by at most ``eps/2`` (1-Lipschitz), so after ``n`` steps a play is
        within ``n·eps/2``; each kink adds at most ``eps/2`` times its slope. The output error is
        at most ``(n·eps/2 + eps/2) · Σ_ij μ_ij``.

        Parameters
        ----------
        eps : float
            Smoothing width (input units), > 0.
        direction_eps : None
            Must stay unset: no direction detection (``ValueError`` otherwise).

        Returns
        -------
        casadi.Function
            ``(state, u) -> (state_next, y)``.
        """
        check_smoothing(eps, direction_eps, has_direction=False)
        r = self.thresholds

        def expressions(state, u):
            z = [u + smooth_clip(state[1 + i] - u, r[i], eps) for i in range(self.n_plays)]
            y = self._shape(0, u, eps) + sum((self._shape(i + 1, z[i], eps) for i in range(self.n_plays)), 0.0)
            return ca.vertcat(u, *z), y
        return smooth_function("preisach_smooth", self.n_plays + 1, expressions)

    # ----- inverse ------------------------------------------------------------------------------------
    def linear_beyond(self) -> tuple[tuple[float, float], float]:
        """``(edges, reach)`` for the bisection.

        Once a move has gone ``reach`` and past ``edges``, every play follows the input beyond the
        knots, and only the reversible part's end slope is left.

        Returns
        -------
        edges : tuple of float
            ``(s_0 − r_max, s_m + r_max)`` (input units).
        reach : float
            ``2·r_max`` (input units).
        """
        r_max = max(self.thresholds, default=0.0)
        return (self.knots[0] - r_max, self.knots[-1] + r_max), 2.0 * r_max

    def tail_slopes(self) -> tuple[float, float]:
        """The output's slope once the input is beyond every knot and play: downwards, upwards.

        Returns
        -------
        tuple of float
            The reversible part's first and last cell slopes, ``(μ_00, μ_0,m−1)``.
        """
        return self.density[0][0], self.density[0][-1]

    def inverse_step(self, state, y_target: float) -> tuple[np.ndarray, float]:
        """The input that brings the output to ``y_target`` from ``state``, and the state after it.

        Found along a monotone move (exact: the output is piecewise linear and monotone along the
        move). A target beyond the model's reach gives the input where the output stops changing.
        On CasADi expressions: bisection (:func:`hystmpc.models.inverse_search.bisection_inverse`).

        Parameters
        ----------
        state : ndarray or CasADi expression
            State to move from.
        y_target : float or CasADi expression
            Output to reach; a NumPy one must be finite (else ``ValueError``).

        Returns
        -------
        state : ndarray or CasADi expression
            State after the move.
        u : float or CasADi expression
            The input.
        """
        if symbolic(state) or symbolic(y_target):
            return bisection_inverse(self, state, y_target, *self.linear_beyond(), self.tail_slopes())
        if not np.isfinite(y_target):
            raise ValueError(f"y_target must be finite, got {y_target}")
        state = np.asarray(state, float)
        u0, z = state[0], state[1:]
        y0 = self.output(state)
        if y_target == y0:
            return state.copy(), float(u0)
        d = 1.0 if y_target > y0 else -1.0
        r, s = np.asarray(self.thresholds), np.asarray(self.knots)
        candidates = np.concatenate((z + d * r, (s[None, :] + d * r[:, None]).ravel(), s))
        candidates = np.unique(candidates[(candidates - u0) * d > 0])
        candidates = candidates[np.argsort((candidates - u0) * d)]
        moved = np.maximum(z, candidates[:, None] - r) if d > 0 else np.minimum(z, candidates[:, None] + r)
        ys = self.outputs(np.column_stack((candidates, moved)))
        past = np.flatnonzero((ys - y_target) * d >= 0)
        if len(past):
            k = past[0]
            u_prev, y_prev = (u0, y0) if k == 0 else (candidates[k - 1], ys[k - 1])
            u = u_prev + (y_target - y_prev) * (candidates[k] - u_prev) / (ys[k] - y_prev)
        else:
            tail = self.density[0][-1 if d > 0 else 0]
            u_end = candidates[-1] if len(candidates) else u0
            y_end = ys[-1] if len(candidates) else y0
            u = u_end + (y_target - y_end) / tail if tail > 0 else u_end
        return self.step(state, float(u))[0], float(u)


def _min(a, b):
    return builtin_min(a, b) if symbolic(a) or symbolic(b) else min(a, b)


def _max(a, b):
    return builtin_max(a, b) if symbolic(a) or symbolic(b) else max(a, b)
