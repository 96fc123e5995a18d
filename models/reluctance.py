"""The reluctance actuator as its controllers know it: identified from major loops (katalenic2013).

Eq. (12): the current drives the parametric hysteresis H (p1, p2(g) = p2/g), whose output
X is mapped to force by a per-gap look-up table: i = IH[Lut(F, g)] (12a) and
F = Lut⁻¹(H[i], g) (12b). :func:`fit_reluctance_model` identifies p1, p2 and the tables
from major loops (Section 3.5) and fits the single-valued polynomial inverse of the
paper's baseline; :func:`prediction_model` is the NMPC's model.
"""

from __future__ import annotations

import bisect
import functools
import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from hystmpc.models.base import interp, symbolic
from hystmpc.models.parametric import ParametricHysteresis, identify_major_loop
from hystmpc.models.prediction import Dynamics, PredictionModel, build_prediction_model
from hystmpc.models.smooth import smooth_max


@dataclass(frozen=True)
class ReluctanceModel:
    """What identification gives the controllers: p1, p2 and per-gap tables (eq. (12))."""

    p1: float
    p2: float
    gaps: tuple[float, ...]
    """Identified air gaps (m), increasing."""
    tables: tuple[tuple[np.ndarray, np.ndarray], ...]
    """Per gap: (F, X) of the ascending look-up table, F increasing."""
    poly: np.ndarray
    """Coefficients of i = Σ c_ab (√F)^a (g/1 mm)^b, a + b <= 4, over all gaps (poly-inverse)."""

    def neighbours(self, gap: float) -> tuple[int, int, float]:
        """Indices of the identified gaps around ``gap`` and the weight of the upper one.

        Parameters
        ----------
        gap : float
            Air gap (m).

        Returns
        -------
        lower, upper : int
            Indices into ``gaps``; outside the identified range both are the nearest end.
        weight : float
            Weight of ``upper`` in [0, 1] (0 outside the identified range).
        """
        if not np.isfinite(gap):
            raise ValueError(f"gap must be finite, got {gap}")
        gaps = [float(g) for g in self.gaps]
        if gap <= gaps[0]:
            return 0, 0, 0.0
        if gap >= gaps[-1]:
            return len(gaps) - 1, len(gaps) - 1, 0.0
        j = bisect.bisect_left(gaps, gap)  # np.searchsorted's side="left"
        return j - 1, j, (gap - gaps[j - 1]) / (gaps[j] - gaps[j - 1])

    def x_of_force(self, force, gap: float):
        """Lut(F, g): linear in F within a gap's table, linear between gaps (eq. (15)).

        Parameters
        ----------
        force : float, ndarray or CasADi expression
            Force (N); the tables' end values hold beyond them.
        gap : float
            Air gap (m).

        Returns
        -------
        float, ndarray or CasADi expression
            H's output X (A).
        """
        a, b, w = self.neighbours(gap)
        xa = interp(force, *self.tables[a])
        xb = interp(force, *self.tables[b])
        return (1 - w) * xa + w * xb

    def force_of_x(self, x, gap: float):
        """Lut⁻¹(X, g).

        Parameters
        ----------
        x : float or ndarray
            H's output X (A); the tables' end values hold beyond them.
        gap : float
            Air gap (m).

        Returns
        -------
        float or ndarray
            Force (N).
        """
        a, b, w = self.neighbours(gap)
        if isinstance(x, float):  # one sample (a controller's step): Python floats
            tables = self._float_tables
            return (1 - w) * interp_float(x, *tables[a]) + w * interp_float(x, *tables[b])
        fa = np.interp(x, self.tables[a][1], self.tables[a][0])
        fb = np.interp(x, self.tables[b][1], self.tables[b][0])
        return (1 - w) * fa + w * fb

    @functools.cached_property
    def _float_tables(self) -> tuple[tuple[list[float], list[float]], ...]:
        """Per gap, (X, F) as lists of floats for :func:`interp_float`."""
        return tuple((np.asarray(x, float).tolist(), np.asarray(f, float).tolist()) for f, x in self.tables)

    def poly_current(self, force, gap: float):
        """Single-valued 4th-order polynomial inverse i(F, g).

        Parameters
        ----------
        force : float or array_like
            Force (N).
        gap : float
            Air gap (m).

        Returns
        -------
        ndarray
            Current (A), at least 1-D (shape (1,) for a scalar force).
        """
        if isinstance(force, float) and isinstance(gap, float):
            return poly_features(force, gap)[np.newaxis] @ self.poly  # the same (1, 15) product
        return poly_features(np.atleast_1d(force), gap) @ self.poly

    def operator(self, gap: float) -> ParametricHysteresis:
        """H with the air-gap law p2(g) = p2/g.

        Parameters
        ----------
        gap : float
            Air gap (m).

        Returns
        -------
        ParametricHysteresis
            H at ``gap``.
        """
        return ParametricHysteresis(self.p1, self.p2 / gap)

    def force_table(self, gap: float) -> tuple[np.ndarray, np.ndarray]:
        """(X, F) points of Lut⁻¹ at ``gap``, anchored at the origin.

        The identified table between the neighbouring gaps (a gap's own table when it was
        identified), with the points where the slope does not change dropped, and (0, 0)
        put in front: no current, no force. Without that anchor the table's lowest point
        (noise-level force) would be extended flat to zero current, where a model with no
        slope gives a Gauss–Newton step nothing to follow.

        Parameters
        ----------
        gap : float
            Air gap (m).

        Returns
        -------
        x : ndarray
            H's output X at the points (A), increasing.
        force : ndarray
            Force at the points (N).
        """
        a, b, w = self.neighbours(gap)
        if w in (0.0, 1.0):
            x_pts = np.asarray(self.tables[b if w == 1.0 else a][1], float)
        else:
            x_pts = np.unique(np.concatenate((self.tables[a][1], self.tables[b][1])))
        f_pts = self.force_of_x(x_pts, gap)
        keep = np.concatenate(([True], (np.diff(x_pts) > 1e-6) & (np.diff(f_pts) > 0)))
        x_pts, f_pts = x_pts[keep], f_pts[keep]
        if x_pts[0] > 0 and f_pts[0] > 0:
            x_pts, f_pts = np.concatenate(([0.0], x_pts)), np.concatenate(([0.0], f_pts))
        slopes = np.diff(f_pts) / np.diff(x_pts)
        bends = np.abs(np.diff(slopes)) > 1e-9 * np.abs(slopes).max()
        keep = np.concatenate(([True], bends, [True]))
        return x_pts[keep], f_pts[keep]

    def smooth_force_of_x(self, gap: float, kink_eps: float = 1e-4):
        """Lut⁻¹(X, g) as the polyline of :meth:`force_table` with its kinks rounded over ``kink_eps``.

        Meant for CasADi. ``kink_eps = 0``: the polyline itself, a binary-search look-up (CasADi's
        linear interpolant, extended linearly beyond the table), what :func:`prediction_model` uses
        by default; the rounded default suits interior-point NLPs (:func:`offline_optimum`).

        Parameters
        ----------
        gap : float
            Air gap (m).
        kink_eps : float, optional
            Width over which each kink is rounded (A), >= 0 (else ``ValueError``).

        Returns
        -------
        callable
            X -> F (N), linear beyond the table; on CasADi expressions, and on NumPy values
            (a float for a scalar X).
        """
        if not (np.isfinite(kink_eps) and kink_eps >= 0):
            raise ValueError(f"kink_eps must be finite and >= 0 (0: the exact polyline), got {kink_eps}")
        xs, fs = self.force_table(gap)
        if kink_eps == 0.0:
            lookup = ca.interpolant("force_table", "linear", [xs], fs, {"lookup_mode": ["binary"]})
            def exact(v):
                if symbolic(v):
                    return lookup(v)
                values = np.asarray(lookup(np.ravel(np.asarray(v, float))), float)
                return float(values[0, 0]) if np.ndim(v) == 0 else values.reshape(np.shape(v))
            return exact
        slopes = np.diff(fs) / np.diff(xs)

        def force(v):
            value = fs[0] + slopes[0] * (v - xs[0])
            for k in range(1, len(slopes)):
                value = value + (slopes[k] - slopes[k - 1]) * smooth_max(v - xs[k], 0.0, kink_eps)
            return value
        return force


