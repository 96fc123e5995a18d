"""Discrete-time prediction model used by the NMPC and its estimator."""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np


@dataclass(frozen=True)
class PredictionModel:
    """Nominal model ``x+ = step(x, u, d)``, ``y = output(x, d)``, ``z = measure(x, d)``.

    ``d`` is an unknown disturbance the estimator tracks and the NMPC holds constant over
    the horizon; it is what makes the tracking offset-free.
    """

    step: ca.Function
    """``(x, u, d) -> x_next``, smooth (CasADi SX)."""
    output: ca.Function
    """``(x, d) -> y``, the tracked output (scalar)."""
    measure: ca.Function
    """``(x, d) -> z``, what the sensors see (vector)."""
    sample_period: float
    """Sample period (s)."""
    state_names: tuple[str, ...]
    """One name per state, for logs and errors."""

    def __post_init__(self):
        for name, fun, n_in in (("step", self.step, 3), ("output", self.output, 2),
                                ("measure", self.measure, 2)):
            if fun.n_in() != n_in:
                raise ValueError(f"{name} must take {n_in} inputs, got {fun.n_in()}")
        if len(self.state_names) != self.nx:
            raise ValueError(f"{len(self.state_names)} state names for {self.nx} states")

    @property
    def nx(self) -> int:
        """Number of states."""
        return self.step.size1_in(0)

    @property
    def nu(self) -> int:
        """Number of inputs."""
        return self.step.size1_in(1)

    @property
    def nd(self) -> int:
        """Number of disturbance states."""
        return self.step.size1_in(2)

    @property
    def nz(self) -> int:
        """Number of measured signals."""
        return self.measure.size1_out(0)

    def rollout(self, x0, u_seq, d) -> np.ndarray:
        """States ``x_0..x_N`` (shape ``(N+1, nx)``) under the inputs ``u_seq`` (shape ``(N, nu)``)."""
        u_seq = np.asarray(u_seq, float).reshape(-1, self.nu)
        xs = np.empty((len(u_seq) + 1, self.nx))
        xs[0] = np.asarray(x0, float).ravel()
        for k, u in enumerate(u_seq):
            xs[k + 1] = np.asarray(self.step(xs[k], u, d)).ravel()
        return xs
