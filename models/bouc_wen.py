"""Bouc–Wen hysteresis (rate-independent, exponent n = 1), exact between samples.

The differential model piezo-stage and MR-damper users know, written with a unit internal
variable ``ζ`` (``z = A·ζ``)::

    y = k·u + A·ζ,      ζ' = u̇ − β·|u̇|·ζ − γ·u̇·|ζ|,

with ``β > |γ|`` (a bounded, dissipative loop: ``|ζ| <= 1/(β + γ)``). ``A > 0`` is the
textbook form; ``A < 0`` is the piezo form ``y = d·u − h`` (reversal curves that start flat
and steepen), allowed while the output stays monotone in the input:
``k >= −A · 2β/(β + γ)``, the largest ``dζ/du``. With the input's direction ``σ`` fixed over a
move, ``dζ/du = 1 − (βσ + γ sgn ζ)·ζ`` is linear on each side of ``ζ = 0``, so a move of any
size has a closed form (an exponential approach to ``±1/(β ± γ)``, with the crossing of
``ζ = 0`` found exactly). The exact step is that closed form; the loop does not depend on
how finely the input is sampled. Along a monotone move the output is monotone, so the
inverse is a bisection.

State: ``[u_last, ζ]``; relaxed at ``u0`` means ``ζ = 0``.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from hystmpc.models.base import SteppedModel, bisection_inverse, check_smoothing, smooth_function, symbolic


def _phi(x):
    """``(1 − e^{−x})/x`` on CasADi expressions (its series near 0)."""
    small = ca.fabs(x) < 1e-6
    safe = ca.if_else(small, 1.0, x)
    return ca.if_else(small, 1.0 - 0.5 * x + x * x / 6.0, -ca.expm1(-safe) / safe)


@dataclass(frozen=True)
class BoucWen(SteppedModel):
    """Bouc–Wen model ``y = k·u + A·ζ`` (see the module)."""

    linear_gain: float
    """k >= 0: the reversible slope (output per input unit)."""
    a: float
    """A != 0: the output's slope from ζ at ζ = 0 (output per input unit)."""
    beta: float
    """β > |γ| (1 / input unit)."""
    gamma: float
    """γ (1 / input unit): the loop's asymmetry between loading and unloading."""

    def __post_init__(self):
        for name in ("linear_gain", "a", "beta", "gamma"):
            if not np.isfinite(getattr(self, name)):
                raise ValueError(f"{name} must be finite, got {getattr(self, name)}")
        if not self.beta > abs(self.gamma):
            raise ValueError(f"beta must exceed |gamma| (a bounded loop), got beta={self.beta}, gamma={self.gamma}")
        steepest = 2.0 * self.beta / (self.beta + self.gamma)
        if self.a == 0 or self.linear_gain < -min(self.a, 0.0) * steepest * (1 - 1e-12):
            raise ValueError(f"need a != 0 and linear_gain >= -a·2β/(β+γ) = {-min(self.a, 0.0) * steepest:.6g} (an "
                             f"output monotone in the input), got a={self.a}, linear_gain={self.linear_gain}")

    @property
    def state_names(self) -> tuple[str, ...]:
        """``u_last`` and the unit internal variable ``ζ``."""
        return ("u_last", "zeta")

    def initial_state(self, u0: float = 0.0) -> np.ndarray:
        """Relaxed at ``u0``: ``ζ = 0``.

        Parameters
        ----------
        u0 : float, optional
            Input the state rests at.

        Returns
        -------
        ndarray
            ``[u0, 0]``.
        """
        return np.array([float(u0), 0.0])

    def output(self, state):
        """``k·u_last + A·ζ`` (NumPy or CasADi).

        Parameters
        ----------
        state : ndarray or CasADi expression
            A state.

        Returns
        -------
        float or CasADi expression
            The output at ``state``.
        """
        if symbolic(state):
            return self.linear_gain * state[0] + self.a * state[1]
        return float(self.linear_gain * state[0] + self.a * state[1])

    def _moves(self, z, du, direction, zsign):
        """What a move ``du`` does to ``ζ``, on CasADi expressions.

        For a move with the direction ``σ`` and the side of ``ζ = 0`` given (possibly smoothed):
        ``ζ`` after the move if it stays on its side, ``ζ`` after it if it crosses zero, and the
        input distance to zero.
        """
        a, beta, gamma = 1.0, self.beta, self.gamma
        k = beta * direction + gamma * zsign
        straight = z * ca.exp(-k * du) + a * du * _phi(k * du)
        nonzero = ca.fabs(k) > 1e-12
        x = ca.fmax(-k * z / a, -0.5)  # only used where the move heads for zero (then x > 0)
        reach = ca.if_else(nonzero, ca.log1p(x) / ca.if_else(nonzero, k, 1.0), -z / a)
        rest = du - reach
        crossed = a * rest * _phi((beta + gamma) * direction * rest)
        return straight, crossed, reach

    def step(self, state, u: float) -> tuple[np.ndarray, float]:
        """Exact step to input ``u``: ``(state, y)`` (CasADi expressions when ``state`` or ``u`` is one).

        Parameters
        ----------
        state : ndarray or CasADi expression
            State before the step.
        u : float or CasADi expression
            New input (finite).

        Returns
        -------
        state : ndarray or CasADi expression
            State after the step.
        y : float or CasADi expression
            Output after the step.
        """
        if symbolic(state) or symbolic(u):
            du, z = u - state[0], state[1]
            s = ca.if_else(du > 0, 1.0, -1.0)
            q = ca.if_else(ca.logic_or(z > 0, ca.logic_and(z == 0, du > 0)), 1.0, -1.0)
            straight, crossed, reach = self._moves(z, du, s, q)
            crosses = ca.logic_and(q == -s, ca.fabs(du) > ca.fabs(reach))
            nxt = ca.vertcat(u, ca.if_else(du == 0, z, ca.if_else(crosses, crossed, straight)))
            return nxt, self.output(nxt)
        if not np.isfinite(u):
            raise ValueError(f"u must be finite, got {u}")
        from hystmpc.models.compiled import bouc_wen_advance  # numba: imported when first needed
        state = np.asarray(state, float)
        z = bouc_wen_advance(float(state[1]), float(u) - float(state[0]), 1.0, self.beta, self.gamma)
        nxt = np.array([float(u), z])
        return nxt, self.output(nxt)

    def smooth_step(self, eps: float, direction_eps: float | None = None) -> ca.Function:
        """Smooth step ``(state, u) -> (state_next, y)``.

        Smoothed: the input's direction ``tanh(Δu / direction_eps)``, the side of ``ζ = 0``
        ``tanh(ζ / eps)`` (at ``ζ = 0`` the move's direction, as in the exact step) and the crossing
        of zero within the move blended over ``eps`` of input. The closed form is kept, so the
        error is O(eps) and does not grow with the move.

        Parameters
        ----------
        eps : float
            Width of the side of ``ζ = 0`` and of the zero crossing, > 0.
        direction_eps : float, optional
            Width of the direction detection (default: ``eps``).

        Returns
        -------
        casadi.Function
            ``(state, u) -> (state_next, y)``.
        """
        check_smoothing(eps, direction_eps)
        direction_eps = direction_eps or eps

        def expressions(state, u):
            du, z = u - state[0], state[1]
            s = ca.tanh(du / direction_eps)
            side = ca.tanh(z / eps)
            q = side + (1 - side * side) * s  # at z = 0 the move's direction, as in the exact step
            straight, crossed, reach = self._moves(z, du, s, q)
            towards = 0.5 * (1 - s * q)  # z on the side the move leaves
            beyond = 0.5 * (1 + ca.tanh((ca.fabs(du) - ca.fabs(reach)) / eps))
            z_next = straight + towards * beyond * (crossed - straight)
            return ca.vertcat(u, z_next), self.linear_gain * u + self.a * z_next
        return smooth_function("bouc_wen_smooth", 2, expressions)

    def linear_beyond(self) -> tuple[tuple[float, float], float]:
        """``(edges, reach)`` for the bisection.

        After a move of 40 loop widths ``ζ`` is within ``e^-40`` of its bound and the output moves
        with ``k`` alone.

        Returns
        -------
        edges : tuple of float
            ``(inf, -inf)``: no input edge, only the move counts.
        reach : float
            ``40 / (β − |γ|)`` (input units).
        """
        return (np.inf, -np.inf), 40.0 / (self.beta - abs(self.gamma))

    def inverse_step(self, state, y_target: float) -> tuple[np.ndarray, float]:
        """The input that brings the output to ``y_target`` from ``state``, and the state after it.

        A bisection over a monotone move (NumPy or CasADi). With ``k = 0`` a target beyond the
        loop's reach gives the input where ``ζ`` has all but reached its bound.

        Parameters
        ----------
        state : ndarray or CasADi expression
            State to move from.
        y_target : float or CasADi expression
            Output to reach (finite).

        Returns
        -------
        state : ndarray or CasADi expression
            State after the move.
        u : float or CasADi expression
            The input.
        """
        if symbolic(state) or symbolic(y_target):
            return bisection_inverse(self, state, y_target, *self.linear_beyond(),
                                     (self.linear_gain, self.linear_gain))
        if not np.isfinite(y_target):
            raise ValueError(f"y_target must be finite, got {y_target}")
        state = np.asarray(state, float)
        y0 = self.output(state)
        if y_target == y0:
            return state.copy(), float(state[0])
        d = 1.0 if y_target > y0 else -1.0
        _, reach = self.linear_beyond()
        near, far = float(state[0]), float(state[0]) + d * reach
        y_far = self.step(state, far)[1]
        if (y_far - y_target) * d < 0:
            u = far + (y_target - y_far) / self.linear_gain if self.linear_gain > 0 else far
            return self.step(state, u)[0], float(u)
        for _ in range(56):
            mid = 0.5 * (near + far)
            if (self.step(state, mid)[1] - y_target) * d >= 0:
                far = mid
            else:
                near = mid
        return self.step(state, far)[0], float(far)