def interp_float(x: float, xp: list[float], fp: list[float]) -> float:
    """``np.interp(x, xp, fp)`` of one float, with NumPy's operations (and so its double).

    Parameters
    ----------
    x : float
        Where to interpolate.
    xp, fp : list of float
        The points, ``xp`` increasing; the end values hold beyond them.

    Returns
    -------
    float
        The interpolated value.
    """
    if x != x:
        return x
    if x > xp[-1]:
        return fp[-1]
    if x < xp[0]:
        return fp[0]
    j = bisect.bisect_right(xp, x) - 1
    if j == len(xp) - 1 or xp[j] == x:
        return fp[j]
    slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])
    value = slope * (x - xp[j]) + fp[j]
    if value != value:  # NumPy tries from the other end
        value = slope * (x - xp[j + 1]) + fp[j + 1]
        if value != value and fp[j] == fp[j + 1]:
            value = fp[j]
    return value


def poly_features(force, gap):
    """Features (√F)^a (g/1 mm)^b, a + b <= 4, of the polynomial inverse.

    Parameters
    ----------
    force : array_like
        Force (N); negative values count as 0.
    gap : float or array_like
        Air gap (m), broadcast to the shape of ``force``.

    Returns
    -------
    ndarray
        The 15 features on a new last axis, ordered by a, then b.
    """
    if isinstance(force, float) and isinstance(gap, float):  # one sample: Python floats, ~20 × faster
        root, g = math.sqrt(max(float(force), 0.0)), float(gap) / 1e-3
        try:
            return np.array([_power(root, a) * _power(g, b) for a in range(5) for b in range(5 - a)])
        except OverflowError:  # NumPy's inf, below
            pass
    root = np.sqrt(np.maximum(np.asarray(force, float), 0.0))
    g = np.broadcast_to(np.asarray(gap, float) / 1e-3, root.shape)
    return np.stack([root**a * g**b for a in range(5) for b in range(5 - a)], axis=-1)


