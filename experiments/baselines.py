"""Building blocks of the papers' baseline controllers."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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

    ``u = clip(ff + kp e + I + kd ė_f, lo, hi)``; the integral only accumulates while that
    does not push a saturated output further into saturation.
    """

    def __init__(self, gains: PidGains, dt: float, limits: tuple[float, float]):
        self.gains = gains
        self.dt = dt
        self.lo, self.hi = limits
        self.reset()

    def reset(self) -> None:
        """Clear the integrator and the derivative filter."""
        self._integral = 0.0
        self._last_error = None
        self._derivative = 0.0

    def update(self, error: float, feedforward: float = 0.0) -> float:
        """Output for this sample's error."""
        g = self.gains
        if self._last_error is not None and g.kd > 0:
            raw = (error - self._last_error) / self.dt
            alpha = self.dt / (g.derivative_filter + self.dt)
            self._derivative += alpha * (raw - self._derivative)
        self._last_error = error
        integral = self._integral + g.ki * error * self.dt
        u = feedforward + g.kp * error + integral + g.kd * self._derivative
        if self.lo <= u <= self.hi or np.sign(error) != np.sign(u - 0.5 * (self.lo + self.hi)):
            self._integral = integral
        return float(np.clip(feedforward + g.kp * error + self._integral + g.kd * self._derivative,
                             self.lo, self.hi))


class Replay:
    """Plays a precomputed input sequence open loop (offline optima; not a controller)."""

    horizon = 0

    def __init__(self, inputs):
        self.inputs = np.asarray(inputs, float)
        self.reset()

    def reset(self) -> None:
        """Back to the first input."""
        self._k = 0
        self.predicted_output = float("nan")

    def step(self, measurement, ref_window) -> float:
        """The next input of the sequence (the last one once it runs out)."""
        u = float(self.inputs[min(self._k, len(self.inputs) - 1)])
        self._k += 1
        return u

    def stats(self) -> None:
        return None
