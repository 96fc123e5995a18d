"""Parametric hysteresis operator and its closed-form inverse (katalenic2013, Defs. 3.1–3.4).

Memory: the input and output at the last input extremum, (u0, v0), and the direction s
of the input since then (Definitions 3.1–3.2; sgn+ is right-continuous, so a standing
input keeps its direction). With m as below,

* direct (eq. (3)):  v = u − u0 + v0 + s·( W(p2·m·e^{p2 (m − |u − u0|)}) / p2 − m ),
                     m = p1 + s (v0 − u0);
* inverse (eq. (5)): v = u − u0 + v0 + s·m·(1 − e^{−p2 |u − u0|}),
                     m = p1 + s (u0 − v0).

Both stay between the asymptotes v = u ± p1, and H[IH[u]] = u when their memories
correspond. State: ``[u_last, s, u0, v0, v_last]``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from hystmpc.models.base import SteppedModel, check_smoothing, smooth_function, symbolic
from hystmpc.models.lambertw import lambertw, lambertw_expr
from hystmpc.models.smooth import smooth_max, smooth_min


@dataclass(frozen=True)
class ParametricHysteresis(SteppedModel):
    """Direct operator H (eq. (3)); :meth:`inverse_step` is IH (eq. (5))."""

    p1: float
    """Largest half-width of the loop (input units; A for the reluctance actuator)."""
    p2: float
    """Rate of approach to the asymptotes (1 / input units)."""

    def __post_init__(self):
        for name in ("p1", "p2"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be finite and > 0, got {value}")

    state_names = ("u_last", "direction", "u_extremum", "v_extremum", "v_last")
    """Last input, direction since the last extremum (±1), input and output at that extremum,
    last output."""

    def initial_state(self, u0: float = 0.0, v0: float | None = None, direction: float = 1.0) -> np.ndarray:
        """Memory at an extremum (u0, v0) (default v0 = u0: demagnetised) moving in ``direction``.

        Parameters
        ----------
        u0 : float, optional
            Input at the extremum.
        v0 : float, optional
            Output at the extremum, within ``p1`` of ``u0`` (else ``ValueError``); None: ``u0``.
        direction : float, optional
            Direction since the extremum: +1 for ``direction >= 0``, else -1.

        Returns
        -------
        ndarray
            ``[u0, ±1, u0, v0, v0]``.
        """
        v0 = u0 if v0 is None else v0
        if abs(v0 - u0) > self.p1:
            raise ValueError(f"|v0 - u0| = {abs(v0 - u0)} exceeds p1 = {self.p1}: outside the asymptotes")
        return np.array([u0, 1.0 if direction >= 0 else -1.0, u0, v0, v0])

    def output(self, state):
        """Output of a state (NumPy or CasADi).

        Parameters
        ----------
        state : ndarray or CasADi expression
            A state.

        Returns
        -------
        float or CasADi expression
            Its last output ``v_last``.
        """
        return state[4] if symbolic(state) else float(state[4])

    @staticmethod
    def _update_memory(state, u):
        """``(s, u0, v0)`` after input ``u``; CasADi expressions (the same tests as if_else)."""
        u_last, s, u0, v0, v_last = (state[i] for i in range(5))
        direction = ca.if_else(u > u_last, 1.0, -1.0)
        turned = ca.logic_and(u != u_last, direction != s)  # u_last was an extremum (Definition 3.1)
        return ca.if_else(turned, direction, s), ca.if_else(turned, u_last, u0), ca.if_else(turned, v_last, v0)

    @staticmethod
    def _memory_after(state: list[float], u: float) -> tuple[float, float, float]:
        """``(s, u0, v0)`` after input ``u`` from a state of floats (see :func:`_floats`)."""
        u_last, s, u0, v0, v_last = state
        if u != u_last:
            direction = 1.0 if u > u_last else -1.0
            if direction != s:  # u_last was an extremum (Definition 3.1)
                u0, v0, s = u_last, v_last, direction
        return s, u0, v0

    def direct(self, u, s, u0, v0):
        """Eq. (3) for given memory; NumPy or CasADi arguments.

        Parameters
        ----------
        u : float, ndarray or CasADi expression
            Input; a CasADi ``u`` makes the result an expression.
        s : float or CasADi expression
            Direction since the last extremum (±1).
        u0, v0 : float or CasADi expression
            Input and output at the last extremum.

        Returns
        -------
        float, ndarray or CasADi expression
            H's output.
        """
        if type(u) is float and type(s) is float and type(u0) is float and type(v0) is float:
            m = self.p1 + s * (v0 - u0)  # one sample of a simulation: math, not 0-d arrays
            try:
                exponential = math.exp(self.p2 * (m - abs(u - u0)))
            except OverflowError:  # NumPy's inf, below
                pass
            else:
                return u - u0 + v0 + s * (lambertw(self.p2 * m * exponential) / self.p2 - m)
        lib = ca if isinstance(u, (ca.SX, ca.MX)) else np
        w = lambertw_expr if lib is ca else lambertw
        m = self.p1 + s * (v0 - u0)
        du = lib.fabs(u - u0) if lib is ca else abs(u - u0)
        return u - u0 + v0 + s * (w(self.p2 * m * lib.exp(self.p2 * (m - du))) / self.p2 - m)

    def inverse(self, u, s, u0, v0):
        """Eq. (5) for given memory (the memory of IH's own input and output).

        Parameters
        ----------
        u : float, ndarray or CasADi expression
            IH's input (H's output); a CasADi ``u`` makes the result an expression.
        s : float or CasADi expression
            Direction of IH's input since its last extremum (±1).
        u0, v0 : float or CasADi expression
            IH's input and output at that extremum.

        Returns
        -------
        float, ndarray or CasADi expression
            IH's output (H's input).
        """
        if type(u) is float and type(s) is float and type(u0) is float and type(v0) is float:
            m = self.p1 + s * (u0 - v0)  # math.exp cannot overflow here: its argument is <= 0
            return u - u0 + v0 + s * m * (1 - math.exp(-self.p2 * abs(u - u0)))
        lib = ca if isinstance(u, (ca.SX, ca.MX)) else np
        m = self.p1 + s * (u0 - v0)
        du = lib.fabs(u - u0) if lib is ca else abs(u - u0)
        return u - u0 + v0 + s * m * (1 - lib.exp(-self.p2 * du))

    def step(self, state, u: float) -> tuple[np.ndarray, float]:
        """Exact step of H to input ``u``; returns ``(state, v)``.

        Both are CasADi expressions when ``state`` or ``u`` is one.

        Parameters
        ----------
        state : ndarray or CasADi expression
            ``[u_last, s, u0, v0, v_last]``.
        u : float or CasADi expression
            New input.

        Returns
        -------
        state : ndarray or CasADi expression
            State after the step.
        v : float or CasADi expression
            Output after the step.
        """
        if not (symbolic(state) or symbolic(u)):  # a simulation's sample
            u = float(u)
            s, u0, v0 = self._memory_after(_floats(state), u)
            v = float(self.direct(u, s, u0, v0))
            return np.array([u, s, u0, v0, v]), v
        s, u0, v0 = self._update_memory(state, u)
        v = self.direct(u if symbolic(u) else type(s)(u), s, u0, v0)
        return ca.vertcat(u, s, u0, v0, v), v

    def inverse_step(self, state, v_target: float) -> tuple[np.ndarray, float]:
        """IH: the input that makes H's output ``v_target`` from ``state``; returns ``(state, u)``.

        ``state`` is H's state; IH runs on swapped memory (its input is H's output), which
        is what makes the pair exact inverses.

        Parameters
        ----------
        state : ndarray or CasADi expression
            H's state.
        v_target : float or CasADi expression
            H's output to reach; must be finite (NumPy: ``ValueError``; CasADi: the input is NaN).

        Returns
        -------
        state : ndarray or CasADi expression
            H's state after the input.
        u : float or CasADi expression
            The input.
        """
        if symbolic(state) or symbolic(v_target):  # a non-finite target gives u = NaN
            u_last, s, u0, v0, v_last = (state[i] for i in range(5))
            s_i, v0_i, u0_i = self._update_memory(ca.vertcat(v_last, s, v0, u0, u_last), v_target)
            u = self.inverse(v_target if symbolic(v_target) else type(s_i)(v_target), s_i, v0_i, u0_i)
            u = ca.if_else(ca.fabs(v_target) < ca.inf, u, np.nan)
            return self.step(state, u)[0], u
        if not np.isfinite(v_target):
            raise ValueError(f"v_target must be finite, got {v_target}")
        v_target = float(v_target)
        u_last, s, u0, v0, v_last = _floats(state)
        s_i, v0_i, u0_i = self._memory_after([v_last, s, v0, u0, u_last], v_target)  # IH's view: input v, output u
        u = float(self.inverse(v_target, s_i, v0_i, u0_i))
        return self.step(state, u)[0], u

    def hysteretic_part(self, u_seq, v0_star: float = 0.0) -> np.ndarray:
        """M[u] of eq. (7) (IH = u + M[u], eq. (6)) from memory ``v0*`` at ``u_seq[0]``.

        Parameters
        ----------
        u_seq : array_like
            Input sequence.
        v0_star : float, optional
            M's output at the starting extremum ``u_seq[0]`` (direction +1).

        Returns
        -------
        ndarray
            M's output at each sample.
        """
        u_seq = np.asarray(u_seq, float)
        out = np.empty(len(u_seq))
        u0, v0, s, u_last, v_last = u_seq[0], v0_star, 1.0, u_seq[0], v0_star
        for k, u in enumerate(u_seq):
            if u != u_last:
                direction = 1.0 if u > u_last else -1.0
                if direction != s:
                    u0, v0, s = u_last, v_last, direction
            m = self.p1 - s * v0
            v_last = v0 + s * m * (1 - np.exp(-self.p2 * abs(u - u0)))
            u_last = u
            out[k] = v_last
        return out

    def smooth_step(self, eps: float, direction_eps: float | None = None) -> ca.Function:
        """Smooth H step ``(state, u) -> (state_next, y)``: direction and extremum blended.

        ``t = tanh(Δu/direction_eps)`` (default width ``eps``); the direction moves to
        ``sign`` by ``t²`` (a standing input keeps it) and the memory (u0, v0) blends to
        (u_last, v_last) by the reversal weight ``t²·|target − s|/2``; ``|u − u0|`` is
        ``sqrt((u − u0)² + eps²)``. The error against :meth:`step` is O(eps) once the
        widths are below the input change per step.

        Parameters
        ----------
        eps : float
            Width of the smoothed ``|u − u0|`` (input units), > 0.
        direction_eps : float, optional
            Width of the direction detection (input units); None: ``eps``.

        Returns
        -------
        casadi.Function
            ``(state, u) -> (state_next, y)``.
        """
        check_smoothing(eps, direction_eps)
        width = eps if direction_eps is None else direction_eps

        def expressions(x, u):
            u_last, s, u0, v0, v_last = (x[i] for i in range(5))
            t = ca.tanh((u - u_last) / width)
            moved = t * t
            s_new = s + moved * (t - s)
            reversal = moved * (1 - t * s) / 2  # 1 when the move reverses the direction
            u0_new = u0 + reversal * (u_last - u0)
            v0_new = v0 + reversal * (v_last - v0)
            # m lies in [0, 2 p1] for any state inside the asymptotes; clamping it (smoothly)
            # keeps the Lambert W argument positive on every NLP iterate, so no NaN.
            m = self.p1 + s_new * (v0_new - u0_new)
            m = smooth_min(smooth_max(m, 1e-3 * self.p1, 1e-3 * self.p1), 2 * self.p1, 1e-3 * self.p1)
            du = ca.sqrt((u - u0_new) ** 2 + eps**2)
            v = u - u0_new + v0_new + s_new * (lambertw_expr(self.p2 * m * ca.exp(self.p2 * (m - du))) / self.p2 - m)
            return ca.vertcat(u, s_new, u0_new, v0_new, v), v
        return smooth_function("parametric_smooth", 5, expressions)


def _floats(state) -> list[float]:
    """A NumPy state as Python floats: the exact step's arithmetic then runs on ``math``."""
    return state.tolist() if isinstance(state, np.ndarray) else [float(x) for x in state]