def _power(x: float, n: int) -> float:
    """``x**n`` as NumPy computes it for an array (a square is ``x * x``, other powers ``pow``)."""
    return x * x if n == 2 else x**n


def fit_reluctance_model(loops: dict[float, tuple[np.ndarray, np.ndarray]], window: int = 1) -> ReluctanceModel:
    """Identify the model from major loops ``loops[g] = (current, force)`` (Section 3.5).

    p1, p2 and the ascending tables by :func:`hystmpc.models.parametric.identify_major_loop`
    (tables made single-valued and monotone), and one polynomial in force and air gap over
    both branches of every loop, as in the paper's reference [2].

    Parameters
    ----------
    loops : dict
        ``loops[g] = (current, force)`` per air gap g (m): the current 0 -> max -> 0 (A) and the
        measured force (N).
    window : int, optional
        Samples averaged per look-up-table point (1: the paper's plain table).

    Returns
    -------
    ReluctanceModel
        The identified model.
    """
    gaps = tuple(sorted(loops))
    p1, p2, luts = identify_major_loop(loops, window=window)
    tables = []
    for g in gaps:
        f_tab, x_tab = luts[g]
        f_tab, keep = np.unique(f_tab, return_index=True)
        tables.append((f_tab, np.maximum.accumulate(x_tab[keep])))
    features = np.concatenate([poly_features(loops[g][1], g) for g in gaps])
    currents = np.concatenate([loops[g][0] for g in gaps])
    poly = np.linalg.lstsq(features, currents, rcond=None)[0]
    return ReluctanceModel(p1, p2, gaps, tuple(tables), poly)


