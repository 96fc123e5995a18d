"""PID on the tracking error, alone or behind an inverse feed-forward.

This is the usual scheme for an actuator with hysteresis (zhou2024 Fig. 14).

* :class:`PidController`: PID on the tracking error, optionally plus a feed-forward term;
* :class:`InverseFeedforward`: the inverse hysteresis model turns the reference into an input;
* :func:`inverse_feedforward_pid` puts the two together for any model that has an inverse;
* :class:`ModeNotch`: a filter on the command that damps a lightly damped mode of the model, as
  the notch filters of piezo-stage servo controllers do.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np

from hystmpc.models.base import HysteresisModel
from hystmpc.models.linear_dynamics import LinearDynamics

NOTCH_DAMPING = 0.7
"""A :class:`ModeNotch` replaces a mode damped less than this by one damped this much."""


@dataclass(frozen=True)
class PidGains:
    """PID gains on the tracking error (units: input per output unit, per second...)."""

    kp: float = 0.0
    """Proportional gain."""
    ki: float = 0.0
    """Integral gain (per second)."""
    kd: float = 0.0
    """Derivative gain (seconds), on the filtered error derivative."""
    derivative_filter: float = 0.02
    """Time constant of the first-order filter on the derivative (s)."""

    def __post_init__(self):
        for name in ("kp", "ki", "kd", "derivative_filter"):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {getattr(self, name)}")


class Pid:
    """Discrete PID with clamping anti-windup and an additive feed-forward term.

    ``u = clip(ff + kp e + I + kd ė_f, lo, hi)``, and within ``rate`` of the last output; the
    integral only accumulates while that does not push a saturated output further into
    saturation.

    Parameters
    ----------
    gains : PidGains
        The gains.
    dt : float
        Sample period (s).
    limits : tuple of float
        ``(lo, hi)``: the output's bounds.
    rate : float, optional
        Largest output change per sample (default: none).
    command_filter : ModeNotch, optional
        Filters ``ff + kp e + I + kd ė_f`` before the clip.
    """

    def __init__(self, gains: PidGains, dt: float, limits: tuple[float, float], rate: float = np.inf,
                 command_filter: ModeNotch | None = None):
        self.gains = gains
        self.dt = dt
        self.lo, self.hi = limits
        self.rate = rate
        self.command_filter = command_filter
        self.reset()

    def reset(self) -> None:
        """Clear the integrator, the derivative filter and the command filter."""
        self._integral = 0.0
        self._last_error = None
        self._derivative = 0.0
        self._last_output = None
        if self.command_filter is not None:
            self.command_filter.reset()

    def update(self, error: float, feedforward: float = 0.0) -> float:
        """Output for this sample's error.

        Parameters
        ----------
        error : float
            The tracking error ``e``.
        feedforward : float, optional
            The feed-forward term ``ff``.

        Returns
        -------
        float
            ``u``, within the bounds and the rate.
        """
        g = self.gains
        if self._last_error is not None and g.kd > 0:
            raw = (error - self._last_error) / self.dt
            alpha = self.dt / (g.derivative_filter + self.dt)
            self._derivative += alpha * (raw - self._derivative)
        self._last_error = error
        integral = self._integral + g.ki * error * self.dt
        u = feedforward + g.kp * error + integral + g.kd * self._derivative
        lo, hi = self.lo, self.hi
        if self._last_output is not None and np.isfinite(self.rate):
            lo, hi = max(lo, self._last_output - self.rate), min(hi, self._last_output + self.rate)
        if lo <= u <= hi or np.sign(error) != np.sign(u - 0.5 * (lo + hi)):
            self._integral = integral
        command = feedforward + g.kp * error + self._integral + g.kd * self._derivative
        if self.command_filter is not None:
            command = self.command_filter(command)
        self._last_output = float(np.clip(command, lo, hi))
        return self._last_output


class ModeNotch:
    """A filter on the command that replaces a lightly damped mode by a damped one.

    ``N(z) = g · a_mode(z) / a_damped(z)``: its zeros are the poles of the model's mode under a
    zero-order hold, its poles those of the same natural frequency at ``target_damping``, and
    ``g`` sets its static gain to 1 (and ``|N| <= 1`` at every frequency). In front of a linear
    block it cancels the model's mode exactly, so a step of the command does not ring it; with
    the hysteresis in between the cancellation is approximate (the loop's local slope scales
    what the mode sees).

    Parameters
    ----------
    dynamics : LinearDynamics
        The model's linear block, second order.
    sample_period : float
        Sample period (s).
    target_damping : float, optional
        Damping of the mode that replaces the model's.

    Raises
    ------
    ValueError
        The block is not second order.
    """

    def __init__(self, dynamics: LinearDynamics, sample_period: float, target_damping: float = NOTCH_DAMPING):
        if dynamics.kind != "second-order":
            raise ValueError(f"a mode notch needs a second-order block, got {dynamics.kind!r}")
        numerator = dynamics.zoh_filter(sample_period)[1]
        denominator = replace(dynamics, damping=target_damping).zoh_filter(sample_period)[1]
        self.b = numerator * (denominator.sum() / numerator.sum())
        """Numerator coefficients (in powers of the delay operator)."""
        self.a = denominator
        """Denominator coefficients, ``a[0] = 1``."""
        self.reset()

    def reset(self) -> None:
        """Forget the filter's state (it starts at rest at its first input)."""
        self._state = None

    def __call__(self, command: float) -> float:
        """The filtered command for this sample (transposed direct form II).

        Parameters
        ----------
        command : float
            This sample's command; the first one after :meth:`reset` is taken as at rest.

        Returns
        -------
        float
            The filtered command.
        """
        b, a = self.b, self.a
        if self._state is None:  # at rest at the first command: the output equals it
            s2 = (b[2] - a[2]) * command
            self._state = [(b[1] - a[1]) * command + s2, s2]
        out = b[0] * command + self._state[0]
        self._state = [b[1] * command - a[1] * out + self._state[1], b[2] * command - a[2] * out]
        return float(out)


