"""Maxwell-slip (elasto-slide) hysteresis, vo2012 Table 1.

``M`` elements in parallel; element ``i`` is a spring of stiffness ``k_i`` in series with a
slider that breaks away at force ``w_i``. Driven by input ``u`` (for the PAM joint: the joint
angle in degrees), the output is the sum of element forces (there: Δp_hys in bar, eq. (3)).

State: ``[u_last, F_1, ..., F_M]``, the last input and each element's force. The exact step is

    F_i <- clip(F_i + k_i (u - u_last), -w_i, w_i),    y = Σ F_i,

which equals ``Σ k_i (u - Play_{w_i/k_i}[u])`` (a sum of play operators) when started from a
relaxed state. Because the output saturates at ``±Σ w_i``, the model is a *compensator*
(vo2012 Fig. 1 adds ``y`` to the pressure command); its inverse exists for targets strictly
inside ``(-Σ w_i, Σ w_i)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from hystmpc.models.base import SteppedModel, check_smoothing, clip, smooth_function, symbolic
from hystmpc.models.smooth import smooth_clip


@dataclass(frozen=True)
class MaxwellSlip(SteppedModel):
    """Maxwell-slip hysteresis: parallel elasto-slide elements."""

    k: tuple[float, ...]
    """Element stiffnesses (output unit per input unit), all > 0."""
    w: tuple[float, ...]
    """Element break-away levels (output unit), all > 0."""

    def __post_init__(self):
        if len(self.k) != len(self.w):
            raise ValueError(f"k and w differ in length: {len(self.k)} != {len(self.w)}")
        if len(self.k) == 0:
            raise ValueError("a Maxwell-slip model needs at least one element")
        for name, values in (("k", self.k), ("w", self.w)):
            if not all(np.isfinite(v) and v > 0 for v in values):
                raise ValueError(f"{name} must be finite and > 0, got {values}")

    @property
    def n_elements(self) -> int:
        """Number of elasto-slide elements ``M``."""
        return len(self.k)

    @property
    def state_names(self) -> tuple[str, ...]:
        """``u_last`` and the element forces ``F_1..F_M``."""
        return ("u_last", *(f"force_{i + 1}" for i in range(self.n_elements)))

    @property
    def saturation(self) -> float:
        """Largest output magnitude ``Σ w_i``."""
        return float(sum(self.w))

    def initial_state(self, u0: float = 0.0, forces=None) -> np.ndarray:
        """State at input ``u0`` with the given element forces (default: relaxed, all zero).

        Parameters
        ----------
        u0 : float, optional
            Input.
        forces : array_like, optional
            The ``M`` element forces (another length: ``ValueError``); None: all zero.

        Returns
        -------
        ndarray
            ``[u0, F_1, ..., F_M]``.
        """
        f = np.zeros(self.n_elements) if forces is None else np.asarray(forces, float)
        if f.shape != (self.n_elements,):
            raise ValueError(f"forces must have {self.n_elements} entries, got {f.shape}")
        return np.concatenate(([float(u0)], f))

    def output(self, state):
        """Output ``Σ F_i`` of a state (NumPy or CasADi).

        Parameters
        ----------
        state : ndarray or CasADi expression
            ``[u_last, F_1, ..., F_M]``.

        Returns
        -------
        float or CasADi expression
            The output.
        """
        if symbolic(state):
            return ca.sum1(state[1:])
        return float(np.sum(np.asarray(state)[1:]))

    def step(self, state, u: float) -> tuple[np.ndarray, float]:
        """Exact step: move the input to ``u``; return the new state and the output.

        NumPy, or CasADi expressions when ``state`` or ``u`` is one.

        Parameters
        ----------
        state : array_like, shape (1 + M,)
            ``[u_last, F_1, ..., F_M]``.
        u : float
            New input.

        Returns
        -------
        state : ndarray or CasADi expression
            ``[u, F_1, ..., F_M]`` after the step.
        y : float or CasADi expression
            Output ``Σ F_i`` after the step.
        """
        k = np.asarray(self.k)
        w = np.asarray(self.w)
        if symbolic(state) or symbolic(u):  # the same clip, for a generated controller's inverse model
            forces = clip(state[1:] + ca.DM(k) * (u - state[0]), ca.DM(-w), ca.DM(w))
            return ca.vertcat(u, forces), ca.sum1(forces)
        state = np.asarray(state, float)
        forces = np.clip(state[1:] + k * (u - state[0]), -w, w)
        return np.concatenate(([u], forces)), float(forces.sum())

    def smooth_forces(self, forces, u_from, u_to, eps: float):
        """Element forces after moving the input ``u_from -> u_to``, with ``clip`` smoothed.

        Works on CasADi symbols and on NumPy values alike; each element's error against the
        exact step is at most ``eps / 2`` per call (see :func:`hystmpc.models.smooth.smooth_clip`).

        Parameters
        ----------
        forces : sequence
            The ``M`` element forces before the move.
        u_from, u_to : float or CasADi expression
            Input before and after the move.
        eps : float
            Smoothing width of each clip (output units: it acts on the forces).

        Returns
        -------
        list
            The ``M`` element forces after the move.
        """
        return [
            smooth_clip(forces[i] + self.k[i] * (u_to - u_from), self.w[i], eps)
            for i in range(self.n_elements)
        ]

    def smooth_step(self, eps: float, direction_eps: float | None = None) -> ca.Function:
        """Smooth step as a CasADi Function ``(state, u) -> (state_next, y)``.

        Over ``n`` steps the output error against :meth:`step` is at most ``n·M·eps/2``
        (each smoothed clip errs by at most ``eps/2`` and is 1-Lipschitz).

        Parameters
        ----------
        eps : float
            Smoothing width of each element's clip (output units), > 0.
        direction_eps : None
            Must stay unset: the model has no direction detection (``ValueError`` otherwise).

        Returns
        -------
        casadi.Function
            ``(state, u) -> (state_next, y)``.
        """
        check_smoothing(eps, direction_eps, has_direction=False)

        def expressions(state, u):
            forces = self.smooth_forces([state[1 + i] for i in range(self.n_elements)], state[0], u, eps)
            return ca.vertcat(u, *forces), ca.sum1(ca.vertcat(*forces))
        return smooth_function("maxwell_slip_smooth", self.n_state, expressions)

    def inverse_step(self, state, y_target: float) -> tuple[np.ndarray, float]:
        """Input that moves the output from ``state`` to ``y_target``, and the new state.

        The output is monotone and piecewise linear in ``u`` along a monotone input path, so
        the inverse is exact. Targets outside ``(-Σw, Σw)`` are unreachable: ``ValueError``
        (on CasADi expressions: :meth:`symbolic_inverse_step`, a NaN input).

        Parameters
        ----------
        state : ndarray or CasADi expression
            State to move from.
        y_target : float or CasADi expression
            Output to reach.

        Returns
        -------
        state : ndarray or CasADi expression
            State after the move.
        u : float or CasADi expression
            The input.
        """
        if symbolic(state) or symbolic(y_target):
            return self.symbolic_inverse_step(state, y_target)
        sat = self.saturation
        if not (np.isfinite(y_target) and -sat < y_target < sat):
            raise ValueError(f"y_target={y_target} is outside the reachable range (-{sat}, {sat})")
        return self.move_to(state, y_target, lambda u, forces: float(forces.sum()), tail_slope=0.0)

    def symbolic_inverse_step(self, state, y_target):
        """:meth:`inverse_step` on CasADi expressions, without branches or loops over the elements.

        Moving the input by ``δ >= 0`` towards the target, the output changes at the rate
        ``Σ k_i`` over the elements not yet at their break-away force, which only falls: the
        output is concave in ``δ`` and lies below each of its supporting lines, the one at
        ``δ = 0`` and the one at each element's break point. So the ``δ`` that reaches the
        target is the largest of the rising lines' crossings. A target outside ``(−Σw, Σw)``
        gives a NaN input (the NumPy steps raise ``ValueError``).

        Parameters
        ----------
        state : CasADi expression
            State to move from.
        y_target : float or CasADi expression
            Output to reach.

        Returns
        -------
        state : CasADi expression
            State after the move.
        u : CasADi expression
            The input.
        """
        k, w = ca.DM(self.k), ca.DM(self.w)
        u0, forces = state[0], state[1:]
        y0 = ca.sum1(forces)
        sign = ca.if_else(y_target >= y0, 1.0, -1.0)
        breaks = ca.fmax((w - sign * forces) / k, 0.0)  # input distance until each element slides

        def crossing(at, y_at, slope):
            return ca.if_else(slope > 0, at + sign * (y_target - y_at) / slope, -ca.inf)
        delta = crossing(0.0, y0, ca.dot(k, breaks > 0))
        for i in range(self.n_elements):
            y_i = ca.sum1(clip(forces + sign * k * breaks[i], -w, w))
            delta = ca.fmax(delta, crossing(breaks[i], y_i, ca.dot(k, breaks > breaks[i])))
        reachable = ca.logic_and(y_target > -self.saturation, y_target < self.saturation)
        u = ca.if_else(reachable, u0 + sign * ca.if_else(y_target == y0, 0.0, delta), np.nan)
        return self.step(state, u)[0], u

    def move_to(self, state, y_target: float, output_of, tail_slope: float) -> tuple[np.ndarray, float]:
        """The monotone input move from ``state`` after which ``output_of(u, forces)`` is ``y_target``.

        ``output_of`` must be continuous, monotone and piecewise linear in ``u`` with kinks
        only where an element saturates, and grow with ``tail_slope`` once all have
        (0: bounded, the target must be reached before).

        Parameters
        ----------
        state : array_like
            State to move from.
        y_target : float
            Output to reach.
        output_of : callable
            ``(u, forces) -> float``: the output at input ``u`` with element forces ``forces``.
        tail_slope : float
            Slope of ``output_of`` in ``u`` once every element saturates; 0: bounded (a target not
            bracketed before raises ``RuntimeError``).

        Returns
        -------
        state : ndarray
            State after the move.
        u : float
            The input.
        """
        state = np.asarray(state, float)
        u0, forces = float(state[0]), state[1:]
        y0 = output_of(u0, forces)
        if y_target == y0:
            return state.copy(), u0
        direction = 1.0 if y_target > y0 else -1.0
        k, w = np.asarray(self.k), np.asarray(self.w)
        room = (direction * w - forces) * direction  # input distance to saturate
        breaks = np.sort(np.unique(np.maximum(room / k, 0.0)))
        du_prev, y_prev = 0.0, y0
        for du in breaks:
            y_here = output_of(u0 + direction * du, np.clip(forces + direction * k * du, -w, w))
            if (y_here - y_target) * direction >= 0:
                slope = (y_here - y_prev) / (du - du_prev)
                du_hit = du_prev + (y_target - y_prev) / slope
                return self.step(state, u0 + direction * du_hit)[0], float(u0 + direction * du_hit)
            du_prev, y_prev = du, y_here
        if tail_slope > 0:
            du_hit = du_prev + (y_target - y_prev) * direction / tail_slope
            return self.step(state, u0 + direction * du_hit)[0], float(u0 + direction * du_hit)
        raise RuntimeError("unreachable: target inside the saturation band was not bracketed")


def play_operator(u_seq, r: float, z0: float = 0.0) -> np.ndarray:
    """Backlash (play) operator of half-width ``r``: ``z <- clip(z, u - r, u + r)``.

    Parameters
    ----------
    u_seq : array_like
        Input sequence.
    r : float
        Half-width (input units).
    z0 : float, optional
        Output before the first input.

    Returns
    -------
    ndarray
        Output ``z`` after each input.
    """
    out = np.empty(len(u_seq))
    z = z0
    for i, u in enumerate(u_seq):
        z = min(max(z, u - r), u + r)
        out[i] = z
    return out