def prediction_model(model: ReluctanceModel, gap: float, sample_period: float, eps: float,
                     direction_eps: float | None = None, kink_eps: float = 0.0) -> PredictionModel:
    """F = Lut⁻¹(H[i], g), eq. (12b), with the smooth H and the table as a polyline.

    The polyline's kinks are rounded over ``kink_eps`` (see
    :meth:`ReluctanceModel.smooth_force_of_x`).

    Force is not measured in operation: no sensors, no disturbance; the state is H's. The
    static inverse is the table, Lut(F, g) (for warm starts: IH[Lut(F, g)], eq. (12a)).

    Parameters
    ----------
    model : ReluctanceModel
        The identified model.
    gap : float
        Air gap (m).
    sample_period : float
        Sample period (s).
    eps : float
        Smoothing width of H (A; see :meth:`ParametricHysteresis.smooth_step`).
    direction_eps : float, optional
        Width of H's direction detection (A); None: ``eps``.
    kink_eps : float, optional
        Rounding of the table's kinks (A); 0: the exact polyline.

    Returns
    -------
    PredictionModel
        The NMPC's prediction model, named ``reluctance``.
    """
    force = model.smooth_force_of_x(gap, kink_eps)
    dynamics = Dynamics(output=lambda x, h: force(h), sensor_names=(),
                        steady_input=lambda f: model.x_of_force(
                            ca.if_else(f < 0.0, 0.0, f) if symbolic(f) else np.maximum(f, 0.0), gap))
    return build_prediction_model(model.operator(gap), sample_period, dynamics=dynamics, eps=eps,
                                  direction_eps=direction_eps, disturbance="none", name="reluctance")


def offline_optimum(model: ReluctanceModel, gap: float, reference: np.ndarray, current_limit: float,
                    slew_per_sample: float) -> np.ndarray:
    """Best slew-limited currents for a whole reference, known in advance (a lower bound).

    Minimises Σ_k (F_{k+1} − r_{k+1})² over the full run under the current bounds and slew
    limit, with the identified model: F = Lut⁻¹(X, g) and X = H[i]. The NLP is posed in X
    (the hysteresis-free static part, solved by IPOPT), then the exact inverse IH turns X
    into currents; H moves X from i by less than p1, so the slew limit holds to within p1
    (the plant's amplifier enforces it exactly). No causal controller, with any horizon, can
    do better on this model than this sequence.

    Parameters
    ----------
    model : ReluctanceModel
        The identified model.
    gap : float
        Air gap (m).
    reference : ndarray, shape (n,)
        Force reference at each sample (N).
    current_limit, slew_per_sample : float
        Largest current (A) and current change per sample (A).

    Returns
    -------
    ndarray, shape (n,)
        Current commanded at each sample (A).
    """
    import casadi as ca

    ref = np.asarray(reference, float)
    n = len(ref)
    force = model.smooth_force_of_x(gap, kink_eps=1e-4)  # IPOPT wants the rounded, smooth table
    opti = ca.Opti()
    x = opti.variable(n)
    opti.subject_to(opti.bounded(-slew_per_sample, x - ca.vertcat(0.0, x[:-1]), slew_per_sample))
    opti.subject_to(opti.bounded(0.0, x, current_limit))
    target = np.append(ref[1:], ref[-1])  # the current of sample k shows in the force at k+1
    opti.minimize(ca.sumsqr(force(x) - target))
    greedy = np.empty(n)
    last = 0.0
    for k in range(n):
        last = float(np.clip(model.x_of_force(max(target[k], 0.0), gap), last - slew_per_sample,
                             last + slew_per_sample))
        greedy[k] = last
    opti.set_initial(x, greedy)
    opti.solver("ipopt", {"print_time": False}, {"print_level": 0, "sb": "yes", "max_iter": 500})
    try:
        x_opt = np.asarray(opti.solve().value(x), float)
    except RuntimeError as exc:
        raise RuntimeError(f"offline optimum did not converge: {exc}") from exc
    op = model.operator(gap)
    state, currents = op.initial_state(0.0), np.empty(n)
    for k in range(n):
        state, currents[k] = op.inverse_step(state, float(x_opt[k]))
    return np.clip(currents, 0.0, current_limit)
