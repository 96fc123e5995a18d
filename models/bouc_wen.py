"""Bouc–Wen hysteresis (rate-independent, exponent n >= 1): exact between samples for n = 1.

The differential model piezo-stage and MR-damper users know, written with a unit internal
variable ``ζ`` (``z = A·ζ``)::

    y = k·u + A·ζ,      ζ' = u̇ − β·|u̇|·|ζ|^(n−1)·ζ − γ·u̇·|ζ|^n,

with ``β > |γ|`` (a bounded, dissipative loop: ``|ζ| <= (β + γ)^(−1/n)``). ``A > 0`` is the
textbook form; ``A < 0`` is the piezo form ``y = d·u − h`` (reversal curves that start flat
and steepen), allowed while the output stays monotone in the input:
``k >= −A · 2β/(β + γ)``, the largest ``dζ/du`` (whatever ``n``). For ``n = 1``, with the
input's direction ``σ`` fixed over a move, ``dζ/du = 1 − (βσ + γ sgn ζ)·ζ`` is linear on each
side of ``ζ = 0``, so a move of any size has a closed form (an exponential approach to
``±1/(β ± γ)``, with the crossing of ``ζ = 0`` found exactly). The step is that closed form;
the loop does not depend on how finely the input is sampled. Along a monotone move the
output is monotone and smooth, so the inverse is a few halvings and then a modified regula
falsi (the Illinois method).

For ``n != 1`` there is no closed form. A move is cut in :data:`SUBSTEPS` equal pieces
``h``, each an exponential Euler step ``ζ + h·φ1(h·f′)·f`` of ``dζ/du = f(ζ)``, ``φ1(x) =
(e^x − 1)/x``, clipped to ``ζ``'s bound: ``h·f′ <= 0`` on both sides of zero, and a long
move converges to the bound as Newton's method would. The step is the same arithmetic in
NumPy (:func:`~hystmpc.models.compiled.bouc_wen_advance_power`) and on CasADi expressions, so
a generated controller repeats it; it is a discretisation, not the equation's exact flow.
Measured on the loop alone (the error over the span of ``A·ζ``, against the equation
integrated finely, on slow moves, a sine and jumps of several loop widths a sample): 0.07–0.16 %
for ``γ/β = 1/3`` and ``n <= 2.5`` (0.45 % at ``n = 4``), but 0.3–3.5 % for ``γ/β = −0.5`` and
2.4–10 % for ``γ/β = −0.9``, where the slope ``f′`` jumps as ``ζ`` crosses zero inside a piece
(a piece is not split there; ``tests/test_hysteresis_contract.py``). The same path sampled ten
times finer gives the same figures: the error is the pieces', not the sampling's.

State: ``[u_last, ζ]``; relaxed at ``u0`` means ``ζ = 0``.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from hystmpc.models.base import SteppedModel, check_smoothing, smooth_function, symbolic
from hystmpc.models.inverse_search import illinois_inverse


def _exp_ratio(x):
    """``(e^x − 1)/x`` on CasADi expressions (its series near 0, as in the compiled step)."""
    small = ca.fabs(x) < 1e-6
    safe = ca.if_else(small, 1.0, x)
    return ca.if_else(small, 1.0 + 0.5 * x + x * x / 6.0, ca.expm1(safe) / safe)


def _phi(x):
    """``(1 − e^{−x})/x`` on CasADi expressions (its series near 0)."""
    small = ca.fabs(x) < 1e-6
    safe = ca.if_else(small, 1.0, x)
    return ca.if_else(small, 1.0 - 0.5 * x + x * x / 6.0, -ca.expm1(-safe) / safe)


SUBSTEPS = 8
"""Pieces of a move for ``n != 1``."""
MAX_EXPONENT = 4.0
"""The largest ``n`` (beyond it the pieces no longer hold the stated accuracy)."""


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
    exponent: float = 1.0
    """n >= 1: the sharpness of the loop's turn towards its bound (β and γ then in 1 / input unit^n)."""

    def __post_init__(self):
        if not 1.0 <= self.exponent <= MAX_EXPONENT:
            raise ValueError(f"exponent must lie in [1, {MAX_EXPONENT:g}], got {self.exponent}")
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
        """The step to input ``u``: ``(state, y)`` (CasADi expressions when ``state`` or ``u`` is one).

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
            if self.exponent == 1.0:
                moved = self._hard_move(z, du, s)
            else:
                moved = self._pieces(z, du, s, lambda x: (ca.sign(x), 0.0),
                                     lambda x: (ca.fabs(x), ca.sign(x), ca.fabs(x) ** (self.exponent - 1.0)))
            nxt = ca.vertcat(u, ca.if_else(du == 0, z, moved))
            return nxt, self.output(nxt)
        if not np.isfinite(u):
            raise ValueError(f"u must be finite, got {u}")
        from hystmpc.models import compiled  # numba: imported when first needed
        state = np.asarray(state, float)
        z, du = float(state[1]), float(u) - float(state[0])
        if self.exponent == 1.0:
            z = compiled.bouc_wen_advance(z, du, 1.0, self.beta, self.gamma)
        else:
            z = compiled.bouc_wen_advance_power(z, du, self.beta, self.gamma, self.exponent, SUBSTEPS)
        nxt = np.array([float(u), z])
        return nxt, self.output(nxt)

    def _hard_move(self, z, du, s):
        """``ζ`` after the move ``du`` in the direction ``s`` (CasADi, the closed form's switches)."""
        q = ca.if_else(ca.logic_or(z > 0, ca.logic_and(z == 0, s > 0)), 1.0, -1.0)
        straight, crossed, reach = self._moves(z, du, s, q)
        crosses = ca.logic_and(q == -s, ca.fabs(du) > ca.fabs(reach))
        return ca.if_else(crosses, crossed, straight)

    def _pieces(self, z, du, s, side, magnitude):
        """:data:`SUBSTEPS` exponential Euler pieces of a move (``n != 1``, CasADi).

        ``side(ζ)`` is ``(sgn ζ, its derivative)`` and ``magnitude(ζ)`` is ``(|ζ|, its
        derivative, |ζ|^(n−1))``, or smoothed ones.
        """
        n, h = self.exponent, du / SUBSTEPS
        bound = (self.beta + self.gamma) ** (-1.0 / n)
        for _ in range(SUBSTEPS):
            sign, dsign = side(z)
            m, dm, w = magnitude(z)
            c = self.beta * s * sign + self.gamma
            rate = 1.0 - c * w * m
            slope = -(self.beta * s * dsign * w * m + n * c * w * dm)
            z = ca.fmin(ca.fmax(z + h * _exp_ratio(h * slope) * rate, -bound), bound)
        return z

    def smooth_step(self, eps: float, direction_eps: float | None = None) -> ca.Function:
        """Smooth step ``(state, u) -> (state_next, y)``.

        Smoothed: the input's direction ``tanh(Δu / direction_eps)``, the side of ``ζ = 0``
        ``tanh(ζ / eps)`` (at ``ζ = 0`` the move's direction, as in the exact step) and the crossing
        of zero within the move blended over ``eps`` of input. The closed form is kept, so the
        error is O(eps) and does not grow with the move. For ``n != 1``, the pieces of the
        exact step with ``sgn ζ`` as ``tanh(ζ / eps)`` and ``|ζ|`` as ``sqrt(ζ² + eps²)``.

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

        def move(z, du, s):
            side = ca.tanh(z / eps)
            q = side + (1 - side * side) * s  # at z = 0 the move's direction, as in the exact step
            straight, crossed, reach = self._moves(z, du, s, q)
            towards = 0.5 * (1 - s * q)  # z on the side the move leaves
            beyond = 0.5 * (1 + ca.tanh((ca.fabs(du) - ca.fabs(reach)) / eps))
            return straight + towards * beyond * (crossed - straight)

        def side(z):
            t = ca.tanh(z / eps)
            return t, (1 - t * t) / eps

        def magnitude(z):  # the power as exp(log): its derivative reuses the exp, where pow's calls pow again
            square = z * z + eps * eps
            m = ca.sqrt(square)
            return m, z / m, ca.exp(0.5 * (self.exponent - 1.0) * ca.log(square))

        def expressions(state, u):
            du, z = u - state[0], state[1]
            s = ca.tanh(du / direction_eps)
            z_next = move(z, du, s) if self.exponent == 1.0 else self._pieces(z, du, s, side, magnitude)
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
            ``40 / (β − |γ|)`` (input units) for ``n = 1``; for ``n != 1`` twice the bound plus 40
            over the slowest rate of approach to it.
        """
        if self.exponent == 1.0:
            return (np.inf, -np.inf), 40.0 / (self.beta - abs(self.gamma))
        bound = (self.beta + self.gamma) ** (-1.0 / self.exponent)
        return (np.inf, -np.inf), 2.0 * bound + 40.0 / (self.exponent * (self.beta - abs(self.gamma)) * bound ** (
            self.exponent - 1.0))

    def inverse_step(self, state, y_target: float) -> tuple[np.ndarray, float]:
        """The input that brings the output to ``y_target`` from ``state``, and the state after it.

        The Illinois method over a monotone move (NumPy or CasADi, the same arithmetic): the
        output along a move is smooth, so a modified regula falsi needs about 9 steps where a
        bisection needs 50. With ``k = 0`` a target beyond the loop's reach gives the input where
        ``ζ`` has all but reached its bound.

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
        if not (symbolic(state) or symbolic(y_target) or np.isfinite(y_target)):
            raise ValueError(f"y_target must be finite, got {y_target}")
        return illinois_inverse(self, state, y_target, *self.linear_beyond(), (self.linear_gain, self.linear_gain))