def major_loop(op: ParametricHysteresis, current) -> np.ndarray:
    """H's response to a major loop 0 -> max -> 0 from the demagnetised state, vectorised.

    Within each monotone half the memory is constant, so eq. (3) applies in closed form:
    (u0, v0) = (0, 0), s = +1 on the way up, and (i_max, X(i_max)), s = −1 on the way down.

    Parameters
    ----------
    op : ParametricHysteresis
        The operator H.
    current : array_like
        Input rising to its maximum and falling back (A); H starts demagnetised at ``current[0]``.

    Returns
    -------
    ndarray
        H's output X at each sample.
    """
    current = np.asarray(current, float)
    top = int(np.argmax(current))
    x = np.empty_like(current)
    x[: top + 1] = op.direct(current[: top + 1], 1.0, current[0], current[0])
    x[top + 1:] = op.direct(current[top + 1:], -1.0, current[top], x[top])
    return x


def _lut_points(force_up, x_up, window: int):
    """Ascending (F, X) pairs, averaged over ``window`` samples to tame measurement noise."""
    n = len(force_up) // window * window
    if window > 1 and n >= 2 * window:
        force_up = force_up[:n].reshape(-1, window).mean(axis=1)
        x_up = x_up[:n].reshape(-1, window).mean(axis=1)
    order = np.argsort(force_up)
    return force_up[order], x_up[order]


