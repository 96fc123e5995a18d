"""Power-function hysteresis of a nonlinear compliant actuator (zhou2024, eqs. (8)–(31)).

Torque τ is a hysteretic function of the virtual deformation s (eq. (8)):

* an **ascending** polyline τ_al(s), used while s increases past the turning point s01,
  and a **descending** polyline τ_dl(s), used while s decreases past s02 (eqs. (14)–(15),
  calibration points of Table V: X..A..E ascending and E..I..R descending, sorted by s);
* a **transition** curve after every reversal of s (eqs. (16)–(17), (19)):
  up:   τ = τ_r + (τ_al(s01) − τ_r)·((s − s02)/(s01 − s02))^b(s02)
  down: τ = τ_r − (τ_r − τ_dl(s02))·((s01 − s)/(s01 − s02))^b(s01)
  where the turning points follow eqs. (10)–(11) with Table VI
  (s01 = s02 + Δs2(s02) after a minimum, s02 = s01 − Δs1(s01) after a maximum) and the
  exponent b(s0) is the quadratic of eq. (18) with Table VII. In eq. (17) the factor
  ``c·a(s0)`` is fixed by eq. (19), so ``a(s0)`` cancels and only ``b`` shapes the curve.

**One deliberate deviation.** The paper's transition starts at τ_dl(s02) (or τ_al(s01))
and only updates a turning point beyond the current one (third condition of eqs.
(12)–(13)). Then a reversal *inside* a transition makes τ jump, because the up and down
curves through the same two points differ. Here every reversal starts a new transition at
the current torque τ_r. This is identical to the paper whenever the reversal happens on a
polyline, and continuous everywhere.

State: ``[s_last, up, s01, s02, tau_r, tau_last]`` with ``up`` = 1 while s increases.
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
from hystmpc.models.smooth import smooth_max, smooth_min

# zhou2024 Table V: (s, τ [N m]); s in the paper's scaled units (see VirtualDeformation).
TABLE_V = {
    "A": (0.0, 0.077), "B": (0.00651, 0.37), "C": (0.0083, 0.538), "D": (0.0305, 1.5077),
    "E": (0.0459, 2.074), "F": (0.0455, 1.91), "G": (0.0361, 1.492), "H": (0.0241, 1.066),
    "I": (0.00724, 0.323), "J": (-0.0017, -0.126), "K": (-0.00335, -0.169), "L": (-0.00869, -0.446),
    "M": (-0.015, -0.8154), "N": (-0.0227, -1.046), "O": (-0.0275, -1.401), "P": (-0.033, -1.631),
    "Q": (-0.0428, -1.849), "R": (-0.046, -1.977), "S": (-0.0436, -1.6779), "T": (-0.03949, -1.3798),
    "U": (-0.0204, -0.8), "V": (-0.0177, -0.6), "W": (-0.00372, -0.1484), "X": (-0.0027, -0.0384),
}
ASCENDING_POINTS = "RSTUVWXABCDE"   # used while s increases (negative side R–X, positive A–E)
DESCENDING_POINTS = "RQPONMLKJIHGFE"  # used while s decreases (positive side E–I, negative J–R)


def _polyline(points, x, relu):
    """Piecewise-linear through ``points`` (sorted by x), extrapolated linearly at both ends.

    Written as a base line plus slope changes at the kinks, so that ``relu = max(·, 0)``
    gives the exact polyline and a smooth ``relu`` a smooth one.
    """
    xs = [p[0] for p in points]
    ys = [p[1] for p in points]
    slopes = [(ys[i + 1] - ys[i]) / (xs[i + 1] - xs[i]) for i in range(len(xs) - 1)]
    value = ys[0] + slopes[0] * (x - xs[0])
    for i in range(1, len(slopes)):
        value = value + (slopes[i] - slopes[i - 1]) * relu(x - xs[i])
    return value


def _exact_relu(x):
    return ca.if_else(x < 0.0, 0.0, x) if symbolic(x) else np.maximum(x, 0.0)


@dataclass(frozen=True)
class PowerFunctionHysteresis(SteppedModel):
    """zhou2024's power-function hysteresis model; defaults are Tables V–VII."""

    ascending: tuple[tuple[float, float], ...] = tuple(TABLE_V[p] for p in ASCENDING_POINTS)
    """(s, τ) points of τ_al, strictly increasing in s and τ (Table V)."""
    descending: tuple[tuple[float, float], ...] = tuple(TABLE_V[p] for p in DESCENDING_POINTS)
    """(s, τ) points of τ_dl, strictly increasing in s and τ (Table V)."""
    k11: float = -0.02048
    """Δs1(s01) = k11·s01 + k01, eq. (11), Table VI."""
    k01: float = 0.00157
    k12: float = 0.03293
    """Δs2(s02) = k12·s02 + k02, eq. (11), Table VI."""
    k02: float = 0.00298
    exponent_positive: tuple[float, float, float] = (-1145.0, 64.34, 1.474)
    """(g2, g1, g0) of b(s0) = g2 s0² + g1 s0 + g0 for s0 > 0, eq. (18), Table VII."""
    exponent_negative: tuple[float, float, float] = (-38.60, 24.20, 2.718)
    """(g2, g1, g0) of b(s0) for s0 < 0, Table VII."""
    torque_scale: float = 1.0
    """Multiplies every torque (for off-nominal plants)."""

    def __post_init__(self):
        for name in ("ascending", "descending"):
            pts = np.asarray(getattr(self, name), float)
            if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 2:
                raise ValueError(f"{name} must be at least two (s, tau) points")
            if np.any(np.diff(pts[:, 0]) <= 0) or np.any(np.diff(pts[:, 1]) <= 0):
                raise ValueError(f"{name} points must increase strictly in s and in tau")
        if not self.torque_scale > 0:
            raise ValueError(f"torque_scale must be > 0, got {self.torque_scale}")

    # ----- pieces of the model, valid for NumPy and CasADi arguments -------------------------
    def _points(self, which):
        pts = self.ascending if which == "al" else self.descending
        return [(s, self.torque_scale * t) for s, t in pts]

    def tau_ascending(self, s, relu=_exact_relu):
        """τ_al(s), eq. (14).

        Parameters
        ----------
        s : float, ndarray or CasADi expression
            Virtual deformation.
        relu : callable, optional
            ``max(·, 0)`` at the kinks; a smooth one gives a smooth polyline.

        Returns
        -------
        float, ndarray or CasADi expression
            The torque (times ``torque_scale``).
        """
        return _polyline(self._points("al"), s, relu)

    def tau_descending(self, s, relu=_exact_relu):
        """τ_dl(s), eq. (15).

        Parameters
        ----------
        s : float, ndarray or CasADi expression
            Virtual deformation.
        relu : callable, optional
            ``max(·, 0)`` at the kinks; a smooth one gives a smooth polyline.

        Returns
        -------
        float, ndarray or CasADi expression
            The torque (times ``torque_scale``).
        """
        return _polyline(self._points("dl"), s, relu)

    def s_ascending(self, tau):
        """Inverse of τ_al (eq. (25)): the s on the ascending polyline with torque ``tau``.

        Parameters
        ----------
        tau : float, ndarray or CasADi expression
            Torque.

        Returns
        -------
        float, ndarray or CasADi expression
            The virtual deformation.
        """
        return _polyline([(t, s) for s, t in self._points("al")], tau, _exact_relu)

    def s_descending(self, tau):
        """Inverse of τ_dl (eq. (26)).

        Parameters
        ----------
        tau : float, ndarray or CasADi expression
            Torque.

        Returns
        -------
        float, ndarray or CasADi expression
            The s on the descending polyline with torque ``tau``.
        """
        return _polyline([(t, s) for s, t in self._points("dl")], tau, _exact_relu)

    def delta_s1(self, s01):
        """Width of the transition after a maximum at s01, eq. (11).

        Parameters
        ----------
        s01 : float or CasADi expression
            The maximum's s.

        Returns
        -------
        float or CasADi expression
            Δs1 = k11·s01 + k01.
        """
        return self.k11 * s01 + self.k01

    def delta_s2(self, s02):
        """Width of the transition after a minimum at s02, eq. (11).

        Parameters
        ----------
        s02 : float or CasADi expression
            The minimum's s.

        Returns
        -------
        float or CasADi expression
            Δs2 = k12·s02 + k02.
        """
        return self.k12 * s02 + self.k02

    exponent_range = (1.0, 4.0)
    """b is clamped to this range. Over Table V's span b lies in [1.47, 2.72], where the clamp
    is inactive; eq. (18)'s quadratic turns negative for s0 > 0.07, where a power < 1 would
    make the transition's slope infinite at the turning point."""

    def exponent(self, s0, eps: float | None = None):
        """b(s0), eq. (18); the Table VII set is picked by the sign of s0 (blended if ``eps``).

        Parameters
        ----------
        s0 : float or CasADi expression
            The turning point.
        eps : float, optional
            Width of the ``tanh`` blend of the two sets; None: exact (a float ``s0`` only).

        Returns
        -------
        float or CasADi expression
            b, clamped to :attr:`exponent_range` (smoothly with ``eps``).
        """
        gp, gn = self.exponent_positive, self.exponent_negative
        bp = gp[0] * s0**2 + gp[1] * s0 + gp[2]
        bn = gn[0] * s0**2 + gn[1] * s0 + gn[2]
        lo, hi = self.exponent_range
        if eps is None:
            return min(max(bp if s0 > 0 else bn, lo), hi)
        w = 0.5 * (1 + ca.tanh(s0 / eps))
        return smooth_max(smooth_min(w * bp + (1 - w) * bn, hi, 0.01), lo, 0.01)

    # ----- the common model shape --------------------------------------------------------------
    state_names = ("s_last", "up", "s01", "s02", "tau_r", "tau")
    """Last input, direction flag (1 while s increases), turning points, torque at the last
    reversal, torque."""

    def initial_state(self, s0: float | None = None) -> np.ndarray:
        """Resting on the ascending polyline at ``s0`` (default: where τ_al = 0).

        Parameters
        ----------
        s0 : float or CasADi expression, optional
            Virtual deformation the state rests at; a CasADi ``s0`` gives the state as an expression.

        Returns
        -------
        ndarray or CasADi expression
            The state ``[s0, 1, s0, s0 − Δs1(s0), τ_al(s0), τ_al(s0)]``.
        """
        if symbolic(s0):
            tau = self.tau_ascending(s0)
            return ca.vertcat(s0, 1.0, s0, s0 - self.delta_s1(s0), tau, tau)
        s0 = float(self.s_ascending(0.0)) if s0 is None else float(s0)
        tau = float(self.tau_ascending(s0))
        return np.array([s0, 1.0, s0, s0 - self.delta_s1(s0), tau, tau])

    def output(self, state):
        """Torque of a state (NumPy or CasADi).

        Parameters
        ----------
        state : ndarray or CasADi expression
            A state.

        Returns
        -------
        float or CasADi expression
            Its last entry, the torque.
        """
        return state[5] if symbolic(state) else float(state[5])

    def _up_branch(self, s, s01, s02, tau_r):
        if s >= s01:
            return float(self.tau_ascending(s))
        x = (max(s, s02) - s02) / (s01 - s02)
        return float(tau_r + (self.tau_ascending(s01) - tau_r) * x ** self.exponent(s02))

    def _down_branch(self, s, s01, s02, tau_r):
        if s <= s02:
            return float(self.tau_descending(s))
        y = (s01 - min(s, s01)) / (s01 - s02)
        return float(tau_r - (tau_r - self.tau_descending(s02)) * y ** self.exponent(s01))

    def _exponent_expr(self, s0):
        """:meth:`exponent` (exact) on a CasADi expression, with Python's min and max."""
        gp, gn = self.exponent_positive, self.exponent_negative
        b = ca.if_else(s0 > 0, gp[0] * s0**2 + gp[1] * s0 + gp[2], gn[0] * s0**2 + gn[1] * s0 + gn[2])
        lo, hi = self.exponent_range
        return builtin_min(builtin_max(b, lo), hi)

    def _step_expr(self, state, s):
        """:meth:`step` on CasADi expressions: the same comparisons, as ``if_else``."""
        s_last, up, s01, s02, tau_r, tau_last = (state[i] for i in range(6))
        was_min = ca.logic_and(s > s_last, up < 0.5)
        was_max = ca.logic_and(ca.logic_not(was_min), ca.logic_and(s < s_last, up >= 0.5))
        s02 = ca.if_else(was_min, s_last, ca.if_else(was_max, s_last - self.delta_s1(s_last), s02))
        s01 = ca.if_else(was_min, s_last + self.delta_s2(s_last), ca.if_else(was_max, s_last, s01))
        tau_r = ca.if_else(ca.logic_or(was_min, was_max), tau_last, tau_r)
        up = ca.if_else(was_min, 1.0, ca.if_else(was_max, 0.0, up))
        x = (builtin_max(s, s02) - s02) / (s01 - s02)
        up_branch = ca.if_else(s >= s01, self.tau_ascending(s),
                               tau_r + (self.tau_ascending(s01) - tau_r) * x ** self._exponent_expr(s02))
        y = (s01 - builtin_min(s, s01)) / (s01 - s02)
        down_branch = ca.if_else(s <= s02, self.tau_descending(s),
                                 tau_r - (tau_r - self.tau_descending(s02)) * y ** self._exponent_expr(s01))
        tau = ca.if_else(s == s_last, tau_last, ca.if_else(up >= 0.5, up_branch, down_branch))
        return ca.vertcat(s, up, s01, s02, tau_r, tau), tau

    def _inverse_step_expr(self, state, tau):
        """:meth:`inverse_step` on CasADi expressions (a non-finite ``tau`` gives NaN, not an error)."""
        s_last, up, s01, s02, tau_r, tau_last = (state[i] for i in range(6))
        # rising torque
        s02_up = ca.if_else(up < 0.5, s_last, s02)
        s01_up = ca.if_else(up < 0.5, s_last + self.delta_s2(s_last), s01)
        tau_r_up = ca.if_else(up < 0.5, tau_last, tau_r)
        tau_01 = self.tau_ascending(s01_up)
        ratio = builtin_min(builtin_max((tau - tau_r_up) / (tau_01 - tau_r_up), 0.0), 1.0)
        s_rise = ca.if_else(ca.logic_or(tau >= tau_01, tau_01 <= tau_r_up), self.s_ascending(tau),
                            s02_up + ratio ** (1.0 / self._exponent_expr(s02_up)) * (s01_up - s02_up))
        # falling torque
        s01_dn = ca.if_else(up >= 0.5, s_last, s01)
        s02_dn = ca.if_else(up >= 0.5, s_last - self.delta_s1(s_last), s02)
        tau_r_dn = ca.if_else(up >= 0.5, tau_last, tau_r)
        tau_02 = self.tau_descending(s02_dn)
        ratio = builtin_min(builtin_max((tau_r_dn - tau) / (tau_r_dn - tau_02), 0.0), 1.0)
        s_fall = ca.if_else(ca.logic_or(tau <= tau_02, tau_02 >= tau_r_dn), self.s_descending(tau),
                            s01_dn - ratio ** (1.0 / self._exponent_expr(s01_dn)) * (s01_dn - s02_dn))
        s = ca.if_else(tau > tau_last, s_rise, s_fall)
        moved, _ = self._step_expr(state, s)
        unmoved = tau == tau_last
        s = ca.if_else(unmoved, s_last, s)
        s = ca.if_else(ca.fabs(tau) < ca.inf, s, np.nan)
        return ca.if_else(unmoved, state, moved), s

    def step(self, state, s: float) -> tuple[np.ndarray, float]:
        """Exact step to virtual deformation ``s``; returns ``(state, τ)``.

        Parameters
        ----------
        state : ndarray or CasADi expression
            State before the step.
        s : float or CasADi expression
            New virtual deformation.

        Returns
        -------
        state : ndarray or CasADi expression
            State after the step (an expression when ``state`` or ``s`` is one).
        tau : float or CasADi expression
            Torque after the step.
        """
        if symbolic(state) or symbolic(s):
            return self._step_expr(state, s)
        s_last, up, s01, s02, tau_r, tau_last = (float(v) for v in state)
        if s > s_last and up < 0.5:  # s_last was a minimum: eq. (13), then eq. (10)
            s02, s01, tau_r, up = s_last, s_last + self.delta_s2(s_last), tau_last, 1.0
        elif s < s_last and up >= 0.5:  # s_last was a maximum: eq. (12), then eq. (10)
            s01, s02, tau_r, up = s_last, s_last - self.delta_s1(s_last), tau_last, 0.0
        if s == s_last:
            tau = tau_last
        elif up >= 0.5:
            tau = self._up_branch(s, s01, s02, tau_r)
        else:
            tau = self._down_branch(s, s01, s02, tau_r)
        return np.array([s, up, s01, s02, tau_r, tau]), tau

    def inverse_step(self, state, tau: float) -> tuple[np.ndarray, float]:
        """The s that brings the torque to ``tau`` from ``state`` (eqs. (20)–(31)), and the new state.

        Every branch increases with s, so the direction of s is that of τ. The transition
        is inverted in closed form (eq. (28): exponent 1/b), the polylines by their swapped
        points (eqs. (25)–(26)). The inverse turning points are the forward ones mapped
        through the polylines (τ01 = τ_al(s01), τ02 = τ_dl(s02)) instead of eq. (22)'s
        separately fitted l-parameters, which the paper does not list; this makes
        ``step(state, inverse_step(state, τ)[1])`` return τ to rounding.

        Parameters
        ----------
        state : ndarray or CasADi expression
            State to move from.
        tau : float or CasADi expression
            Torque to reach (finite; a non-finite CasADi one gives NaN).

        Returns
        -------
        state : ndarray or CasADi expression
            State after the move (expressions for CasADi arguments).
        s : float or CasADi expression
            The virtual deformation.
        """
        if symbolic(state) or symbolic(tau):
            return self._inverse_step_expr(state, tau)
        if not np.isfinite(tau):
            raise ValueError(f"tau must be finite, got {tau}")
        s_last, up, s01, s02, tau_r, tau_last = (float(v) for v in state)
        if tau == tau_last:
            return np.asarray(state, float).copy(), s_last
        if tau > tau_last:
            if up < 0.5:
                s02, s01, tau_r = s_last, s_last + self.delta_s2(s_last), tau_last
            tau_01 = float(self.tau_ascending(s01))
            if tau >= tau_01 or tau_01 <= tau_r:
                s = float(self.s_ascending(tau))
            else:
                ratio = min(max((tau - tau_r) / (tau_01 - tau_r), 0.0), 1.0)  # [0, 1] on a consistent state
                x = ratio ** (1.0 / self.exponent(s02))
                s = s02 + x * (s01 - s02)
        else:
            if up >= 0.5:
                s01, s02, tau_r = s_last, s_last - self.delta_s1(s_last), tau_last
            tau_02 = float(self.tau_descending(s02))
            if tau <= tau_02 or tau_02 >= tau_r:
                s = float(self.s_descending(tau))
            else:
                ratio = min(max((tau_r - tau) / (tau_r - tau_02), 0.0), 1.0)
                y = ratio ** (1.0 / self.exponent(s01))
                s = s01 - y * (s01 - s02)
        return self.step(state, s)[0], s

    def smooth_step(self, eps: float, direction_eps: float | None = None) -> ca.Function:
        """Smooth step ``(state, u) -> (state_next, y)`` (u: s, y: τ) with switching width ``eps`` (in s).

        ``direction_eps`` (default ``eps``) is the width of the direction detection on the
        per-step change Δs. It must be well below the typical |Δs| per step, or steady
        motion counts as a partial reversal every step and the turning points creep; the
        polyline kinks and clips can be much wider (``eps``), which is what keeps an NLP
        through this model well conditioned.

        Direction: ``t = tanh(Δs/direction_eps)``; the up-flag moves towards ``(1+t)/2`` by ``t²``,
        so a standing input keeps it. A reversal's weight is ``t²·(1+t)/2·(1−up)`` (and its
        mirror); turning points and τ_r blend towards their updated values by it. Polyline
        kinks use ``smooth_max``; the transition's progress is clipped smoothly into
        ``(s02, s01)``; the Table VII set is blended by ``tanh(s0/eps)``.

        Parameters
        ----------
        eps : float
            Switching width (in s), > 0.
        direction_eps : float, optional
            Width of the direction detection on Δs (default: ``eps``).

        Returns
        -------
        casadi.Function
            ``(state, u) -> (state_next, y)``.
        """
        check_smoothing(eps, direction_eps)
        return smooth_function("power_function_smooth", 6,
                               lambda state, s: self.smooth_expressions(state, s, eps, direction_eps))

    def smooth_expressions(self, state, s, eps: float, direction_eps: float | None = None):
        """CasADi expressions of :meth:`smooth_step` (for embedding in larger models).

        Parameters
        ----------
        state : CasADi expression
            State before the step.
        s : CasADi expression
            New virtual deformation.
        eps : float
            Switching width (in s).
        direction_eps : float, optional
            Width of the direction detection (default: ``eps``).

        Returns
        -------
        state_next : CasADi expression
            State after the step.
        tau : CasADi expression
            Torque after the step.
        """
        s_last, up, s01, s02, tau_r, tau_last = (state[i] for i in range(6))

        def relu(x):
            return smooth_max(x, 0.0, eps)

        t = ca.tanh((s - s_last) / (eps if direction_eps is None else direction_eps))
        moved = t * t
        target = 0.5 * (1 + t)
        up_new = up + moved * (target - up)
        r_up = moved * target * (1 - up)  # s_last was a minimum
        r_dn = moved * (1 - target) * up  # s_last was a maximum
        s02_new = s02 + r_up * (s_last - s02) + r_dn * (s_last - self.delta_s1(s_last) - s02)
        s01_new = s01 + r_up * (s_last + self.delta_s2(s_last) - s01) + r_dn * (s_last - s01)
        tau_r_new = tau_r + (r_up + r_dn) * (tau_last - tau_r)
        # Total on any argument (the NLP's iterates can put s02 above s01): the span is
        # floored smoothly and both progresses stay strictly positive, so powers stay real.
        span = smooth_max(s01_new - s02_new, 1e-5, eps)
        s_in = smooth_max(smooth_min(s, s01_new, eps), s02_new, eps)
        tau_al01 = self.tau_ascending(s01_new, relu)
        tau_dl02 = self.tau_descending(s02_new, relu)
        x = 1e-12 + smooth_max((s_in - s02_new) / span, 0.0, 1e-9)  # never exactly 0: log(x) in d(x^b)
        y = 1e-12 + smooth_max((s01_new - s_in) / span, 0.0, 1e-9)
        branch_up = (tau_r_new + (tau_al01 - tau_r_new) * x ** self.exponent(s02_new, eps)
                     + self.tau_ascending(smooth_max(s, s01_new, eps), relu) - tau_al01)
        branch_dn = (tau_r_new - (tau_r_new - tau_dl02) * y ** self.exponent(s01_new, eps)
                     + self.tau_descending(smooth_min(s, s02_new, eps), relu) - tau_dl02)
        tau = up_new * branch_up + (1 - up_new) * branch_dn
        return ca.vertcat(s, up_new, s01_new, s02_new, tau_r_new, tau), tau


