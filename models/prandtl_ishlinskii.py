"""Prandtl–Ishlinskii hysteresis: a linear term plus weighted play operators.

The form piezo users fit and invert::

    y = p0·u + Σ_i p_i · Play_{r_i}[u],        Play_r: z <- clip(z, u − r, u + r)

with thresholds ``r_i > 0`` (input units) and weights ``p_i > 0`` (output per input unit).
A play operator of threshold ``r`` and weight ``p`` is a Maxwell-slip element of stiffness
``p`` and break-away level ``p·r`` seen from the other side: ``p·Play_r[u] = p·u − F``.
So ``y = (p0 + Σp)·u − MS[u]`` and the model is built on :class:`MaxwellSlip`; its state is
the Maxwell-slip state ``[u_last, F_1..F_n]`` (``F_i = p_i·(u_last − z_i)``, ``z_i`` the
play outputs). Unlike Maxwell-slip, the output is unbounded: once a move exceeds twice the
largest threshold every play follows the input, so every target is reachable.

A relaxed state (every ``F_i = 0``) is the virgin state: all plays centred on the input.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from hystmpc.models.base import SteppedModel, check_smoothing, clip, smooth_function, symbolic
from hystmpc.models.maxwell_slip import MaxwellSlip


@dataclass(frozen=True)
class PrandtlIshlinskii(SteppedModel):
    """Prandtl–Ishlinskii model ``y = p0·u + Σ p_i Play_{r_i}[u]``."""

    linear_gain: float
    """p0 >= 0: weight of the threshold-zero play (the linear term)."""
    thresholds: tuple[float, ...]
    """r_i > 0, input units."""
    weights: tuple[float, ...]
    """p_i > 0, output per input unit."""
    elements: MaxwellSlip | None = field(init=False, repr=False, compare=False, default=None)
    """The equivalent Maxwell-slip elements (k_i = p_i, w_i = p_i r_i); None without plays."""

    def __post_init__(self):
        object.__setattr__(self, "thresholds", tuple(float(r) for r in self.thresholds))
        object.__setattr__(self, "weights", tuple(float(p) for p in self.weights))
        if not (np.isfinite(self.linear_gain) and self.linear_gain >= 0):
            raise ValueError(f"linear_gain must be finite and >= 0, got {self.linear_gain}")
        if len(self.thresholds) != len(self.weights):
            raise ValueError(f"thresholds and weights differ in length: "
                             f"{len(self.thresholds)} != {len(self.weights)}")
        for name, values in (("thresholds", self.thresholds), ("weights", self.weights)):
            if not all(np.isfinite(v) and v > 0 for v in values):
                raise ValueError(f"{name} must be finite and > 0, got {values}")
        if self.linear_gain == 0 and not self.weights:
            raise ValueError("a Prandtl–Ishlinskii model needs linear_gain > 0 or at least one play")
        if self.weights:
            elements = MaxwellSlip(k=self.weights, w=tuple(p * r for p, r in zip(self.weights, self.thresholds,
                                                                                  strict=True)))
            object.__setattr__(self, "elements", elements)

    @property
    def gain(self) -> float:
        """Slope once every play moves with the input: ``p0 + Σ p_i``."""
        return self.linear_gain + float(sum(self.weights))

    @property
    def state_names(self) -> tuple[str, ...]:
        """``u_last`` and the Maxwell-slip forces ``F_i = p_i (u_last − z_i)``."""
        return ("u_last", *(f"force_{i + 1}" for i in range(len(self.weights))))

    def initial_state(self, u0: float = 0.0) -> np.ndarray:
        """Virgin state at ``u0``: every play centred on the input.

        Parameters
        ----------
        u0 : float, optional
            Input.

        Returns
        -------
        ndarray
            ``[u0, 0, …, 0]``: no force in any element.
        """
        return np.concatenate(([float(u0)], np.zeros(len(self.weights))))

    def output(self, state):
        """Output of a state (NumPy or CasADi).

        Parameters
        ----------
        state : ndarray or CasADi expression
            ``[u_last, F_1, …, F_n]``.

        Returns
        -------
        float or CasADi expression
            ``gain·u_last − Σ F_i``.
        """
        if symbolic(state):
            return self.gain * state[0] - ca.sum1(state[1:])
        state = np.asarray(state, float)
        return float(self.gain * state[0] - np.sum(state[1:]))

    def step(self, state, u: float) -> tuple[np.ndarray, float]:
        """Exact step to input ``u``; returns ``(state, y)`` (CasADi expressions when ``state`` or ``u`` is one).

        Parameters
        ----------
        state : ndarray or CasADi expression
            State before the step.
        u : float or CasADi expression
            New input.

        Returns
        -------
        state : ndarray or CasADi expression
            State after the step.
        y : float or CasADi expression
            Output after the step.
        """
        if symbolic(state) or symbolic(u):
            if not self.weights:
                return ca.vertcat(u), self.linear_gain * u
            nxt, forces = self.elements.step(state, u)
            return nxt, self.gain * u - forces
        if not self.weights:
            return np.array([float(u)]), float(self.linear_gain * u)
        nxt, forces = self.elements.step(state, u)
        return nxt, float(self.gain * u - forces)

    def smooth_step(self, eps: float, direction_eps: float | None = None) -> ca.Function:
        """Smooth step ``(state, u) -> (state_next, y)``: each play's clip smoothed over ``eps``.

        As for Maxwell-slip, the output error after ``n`` steps is at most ``n·M·eps/2`` for
        ``M`` plays (each smoothed clip errs by at most ``eps/2`` and is 1-Lipschitz).

        Parameters
        ----------
        eps : float
            Smoothing width of each clip, > 0; it acts on the element forces (output units).
        direction_eps : None
            Must stay unset: no direction detection (``ValueError`` otherwise).

        Returns
        -------
        casadi.Function
            ``(state, u) -> (state_next, y)``.
        """
        check_smoothing(eps, direction_eps, has_direction=False)
        n = len(self.weights)

        def expressions(state, u):
            forces = (self.elements.smooth_forces([state[1 + i] for i in range(n)], state[0], u, eps)
                      if n else [])
            return ca.vertcat(u, *forces), self.gain * u - sum(forces, ca.SX(0))
        return smooth_function("prandtl_ishlinskii_smooth", 1 + n, expressions)

    def inverse_step(self, state, y_target: float) -> tuple[np.ndarray, float]:
        """The input that brings the output to ``y_target`` from ``state``, and the new state.

        Exact: the output is piecewise linear and monotone along a monotone input path. On CasADi
        expressions (a generated controller) :meth:`symbolic_inverse_step`.

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
            return self.symbolic_inverse_step(state, y_target)
        if not np.isfinite(y_target):
            raise ValueError(f"y_target must be finite, got {y_target}")
        if not self.weights:
            u = float(y_target) / self.linear_gain
            return np.array([u]), u
        return self.elements.move_to(state, y_target, lambda u, forces: self.gain * u - float(forces.sum()),
                                     tail_slope=self.gain)

    def symbolic_inverse_step(self, state, y_target):
        """:meth:`inverse_step` on CasADi expressions, without branches or loops over the plays.

        Moving the input by ``δ >= 0`` towards the target, the output changes at the rate
        ``p0 + Σ p_i`` over the plays already dragged along, which only grows: the output is
        convex in ``δ`` and lies above each of its supporting lines, the one at ``δ = 0`` and
        the one at each play's break point ``b_i``. So the ``δ`` that reaches the target is the
        smallest of the lines' own crossings (a line with no slope never crosses). The same
        input as the NumPy steps to rounding; ``O(n²)`` operations for ``n`` plays.

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
        if not self.weights:
            u = y_target / self.linear_gain
            return ca.vertcat(u), u
        p = ca.DM(self.weights)
        w = ca.DM([pi * r for pi, r in zip(self.weights, self.thresholds, strict=True)])
        u0, forces = state[0], state[1:]
        y0 = self.gain * u0 - ca.sum1(forces)
        sign = ca.if_else(y_target >= y0, 1.0, -1.0)
        breaks = ca.fmax((w - sign * forces) / p, 0.0)  # input distance until each play is dragged

        def output_after(delta):
            return self.gain * (u0 + sign * delta) - ca.sum1(clip(forces + sign * p * delta, -w, w))

        def crossing(at, y_at, slope):
            return ca.if_else(slope > 0, at + sign * (y_target - y_at) / slope, ca.inf)
        delta = crossing(0.0, y0, self.linear_gain + ca.dot(p, breaks <= 0))
        for i in range(len(self.weights)):
            delta = ca.fmin(delta, crossing(breaks[i], output_after(breaks[i]),
                                            self.linear_gain + ca.dot(p, breaks <= breaks[i])))
        u = u0 + sign * ca.if_else(y_target == y0, 0.0, delta)
        return self.step(state, u)[0], u