P1_RANGE = (1e-5, 0.1)
"""Search range of p1 (A) in identification."""
P2_RANGE = (1e-6, 0.1)
"""Search range of p2 (1/(A m)) in identification; p2(g) = p2/g."""


LOW_FORCE_FRACTION = 0.02
"""Descending samples below this fraction of the peak force are left out of the cost: with
F ∝ X², dX/dF is unbounded near F = 0, so force noise there would dominate eq. (13)."""


def major_loop_cost(p1: float, p2: float, loops: dict[float, tuple[np.ndarray, np.ndarray]],
                    window: int = 1) -> float:
    """J_F(p1, p2), eqs. (13)–(16): the descending branch against the ascending look-up table.

    Parameters
    ----------
    p1, p2 : float
        Operator parameters; the air-gap law p2(g) = p2/g (g in m) applies.
    loops : dict
        Per air gap g (m): the current 0 -> max -> 0 (Fig. 9) and the measured force.
    window : int, optional
        Samples averaged per look-up-table point (1: the paper's plain table).

    Returns
    -------
    float
        Sum over the gaps of the squared differences in X; inf when not finite.
    """
    total = 0.0
    for gap, (current, force) in loops.items():
        current = np.asarray(current, float)
        force = np.asarray(force, float)
        top = int(np.argmax(current))
        x = major_loop(ParametricHysteresis(p1, p2 / gap), current)
        f_a, x_a = _lut_points(force[: top + 1], x[: top + 1], window)
        f_d = force[top:]
        lut = np.interp(f_d, f_a, x_a)  # eq. (15), linear interpolation
        keep = f_d >= LOW_FORCE_FRACTION * np.max(force)
        total += float(np.sum((x[top:][keep] - lut[keep]) ** 2))
    return total if np.isfinite(total) else np.inf


