"""Generalised (asymmetric, saturating) Prandtl–Ishlinskii: a PI model behind a monotone output curve.

``y = Γ(v)``, ``v = p0·u + Σ p_i Play_{r_i}[u]``, with ``Γ`` continuous, strictly increasing and
piecewise linear on knots ``v_0 < … < v_m`` (values ``g_0 < … < g_m``), continued with its end
slopes. The plays give the loop's memory and its symmetric width; ``Γ`` bends the two branches
alike, so a loop can saturate at one end and widen at the other, which a plain PI model
(odd-symmetric branches) cannot. Both parts invert exactly: ``Γ⁻¹`` is piecewise linear and the
PI inverse is exact, so the inverse of the whole is too.

State: the PI model's (``[u_last, F_1..F_n]``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from hystmpc.models.base import SteppedModel, builtin_max, check_smoothing, smooth_function, symbolic
from hystmpc.models.prandtl_ishlinskii import PrandtlIshlinskii
from hystmpc.models.smooth import smooth_max


def _hinges(x, start, values, slopes, knots, eps=None):
    """``values[0] + slopes[0]·(x − start) + Σ_j (slopes[j] − slopes[j−1])·max(x − knots[j], 0)``."""
    total = values + slopes[0] * (x - start)
    for j in range(1, len(slopes)):
        kink = slopes[j] - slopes[j - 1]
        if kink == 0:
            continue
        if eps:
            ramp = smooth_max(x - knots[j], 0.0, eps)
        elif symbolic(x):
            ramp = builtin_max(x - knots[j], 0.0)
        else:
            ramp = np.maximum(x - knots[j], 0.0)
        total = total + kink * ramp
    return total


@dataclass(frozen=True)
class GeneralisedPI(SteppedModel):
    """``y = Γ(PI[u])`` (see the module)."""

    linear_gain: float
    """p0 >= 0 of the PI part."""
    thresholds: tuple[float, ...]
    """Play thresholds r_i > 0 (input units)."""
    weights: tuple[float, ...]
    """Play weights p_i > 0."""
    output_knots: tuple[float, ...]
    """Knots ``v_j`` of Γ on the PI output, increasing."""
    output_values: tuple[float, ...]
    """``Γ(v_j)``, strictly increasing (output units)."""
    inner: PrandtlIshlinskii | None = field(init=False, repr=False, compare=False, default=None)
    """The PI part."""

    def __post_init__(self):
        for name in ("output_knots", "output_values"):
            object.__setattr__(self, name, tuple(float(v) for v in getattr(self, name)))
        object.__setattr__(self, "inner", PrandtlIshlinskii(self.linear_gain, self.thresholds, self.weights))
        knots, values = np.asarray(self.output_knots), np.asarray(self.output_values)
        if len(knots) < 2 or len(values) != len(knots):
            raise ValueError(f"output_knots and output_values need the same length >= 2, got {len(knots)} and "
                             f"{len(values)}")
        if not (np.all(np.isfinite(knots)) and np.all(np.isfinite(values))):
            raise ValueError("output_knots and output_values must be finite")
        if np.any(np.diff(knots) <= 0) or np.any(np.diff(values) <= 0):
            raise ValueError("output_knots and output_values must both be strictly increasing (Γ invertible)")

    @property
    def slopes(self) -> np.ndarray:
        """Γ's slope on each knot interval."""
        return np.diff(self.output_values) / np.diff(self.output_knots)

    def curve(self, v, eps: float | None = None):
        """``Γ(v)`` (NumPy or CasADi; ``eps`` smooths its kinks).

        Parameters
        ----------
        v : float, ndarray or CasADi expression
            PI output.
        eps : float, optional
            Width over which each kink is smoothed (PI output units); None or 0: the exact curve.

        Returns
        -------
        float, ndarray or CasADi expression
            ``Γ(v)`` (output units).
        """
        return _hinges(v, self.output_knots[0], self.output_values[0], self.slopes, self.output_knots, eps)

    def curve_inverse(self, y):
        """``Γ⁻¹(y)`` (NumPy or CasADi).

        Parameters
        ----------
        y : float, ndarray or CasADi expression
            Output.

        Returns
        -------
        float, ndarray or CasADi expression
            The PI output ``v`` with ``Γ(v) = y``.
        """
        return _hinges(y, self.output_values[0], self.output_knots[0], 1.0 / self.slopes, self.output_values)

    @property
    def state_names(self) -> tuple[str, ...]:
        """The PI part's state."""
        return self.inner.state_names

    def initial_state(self, u0: float = 0.0) -> np.ndarray:
        """The PI part's virgin state at ``u0``.

        Parameters
        ----------
        u0 : float, optional
            Input.

        Returns
        -------
        ndarray
            ``[u0, 0, …, 0]``.
        """
        return self.inner.initial_state(u0)

    def output(self, state):
        """``Γ`` of the PI output (NumPy or CasADi).

        Parameters
        ----------
        state : ndarray or CasADi expression
            A state of the PI part.

        Returns
        -------
        float or CasADi expression
            The output.
        """
        y = self.curve(self.inner.output(state))
        return y if symbolic(y) else float(y)

    def step(self, state, u: float) -> tuple[np.ndarray, float]:
        """Exact step: ``(state, Γ(v))``.

        Parameters
        ----------
        state : ndarray or CasADi expression
            State before the step.
        u : float or CasADi expression
            New input.

        Returns
        -------
        state : ndarray or CasADi expression
            The PI part's state after the step.
        y : float or CasADi expression
            ``Γ`` of the PI output after the step.
        """
        nxt, v = self.inner.step(state, u)
        y = self.curve(v)
        return nxt, y if symbolic(y) else float(y)

    def smooth_step(self, eps: float, direction_eps: float | None = None) -> ca.Function:
        """The PI part's smooth step, then Γ with its kinks smoothed over ``eps`` times the PI part's gain.

        Scaling by the gain keeps ``eps`` in input units. The error is the PI part's times Γ's
        largest slope, plus ``eps·gain/2`` per kink times its change of slope.

        Parameters
        ----------
        eps : float
            Smoothing width of the PI part (see :meth:`PrandtlIshlinskii.smooth_step`) and, times
            its gain, of Γ's kinks; > 0.
        direction_eps : None
            Must stay unset: no direction detection (``ValueError`` otherwise).

        Returns
        -------
        casadi.Function
            ``(state, u) -> (state_next, y)``.
        """
        check_smoothing(eps, direction_eps, has_direction=False)
        inner = self.inner.smooth_step(eps)
        width = eps * self.inner.gain

        def expressions(x, u):
            x_next, v = inner(x, u)
            return x_next, self.curve(v, width)
        return smooth_function("generalised_pi_smooth", len(self.state_names), expressions)

    def inverse_step(self, state, y_target: float) -> tuple[np.ndarray, float]:
        """Exact: ``Γ⁻¹`` of the target, then the PI part's inverse (NumPy or CasADi).

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
        if not symbolic(state) and not symbolic(y_target):
            if not np.isfinite(y_target):
                raise ValueError(f"y_target must be finite, got {y_target}")
            return self.inner.inverse_step(state, float(self.curve_inverse(float(y_target))))
        return self.inner.inverse_step(state, self.curve_inverse(y_target))