@dataclass(frozen=True)
class VirtualDeformation:
    """Virtual deformation s(θ1), eq. (8), in Table V's units.

    Eq. (8) gives s in m² with τ = K·s (eq. (7)); Table V's s is that times ``scale``.
    Table I gives K and r but not the pretension P0. We choose ``scale = K / 45 N m`` (the
    slope of Table V's polylines, τ ≈ 45·s) and P0 = 23.2 N, so that θ1 = ±0.5 rad (Table I)
    maps to s = ±0.046, the ends of Table V.
    """

    stiffness: float = 15.49e3
    """K, N/m (Table I: 15.49 N/mm)."""
    pinion_radius: float = 0.021
    """r, m (Table I)."""
    pretension: float = 23.2
    """P0, N (our choice; see the class docstring)."""
    scale: float = 15.49e3 / 45.0
    """Table V units per m²."""

    def s(self, theta, xp=np):
        """s(θ1), eq. (8), scaled; works on NumPy and CasADi values.

        Parameters
        ----------
        theta : float, ndarray or CasADi expression
            θ1 (rad).
        xp : module, optional
            ``numpy`` or ``casadi``, whose ``sin`` and ``cos`` are used.

        Returns
        -------
        float, ndarray or CasADi expression
            s in Table V's units.
        """
        r, k = self.pinion_radius, self.stiffness
        return self.scale * (4 * r**2 * xp.sin(theta) * (1 - xp.cos(theta))
                             + 2 * self.pretension * r * xp.sin(theta) / k)

    def theta(self, s) -> np.ndarray:
        """Inverse of :meth:`s` on |θ1| < π/2 (s is odd and increasing there), by Newton steps.

        Parameters
        ----------
        s : float, array_like or CasADi expression
            Virtual deformation (Table V's units); a CasADi ``s`` takes the same steps as an
            expression, through :meth:`theta_function`.

        Returns
        -------
        ndarray or CasADi expression
            θ1 (rad), of the shape of ``s`` (a column for a CasADi ``s``).
        """
        if symbolic(s):
            theta = self.theta_function()  # one Function, called per element: small C
            return ca.vertcat(*[theta(s[i]) for i in range(s.numel())])
        s = np.asarray(s, float)
        theta = s / (self.scale * 2 * self.pretension * self.pinion_radius / self.stiffness)
        theta = np.clip(theta, -1.2, 1.2)
        for _ in range(50):
            r, k = self.pinion_radius, self.stiffness
            ds = self.scale * (4 * r**2 * (np.cos(theta) - np.cos(2 * theta))
                               + 2 * self.pretension * r * np.cos(theta) / k)
            step = (self.s(theta) - s) / ds
            theta = np.clip(theta - step, -1.5, 1.5)
            if np.max(np.abs(step)) < 1e-15:
                break
        return theta

    def theta_function(self) -> ca.Function:
        """``theta(s)`` for a scalar as a CasADi Function.

        The 50 Newton steps of :meth:`theta` unrolled, each applied only until one is below 1e-15
        (as the loop's ``break``).

        Returns
        -------
        casadi.Function
            ``s -> θ1`` on a scalar.
        """
        s = ca.SX.sym("s")
        r, k = self.pinion_radius, self.stiffness
        theta = clip(s / (self.scale * 2 * self.pretension * r / k), -1.2, 1.2)
        done = ca.SX(0)
        for _ in range(50):
            ds = self.scale * (4 * r**2 * (ca.cos(theta) - ca.cos(2 * theta))
                               + 2 * self.pretension * r * ca.cos(theta) / k)
            step = (self.s(theta, ca) - s) / ds
            theta = ca.if_else(done, theta, clip(theta - step, -1.5, 1.5))
            done = ca.logic_or(done, ca.fabs(step) < 1e-15)
        return ca.Function("virtual_deformation_theta", [s], [theta])
