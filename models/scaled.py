"""A hysteresis model seen through a gain (``y = gain · H[u]``) or through offsets.

The parametric operator of katalenic2013 maps an input to an output in the input's own
units (``v ≈ u ± p1``); a user's actuator measures something else (µm, N). ``Scaled`` puts
the gain between them and keeps the model's whole shape (exact step, smooth step, inverse).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from hystmpc.models.base import SteppedModel, smooth_function, symbolic


@dataclass(frozen=True)
class Scaled(SteppedModel):
    """``gain · inner``: output scaled, input and state unchanged."""

    inner: object
    """Any :class:`hystmpc.models.base.HysteresisModel`."""
    gain: float = 1.0
    """Output per inner output unit, != 0."""

    def __post_init__(self):
        if not (np.isfinite(self.gain) and self.gain != 0):
            raise ValueError(f"gain must be finite and != 0, got {self.gain}")

    @property
    def state_names(self) -> tuple[str, ...]:
        """The inner model's state."""
        return tuple(self.inner.state_names)

    def initial_state(self, u0: float = 0.0) -> np.ndarray:
        """The inner model's relaxed state.

        Parameters
        ----------
        u0 : float, optional
            Input the state rests at.

        Returns
        -------
        ndarray
            The inner model's ``initial_state(u0)``.
        """
        return self.inner.initial_state(u0)

    def output(self, state):
        """``gain ·`` the inner output (NumPy or CasADi).

        Parameters
        ----------
        state : ndarray or CasADi expression
            A state of the inner model.

        Returns
        -------
        float or CasADi expression
            The output.
        """
        y = self.gain * self.inner.output(state)
        return y if symbolic(y) else float(y)

    def step(self, state, u: float) -> tuple[np.ndarray, float]:
        """Exact step; returns ``(state, gain · y_inner)``.

        Parameters
        ----------
        state : ndarray or CasADi expression
            State before the step.
        u : float or CasADi expression
            New input.

        Returns
        -------
        state : ndarray or CasADi expression
            The inner model's state after the step.
        y : float or CasADi expression
            ``gain`` times the inner output.
        """
        state, y = self.inner.step(state, u)
        y = self.gain * y
        return state, y if symbolic(y) else float(y)

    def smooth_step(self, eps: float, direction_eps: float | None = None) -> ca.Function:
        """The inner smooth step with its output scaled.

        Parameters
        ----------
        eps : float
            Smoothing width, passed to the inner model's ``smooth_step``.
        direction_eps : float, optional
            Direction-detection width, passed likewise.

        Returns
        -------
        casadi.Function
            ``(state, u) -> (state_next, y)``.
        """
        inner = self.inner.smooth_step(eps, direction_eps)

        def expressions(x, u):
            x_next, y = inner(x, u)
            return x_next, self.gain * y
        return smooth_function("scaled_smooth", len(self.state_names), expressions)

    def inverse_step(self, state, y_target: float) -> tuple[np.ndarray, float]:
        """The inner inverse of ``y_target / gain``.

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
        return self.inner.inverse_step(state, (y_target if symbolic(y_target) else float(y_target)) / self.gain)


@dataclass(frozen=True)
class Offset(SteppedModel):
    """``inner`` seen through an input and an output offset: ``y = inner[u − input_offset] + output_offset``.

    A sensor that does not read zero at rest, or an amplifier's bias: identification fits
    them beside the family's own parameters. The state is the inner model's (its input
    entries in the inner model's coordinates).
    """

    inner: object
    """Any :class:`hystmpc.models.base.HysteresisModel`."""
    input_offset: float = 0.0
    """Subtracted from the input before the inner model (input units)."""
    output_offset: float = 0.0
    """Added to the inner model's output (output units)."""

    def __post_init__(self):
        for name in ("input_offset", "output_offset"):
            if not np.isfinite(getattr(self, name)):
                raise ValueError(f"{name} must be finite, got {getattr(self, name)}")

    @property
    def state_names(self) -> tuple[str, ...]:
        """The inner model's state."""
        return tuple(self.inner.state_names)

    def initial_state(self, u0: float = 0.0) -> np.ndarray:
        """The inner model's relaxed state at ``u0``.

        Parameters
        ----------
        u0 : float, optional
            Input the state rests at (this model's input: the inner model's is ``u0 − input_offset``).

        Returns
        -------
        ndarray
            The inner model's ``initial_state(u0 − input_offset)``.
        """
        return self.inner.initial_state(u0 - self.input_offset)

    def output(self, state):
        """The inner output plus the output offset (NumPy or CasADi).

        Parameters
        ----------
        state : ndarray or CasADi expression
            A state of the inner model.

        Returns
        -------
        float or CasADi expression
            The output.
        """
        y = self.inner.output(state) + self.output_offset
        return y if symbolic(y) else float(y)

    def step(self, state, u: float) -> tuple[np.ndarray, float]:
        """Exact step of the inner model at ``u − input_offset``.

        Parameters
        ----------
        state : ndarray or CasADi expression
            State before the step.
        u : float or CasADi expression
            New input.

        Returns
        -------
        state : ndarray or CasADi expression
            The inner model's state after the step.
        y : float or CasADi expression
            The inner output plus ``output_offset``.
        """
        state, y = self.inner.step(state, u - self.input_offset)
        y = y + self.output_offset
        return state, y if symbolic(y) else float(y)

    def smooth_step(self, eps: float, direction_eps: float | None = None) -> ca.Function:
        """The inner smooth step, shifted.

        Parameters
        ----------
        eps : float
            Smoothing width, passed to the inner model's ``smooth_step``.
        direction_eps : float, optional
            Direction-detection width, passed likewise.

        Returns
        -------
        casadi.Function
            ``(state, u) -> (state_next, y)``.
        """
        inner = self.inner.smooth_step(eps, direction_eps)

        def expressions(x, u):
            x_next, y = inner(x, u - self.input_offset)
            return x_next, y + self.output_offset
        return smooth_function("offset_smooth", len(self.state_names), expressions)

    def inverse_step(self, state, y_target: float) -> tuple[np.ndarray, float]:
        """The inner inverse of ``y_target − output_offset``, shifted back to this input.

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
            The input (the inner model's plus ``input_offset``).
        """
        target = y_target - self.output_offset
        state, u = self.inner.inverse_step(state, target if symbolic(target) else float(target))
        u = u + self.input_offset
        return state, u if symbolic(u) else float(u)