class Feedforward(Protocol):
    """A feed-forward term: ``reset()``, then one value per sample."""

    def reset(self) -> None:
        """Back to the state before the first sample."""

    def __call__(self, measurement, ref_window) -> float:
        """The feed-forward value for this sample."""


class PidController:
    """PID on ``reference − measured output``, plus an optional feed-forward term.

    Parameters
    ----------
    gains : PidGains
        The gains.
    sample_period : float
        Sample period (s).
    limits : tuple of float
        The input's bounds; the output is clipped there (with anti-windup).
    feedforward : Feedforward, optional
        Added to the PID output before the clip.
    rate : float, optional
        Largest input change per sample (default: none).
    command_filter : ModeNotch, optional
        Filters the command before the clip (:class:`Pid`).
    """

    horizon = 0

    def __init__(self, gains: PidGains, sample_period: float, limits: tuple[float, float],
                 feedforward: Feedforward | None = None, rate: float = np.inf,
                 command_filter: ModeNotch | None = None):
        self.pid = Pid(gains, sample_period, limits, rate, command_filter)
        self.feedforward = feedforward
        self.reset()

    def reset(self) -> None:
        """Clear the PID and the feed-forward's memory."""
        self.pid.reset()
        if self.feedforward is not None:
            self.feedforward.reset()
        self.predicted_output = float("nan")

    def step(self, measurement, ref_window) -> float:
        """Input for this sample.

        Parameters
        ----------
        measurement : Measurement
            This sample's measurement (its output ``y``).
        ref_window : ndarray
            The references from this sample on (``horizon + 1`` samples).

        Returns
        -------
        float
            The input to send.
        """
        ff = 0.0 if self.feedforward is None else self.feedforward(measurement, ref_window)
        return self.pid.update(float(ref_window[0]) - measurement.y, ff)

    def stats(self) -> None:
        """None: nothing is solved."""
        return None


class InverseFeedforward:
    """The input that the inverse hysteresis model gives for the reference.

    ``h = steady_input(r)`` is the hysteresis output that holds the output at ``r`` at rest
    (default: ``r`` itself), ``v = hysteresis.inverse_step(h)`` the hysteresis input and
    ``u = input_of(v)`` the actuator input (default: ``v``). The inverse model's memory
    follows its own inputs; a target the model cannot reach holds the last input.

    Parameters
    ----------
    hysteresis : HysteresisModel
        The nominal hysteresis model.
    steady_input, input_of : callable, optional
        See above.
    preview : int, optional
        Target the reference this many samples ahead (a known dead time).
    """

    def __init__(self, hysteresis: HysteresisModel, steady_input: Callable | None = None,
                 input_of: Callable | None = None, preview: int = 0):
        self.hysteresis, self.steady_input, self.input_of, self.preview = hysteresis, steady_input, input_of, preview
        self.reset()

    def reset(self) -> None:
        """The inverse model at rest."""
        self._state = self.hysteresis.initial_state()
        self._last = None

    def __call__(self, measurement, ref_window) -> float:
        """The inverse model's input for the reference ``preview`` samples ahead."""
        r = float(ref_window[min(self.preview, len(ref_window) - 1)])
        target = r if self.steady_input is None else float(self.steady_input(r))
        try:
            self._state, v = self.hysteresis.inverse_step(self._state, target)
        except ValueError:  # beyond the model's reach: hold (the PID does the rest)
            if self._last is None:
                raise
            return self._last
        self._last = float(v if self.input_of is None else self.input_of(v))
        return self._last




def inverse_feedforward_pid(hysteresis: HysteresisModel, gains: PidGains, sample_period: float,
                            limits: tuple[float, float], steady_input: Callable | None = None,
                            input_of: Callable | None = None, preview: int = 0, rate: float = np.inf,
                            command_filter: ModeNotch | None = None) -> PidController:
    """Inverse feed-forward + PID (the usual scheme for an actuator with hysteresis).

    Parameters
    ----------
    hysteresis : HysteresisModel
        The nominal hysteresis model.
    gains : PidGains
        The PID's gains.
    sample_period : float
        Sample period (s).
    limits : tuple of float
        The input's bounds.
    steady_input, input_of : callable, optional
        As in :class:`InverseFeedforward`.
    preview : int, optional
        As in :class:`InverseFeedforward`; the controller asks for ``preview`` samples of
        reference preview (its ``horizon``).
    rate : float, optional
        Largest input change per sample (default: none).
    command_filter : ModeNotch, optional
        Filters the command before the clip (:class:`Pid`).

    Returns
    -------
    PidController
        The PID with the inverse feed-forward.
    """
    controller = PidController(gains, sample_period, limits,
                               InverseFeedforward(hysteresis, steady_input, input_of, preview), rate, command_filter)
    controller.horizon = preview
    return controller


@dataclass(frozen=True)
class FeedforwardPidGains(PidGains):
    """PID gains and the feed-forward's reference preview (``--set inverse_ff_pid.*``)."""

    preview: int = 0
    """Samples by which the inverse feed-forward leads the reference (it covers the dead time,
    the sampling's one sample and the block's lag)."""

    def __post_init__(self):
        super().__post_init__()
        if not (isinstance(self.preview, int) and 0 <= self.preview <= 1000):
            raise ValueError(f"preview must be an integer in [0, 1000], got {self.preview}")
