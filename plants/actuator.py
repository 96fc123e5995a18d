"""A simulated actuator from any hysteresis model and dynamics: the truth for your own actuator.

:class:`HysteresisActuator` runs the *exact*, non-smooth hysteresis model with the same
:class:`~hystmpc.models.prediction.Dynamics` the prediction model is built from (written
with plain arithmetic, its callables take NumPy values too), a dead time, sensor noise
and the input's physical bounds. Give it other parameters than the controller's model
(a mismatch) so that the NMPC never runs on its own model.
"""

from __future__ import annotations

import numpy as np

from hystmpc.models.base import HysteresisModel
from hystmpc.models.fractional import GrunwaldLetnikov
from hystmpc.models.integrators import rk4
from hystmpc.models.prediction import Dynamics, check_sampling
from hystmpc.plants.base import Measurement


class HysteresisActuator:
    """Exact hysteresis + dynamics + dead time + sensor noise.

    Parameters
    ----------
    hysteresis : HysteresisModel
        The true hysteresis (its exact ``step`` runs).
    sample_period : float
        Sample period (s); the input is held over it.
    dynamics : Dynamics, optional
        The true dynamics (None: the output is the hysteresis output).
    delay_samples : int
        Dead time between the input and the hysteresis (input-driven) or dynamics.
    noise : float or dict
        Standard deviation of the sensor noise: one value for every sensor, or per sensor
        name (``y`` is the measured output).
    input_bounds : tuple of float
        The actuator saturates its input there.
    substeps : int
        RK4 steps per sample for continuous dynamics (a state-driven hysteresis steps after
        each).
    rest_input : float
        Input at rest before the first sample.
    creep_order : float
        α > 0 puts a Grünwald–Letnikov creep integral ``D^(−α)`` (full memory) between an
        input-driven hysteresis and the dynamics, as :func:`build_prediction_model` does.
    """

    def __init__(self, hysteresis: HysteresisModel, sample_period: float, dynamics: Dynamics | None = None,
                 delay_samples: int = 0, noise: float | dict = 0.0,
                 input_bounds: tuple[float, float] = (-np.inf, np.inf), substeps: int = 10,
                 rest_input: float = 0.0, creep_order: float = 0.0):
        check_sampling(sample_period, delay_samples, substeps)
        if not (np.isfinite(creep_order) and 0 <= creep_order < 1):
            raise ValueError(f"creep_order must be in [0, 1), got {creep_order}")
        if creep_order > 0 and dynamics is not None and dynamics.hysteresis_input is not None:
            raise ValueError("creep is supported after an input-driven hysteresis only")
        self.creep_order = float(creep_order)
        self.hysteresis, self.dynamics = hysteresis, dynamics or Dynamics()
        self._sample_period, self.delay_samples, self.substeps = float(sample_period), delay_samples, substeps
        names = self.dynamics.sensor_names
        if isinstance(noise, dict) and set(noise) - set(names):
            raise ValueError(f"noise names sensors {sorted(set(noise) - set(names))} the dynamics do not have; "
                             f"sensors: {', '.join(names) or 'none'}")
        self.noise = {n: float(noise.get(n, 0.0) if isinstance(noise, dict) else noise) for n in names}
        if any(not (np.isfinite(v) and v >= 0) for v in self.noise.values()):
            raise ValueError(f"noise must be finite and >= 0, got {noise}")
        self.input_bounds = (float(input_bounds[0]), float(input_bounds[1]))
        self.rest_input = float(rest_input)
        self.reset(0)

    @property
    def sample_period(self) -> float:
        """Sample period (s)."""
        return self._sample_period

    def reset(self, seed: int) -> Measurement:
        """At rest at ``rest_input``: relaxed hysteresis, dynamics at zero (or their ``rest_state``); seed the noise.

        Parameters
        ----------
        seed : int
            Seed of the sensor noise.

        Returns
        -------
        Measurement
            The first measurement, at rest.
        """
        self._rng = np.random.default_rng(seed)
        self._hys = self.hysteresis.initial_state(self.rest_input)
        self._x = np.zeros(len(self.dynamics.state_names))
        if self.dynamics.rest_state is not None:  # a long memory (a creep) starts settled
            self._x = np.array([float(v) for v in self.dynamics.rest_state(self.hysteresis.output(self._hys))])
        self._queue = [self.rest_input] * self.delay_samples
        self._u = self.rest_input
        self._t = 0.0
        self._creep = None
        if self.creep_order > 0:
            self._creep = GrunwaldLetnikov(-self.creep_order, self._sample_period)
            self._creep_output = 0.0  # nothing pushed yet: the creep integral of the past is zero
        return self._measure()

    def _rhs(self, u, h):
        return lambda x, t: self._evaluate(x, u, h)

    def _evaluate(self, x, u, h) -> np.ndarray:
        value = np.atleast_1d(np.asarray(self.dynamics.rhs(x, u, h, 0.0), float)).ravel()
        if len(value) != len(x):
            raise ValueError(f"the dynamics' rhs gives {len(value)} entries for {len(x)} states")
        return value

    def step(self, u: float) -> Measurement:
        """Apply the input ``u`` for one sample (saturated at the input bounds).

        Parameters
        ----------
        u : float
            The input; it reaches the actuator after ``delay_samples`` samples.

        Returns
        -------
        Measurement
            The measurement at the end of the sample.
        """
        if not np.isfinite(u):
            raise ValueError(f"plant input must be finite, got {u}")
        self._u = float(np.clip(u, *self.input_bounds))
        self._queue.append(self._u)
        u_in = self._queue.pop(0)
        dyn, hys = self.dynamics, self.hysteresis
        if dyn.hysteresis_input is None:
            self._hys, h = hys.step(self._hys, u_in)
            if self._creep is not None:
                h = self._creep_output = self._creep.push(h)
            if dyn.state_names:
                self._x = self._advance(u_in, h, self.substeps)
        else:
            for _ in range(1 if dyn.discrete else self.substeps):
                self._x = self._advance(u_in, hys.output(self._hys), 1)
                self._hys, _ = hys.step(self._hys, float(dyn.hysteresis_input(self._x, u_in)))
        self._t += self._sample_period
        return self._measure()

    def _advance(self, u_in: float, h: float, substeps: int) -> np.ndarray:
        if self.dynamics.discrete:
            return self._evaluate(self._x, u_in, h)
        return rk4(self._rhs(u_in, h), self._x, self._sample_period / self.substeps, substeps)

    def _measure(self) -> Measurement:
        dyn = self.dynamics
        h = self.hysteresis.output(self._hys)
        if self._creep is not None:
            h = self._creep_output
        y = float(dyn.output(self._x, h))
        if not dyn.sensor_names:
            values = []
        else:
            values = [y] if dyn.measure is None else [float(v) for v in dyn.measure(self._x, h, y)]
        noisy = {n: v + self.noise[n] * self._rng.standard_normal() for n, v in zip(dyn.sensor_names, values,
                                                                                      strict=True)}
        return Measurement(t=self._t, y=noisy.get("y", y), sensors={n: v for n, v in noisy.items() if n != "y"},
                           truth={"output": y, "hysteresis_output": float(h), "input": self._u,
                                  **{name: float(v) for name, v in zip(dyn.state_names, self._x, strict=True)}})


