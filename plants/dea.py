"""Dielectric elastomer actuator with a 20 g load (wang2025 eq. (2)).

::

    x1' = x2
    x2' = f(x1, x2) + g(x1) W[u] + d(t)
    f = −ω² (x1 + β x1³) − 2 ζ ω x2          (hyperelastic stiffening, viscous damping)
    g = ω² (1 + γ tanh(x1 / 2 mm))           (bounded, > 0: Assumption 3)

so that at rest x1 ≈ W: the FCKP output is the displacement it would cause statically.
W[u] is the FCKP model with the *full* creep memory at the 100 Hz input rate (the input is
held between samples); the mechanics are integrated with RK4 at ``substeps`` per sample.
d(t) is a bounded, slow disturbance (Assumption 1); the laser sensor adds white noise.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from hystmpc.models.base import symbolic
from hystmpc.models.fckp import Fckp, FckpParams
from hystmpc.models.integrators import rk4
from hystmpc.models.prediction import CreepPredictionModel, Dynamics, PredictionModel, build_prediction_model
from hystmpc.plants.base import Measurement, ParametrisedPlant


@dataclass(frozen=True)
class DeaParams:
    """DEA plant parameters; the defaults are the *nominal* model the controllers know."""

    fckp: FckpParams = FckpParams()
    """Hysteresis and creep."""
    natural_frequency: float = 2 * np.pi * 6.0
    """ω of the membrane with its load (rad/s)."""
    damping_ratio: float = 0.7
    """ζ (VHB's strong viscoelastic damping lumped as viscous)."""
    stiffening: float = 0.02
    """β (1/mm²): hyperelastic stiffening."""
    gain_variation: float = 0.1
    """γ: how the electromechanical gain g changes with displacement."""
    disturbance: float = 0.0
    """Amplitude of d(t) as an equivalent static displacement (mm)."""
    noise: float = 0.0005
    """Laser sensor noise (mm, standard deviation)."""
    substeps: int = 10
    """RK4 steps per 10 ms sample."""

    def __post_init__(self):
        for name in ("natural_frequency", "damping_ratio"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be finite and > 0, got {value}")
        for name in ("stiffening", "disturbance", "noise"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {value}")
        if not 0 <= self.gain_variation < 1:
            raise ValueError(f"gain_variation must be in [0, 1), got {self.gain_variation}")
        if self.substeps < 1:
            raise ValueError(f"substeps must be >= 1, got {self.substeps}")

    @property
    def sample_period(self) -> float:
        """Control sample period (s)."""
        return self.fckp.sample_period

    def f(self, x1, x2):
        """Hyperelastic and damping acceleration (mm/s²).

        Parameters
        ----------
        x1 : float or SX
            Displacement (mm).
        x2 : float or SX
            Velocity (mm/s).

        Returns
        -------
        float or SX
            ``−ω² (x1 + β x1³) − 2 ζ ω x2`` (mm/s²).
        """
        w = self.natural_frequency
        return -w * w * (x1 + self.stiffening * x1**3) - 2 * self.damping_ratio * w * x2

    def g(self, x1, tanh=np.tanh):
        """Electromechanical gain (1/s²), bounded in ω²(1 ± γ).

        Parameters
        ----------
        x1 : float or SX
            Displacement (mm).
        tanh : callable, optional
            The tanh to use: ``np.tanh`` (default) or ``ca.tanh`` on CasADi expressions.

        Returns
        -------
        float or SX
            ``ω² (1 + γ tanh(x1 / 2 mm))`` (1/s²).
        """
        return self.natural_frequency**2 * (1 + self.gain_variation * tanh(x1 / 2.0))


def mechanics_rhs(p: DeaParams, x, w, extra_acceleration, tanh=np.tanh) -> list:
    """Time derivative of ``x = [x1, x2]`` (mm, mm/s) driven by the FCKP output ``w`` (mm).

    Parameters
    ----------
    p : DeaParams
        The plant parameters.
    x : array_like or SX
        State ``[x1, x2]`` (mm, mm/s).
    w : float or SX
        FCKP output (mm).
    extra_acceleration : float or SX
        Added to ``x2'``, e.g. the disturbance d(t) (mm/s²).
    tanh : callable, optional
        As in :meth:`DeaParams.g`.

    Returns
    -------
    list
        ``[x1', x2']`` (mm/s, mm/s²).
    """
    return [x[1], p.f(x[0], x[1]) + p.g(x[0], tanh=tanh) * w + extra_acceleration]


def steady_output_input(p: DeaParams, y):
    """The FCKP output W that holds the displacement at ``y`` at rest: ``f(y, 0) + g(y) W = 0``.

    Parameters
    ----------
    p : DeaParams
        The plant parameters.
    y : float, array_like or SX
        Displacement (mm).

    Returns
    -------
    ndarray or SX
        W (mm), of the shape of ``y``; a CasADi expression for a symbolic ``y``.
    """
    tanh = ca.tanh if symbolic(y) else np.tanh
    y = y if symbolic(y) else np.asarray(y, float)
    return (y + p.stiffening * y**3) / (1 + p.gain_variation * tanh(y / 2.0))


LEARNED_GAIN_RANGE = (-0.5, 1.0)
"""The model uses a learned relative gain error of W clipped to this range (half to twice the
nominal stroke). Outside it the model does not depend on the estimate, so an estimate that
left it would not be pulled back (on a membrane with a 19 % longer stroke the estimate went
much higher with a process noise of 1e-6 than with dea's 1e-7)."""


def _bounded_gain(error):
    low, high = LEARNED_GAIN_RANGE
    return ca.fmin(ca.fmax(error, low), high) if symbolic(error) else float(np.clip(error, low, high))


def prediction_model(p: DeaParams, eps: float, direction_eps: float | None = None,
                     learn_gain: bool = False) -> CreepPredictionModel:
    """The NMPC's model: smooth FCKP in volts, the GL creep integral, the nominal mechanics.

    ``d`` adds to the FCKP output W (an input disturbance); the sensor is the laser. The
    creep history is a parameter of the horizon prediction (docs/dea.md, "Model").

    Parameters
    ----------
    p : DeaParams
        The nominal parameters.
    eps : float
        Smoothing width of the FCKP (see :meth:`Fckp.smooth_step`).
    direction_eps : float, optional
        Smoothing width of the input direction (None: ``eps``).
    learn_gain : bool, optional
        Make ``d = [offset, e]``: the mechanics see ``(1 + e) W + offset``, ``e`` a relative
        error of the stroke (the static gain) that the estimator learns, used within
        :data:`LEARNED_GAIN_RANGE`.

    Returns
    -------
    CreepPredictionModel
        The model, its CasADi Functions named ``dea...``.
    """
    if learn_gain:
        def rhs(x, u, h, d):
            return mechanics_rhs(p, x, (1 + _bounded_gain(d[1])) * h + d[0], 0.0, tanh=ca.tanh)
        dynamics = Dynamics(state_names=("displacement", "velocity"), disturbances=2, rhs=rhs,
                            output=lambda x, h: x[0], steady_input=lambda y: steady_output_input(p, y),
                            steady_correction=lambda h, d: (h - d[0]) / (1 + _bounded_gain(d[1])))
        mode = "dynamics"
    else:
        dynamics = Dynamics(state_names=("displacement", "velocity"),
                            rhs=lambda x, u, h, d: mechanics_rhs(p, x, h, d, tanh=ca.tanh),
                            output=lambda x, h: x[0], steady_input=lambda y: steady_output_input(p, y))
        mode = "hysteresis"
    return build_prediction_model(Fckp(p.fckp), p.sample_period, dynamics=dynamics, eps=eps,
                                  direction_eps=direction_eps, disturbance=mode,
                                  creep_order=p.fckp.creep_order, name="dea")


def linear_model(p: DeaParams, operating_point: float = 1.5, substeps: int = 2) -> PredictionModel:
    """The mechanics linearised at ``x1 = operating_point`` (mm).

    They are driven by the FCKP output W (the virtual input of ``inverse-lmpc``) plus an input
    disturbance ``d`` (mm, as in :func:`prediction_model`); the creep is left to ``d``. Sensor:
    the laser.

    Parameters
    ----------
    p : DeaParams
        The nominal parameters.
    operating_point : float, optional
        Displacement to linearise at (mm), at rest.
    substeps : int, optional
        RK4 steps per sample.

    Returns
    -------
    PredictionModel
        Input W (mm), state ``[displacement, velocity]``, output and measurement the displacement.
    """
    x, w, d = ca.SX.sym("x", 2), ca.SX.sym("w"), ca.SX.sym("d")
    x0 = ca.DM([operating_point, 0.0])
    w0 = float(steady_output_input(p, operating_point))
    exact = ca.vertcat(*mechanics_rhs(p, x, w, 0.0, tanh=ca.tanh))
    at = {"x": x0, "w": w0}
    jx = ca.Function("jx", [x, w], [ca.jacobian(exact, x)])(at["x"], at["w"])
    jw = ca.Function("jw", [x, w], [ca.jacobian(exact, w)])(at["x"], at["w"])
    A, B = np.asarray(jx, float), np.asarray(jw, float).ravel()

    def rhs(xs, _t):  # f(x0, w0) = 0: the tangent dynamics around the operating point
        return ca.mtimes(ca.DM(A), xs - x0) + ca.DM(B) * (w - w0 + d)

    x_next = rk4(rhs, x, p.sample_period / substeps, substeps)
    return PredictionModel(
        step=ca.Function("dea_linear_step", [x, w, d], [x_next], ["x", "u", "d"], ["x_next"]),
        output=ca.Function("dea_linear_output", [x, d], [x[0]], ["x", "d"], ["y"]),
        measure=ca.Function("dea_linear_measure", [x, d], [x[0]], ["x", "d"], ["z"]),
        sample_period=p.sample_period, state_names=("displacement", "velocity"))


def disturbance(t, amplitude: float, omega: float):
    """d(t): two slow sines, bounded by 1.5 ω² · amplitude (mm/s²).

    Parameters
    ----------
    t : float or ndarray
        Time (s).
    amplitude : float
        Amplitude as an equivalent static displacement (mm).
    omega : float
        ω of the membrane (rad/s).

    Returns
    -------
    float or ndarray
        d(t) (mm/s²).
    """
    return amplitude * omega**2 * (np.sin(2 * np.pi * 0.07 * t) + 0.5 * np.sin(2 * np.pi * 0.31 * t + 1.0))


@dataclass
class DeaActuator(ParametrisedPlant):
    """Simulated DEA; input: amplifier command (V, 0–10); output: displacement (mm)."""

    params: DeaParams = field(default_factory=DeaParams)

    def __post_init__(self):
        self.model = Fckp(self.params.fckp)
        super().__post_init__()

    def reset(self, seed: int) -> Measurement:
        """At rest at zero volts, demagnetised, empty creep memory; seed the sensor noise.

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
        self._kp = self.model.initial_state()
        self._creep = self.model.creep()
        self._x = np.zeros(2)
        self._W = 0.0
        self._u = 0.0
        self._t = 0.0
        return self._measure()

    def step(self, u: float) -> Measurement:
        """Apply the voltage command ``u`` (V) for one sample.

        Parameters
        ----------
        u : float
            Voltage command (V), clipped to [0, ``u_max``].

        Returns
        -------
        Measurement
            The measurement at the end of the sample.
        """
        if not np.isfinite(u):
            raise ValueError(f"plant input must be finite, got {u}")
        p = self.params
        self._u = float(np.clip(u, 0.0, p.fckp.u_max))
        self._kp, self._W = self.model.creep_step(self._kp, self._creep, self._u)

        def rhs(x, t):
            return np.array(mechanics_rhs(p, x, self._W, disturbance(t, p.disturbance, p.natural_frequency)))
        self._x = rk4(rhs, self._x, p.sample_period / p.substeps, p.substeps, self._t)
        self._t = self._t + p.sample_period
        return self._measure()

    def _measure(self) -> Measurement:
        noisy = self._x[0] + self.params.noise * self._rng.standard_normal()
        return Measurement(t=self._t, y=float(noisy), sensors={},
                           truth={"displacement": float(self._x[0]), "W": self._W,
                                  "voltage": self._u})