def identify_major_loop(loops: dict[float, tuple[np.ndarray, np.ndarray]], p_start=(0.005, 0.002),
                        window: int = 1):
    """Identify p1, p2 from major loops at several air gaps (Section 3.5, eq. (17)).

    Nelder–Mead (as the paper) on log p1, log p2 inside :data:`P1_RANGE` and
    :data:`P2_RANGE`.

    Parameters
    ----------
    loops : dict
        ``loops[g] = (current, force)`` per air gap g (m): the current 0 -> max -> 0 and the
        measured force; one gap at least (else ``ValueError``).
    p_start : tuple of float, optional
        Starting ``(p1, p2)``.
    window : int, optional
        Samples averaged per look-up-table point (1: the paper's plain table).

    Returns
    -------
    p1, p2 : float
        Operator parameters; p2(g) = p2/g.
    luts : dict
        ``luts[g] = (F, X)``, the ascending table of eq. (15) for gap g:
        X = Lut(F, g) and F = Lut⁻¹(X, g).
    """
    from scipy.optimize import minimize

    if len(loops) == 0:
        raise ValueError("need the major loop at one air gap at least")
    bounds = np.log([P1_RANGE, P2_RANGE])

    def cost(z):
        if np.any(z < bounds[:, 0]) or np.any(z > bounds[:, 1]):
            return np.inf
        return major_loop_cost(float(np.exp(z[0])), float(np.exp(z[1])), loops, window)

    # fatol 1e-30 never held (the table makes the cost flat in steps): every fit ran into
    # maxfev, 8000 evaluations; 1e-14 stops after about 130 at the same p1, p2
    result = minimize(cost, np.log(np.asarray(p_start, float)), method="Nelder-Mead",
                      options={"xatol": 1e-8, "fatol": 1e-14, "maxiter": 4000, "maxfev": 8000})
    p1, p2 = (float(v) for v in np.exp(result.x))
    luts = {}
    for gap, (current, force) in loops.items():
        current = np.asarray(current, float)
        top = int(np.argmax(current))
        x = major_loop(ParametricHysteresis(p1, p2 / gap), current)
        luts[gap] = _lut_points(np.asarray(force, float)[: top + 1], x[: top + 1], window)
    return p1, p2, luts