class BlendedActuator:
    """Two noise-free actuators driven by the same inputs; the output ``(1 − w)·y_a + w·y_b`` plus sensor noise.

    With two models fitted to one record, ``w`` sets how far the plant moves from ``a`` toward
    ``b``: a truth that differs from a model as much as the actuator does.

    Parameters
    ----------
    first, second : HysteresisActuator
        The two actuators (their own noise is not used).
    weight : float
        ``w`` in [0, 1].
    noise : float
        Standard deviation of the sensor noise on ``y``.
    """

    def __init__(self, first: HysteresisActuator, second: HysteresisActuator, weight: float, noise: float = 0.0):
        if not (np.isfinite(weight) and 0 <= weight <= 1):
            raise ValueError(f"weight must be in [0, 1], got {weight}")
        if not (np.isfinite(noise) and noise >= 0):
            raise ValueError(f"noise must be finite and >= 0, got {noise}")
        if first.sample_period != second.sample_period:
            raise ValueError(f"the two actuators' sample periods differ: {first.sample_period} and "
                             f"{second.sample_period} s")
        self.first, self.second, self.weight, self.noise = first, second, float(weight), float(noise)
        self.input_bounds = first.input_bounds
        self.reset(0)

    @property
    def sample_period(self) -> float:
        """Sample period (s)."""
        return self.first.sample_period

    def reset(self, seed: int) -> Measurement:
        """Both actuators at rest; seed the noise.

        Parameters
        ----------
        seed : int
            Seed of the sensor noise (and of the two actuators' own).

        Returns
        -------
        Measurement
            The first, blended measurement.
        """
        self._rng = np.random.default_rng(seed)
        return self._blend(self.first.reset(seed), self.second.reset(seed))

    def step(self, u: float) -> Measurement:
        """Apply the input ``u`` to both for one sample.

        Parameters
        ----------
        u : float
            The input.

        Returns
        -------
        Measurement
            The blended measurement at the end of the sample (no ``sensors``).
        """
        return self._blend(self.first.step(u), self.second.step(u))

    def _blend(self, a: Measurement, b: Measurement) -> Measurement:
        w = self.weight
        truth = {k: (1 - w) * v + w * b.truth[k] for k, v in a.truth.items() if k in b.truth and k != "input"}
        truth["input"] = a.truth["input"]
        y = truth["output"]
        return Measurement(t=a.t, y=y + self.noise * self._rng.standard_normal(), truth=truth)
