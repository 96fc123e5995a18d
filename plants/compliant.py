"""Nonlinear-stiffness compliant actuator with power-function hysteresis (zhou2024).

The output plate is fixed to the torque sensor (torque-tracking tests of Section V-C), so
the deformation angle θ1 is the motor's angle. The motor is a Maxon RE40 under a position
loop, modelled as a second-order lag with a rate limit::

    θm'' = ωs² (θ_cmd(t − delay) − θm) − 2 ζs ωs θm',   |θm'| ≤ rate_limit
    θ1 = Play_backlash[θm]                         (gearhead clearance)

The torque is the power-function hysteresis of the virtual deformation, τ = H[s(θ1)]
(eqs. (8)–(19)). Sensors: a 500 CPT encoder on the motor side (quadrature, through the
gearhead, so it does not see the backlash) and the ATI Mini45 with a resolution of
1/1504 N m; 100 Hz. The command reaches the drive one sample late (host → drive).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from hystmpc.models.base import clip, symbolic
from hystmpc.models.integrators import rk4
from hystmpc.models.power_function import PowerFunctionHysteresis, VirtualDeformation
from hystmpc.models.prediction import Dynamics, PredictionModel, build_prediction_model
from hystmpc.plants.base import Measurement, ParametrisedPlant


@dataclass(frozen=True)
class CompliantParams:
    """Parameters of the compliant actuator; the defaults are the *nominal* model."""

    hysteresis: PowerFunctionHysteresis = PowerFunctionHysteresis()
    """Torque/virtual-deformation hysteresis (Tables V–VII)."""
    geometry: VirtualDeformation = VirtualDeformation()
    """Virtual deformation s(θ1), eq. (8)."""
    servo_wn: float = 60.0
    """Natural frequency of the motor position loop (rad/s), about 10 Hz."""
    servo_zeta: float = 0.8
    """Damping ratio of the position loop."""
    rate_limit: float = 3.0
    """Largest motor speed at the output (rad/s)."""
    angle_limit: float = 0.5
    """|θ1| range (rad), Table I."""
    command_delay: int = 1
    """Samples between the controller's command and the drive acting on it."""
    backlash: float = 0.0
    """Half-width of the gearhead clearance between motor and θ1 (rad); nominal: none."""
    encoder_counts: int = 2000 * 43
    """Counts per output revolution: 500 CPT × 4 (quadrature) × 43:1 gearhead (our choice)."""
    torque_resolution: float = 1.0 / 1504.0
    """Torque-sensor resolution (N m), Section V."""
    torque_noise: float = 0.0003
    """Torque-sensor noise before quantisation (N m, standard deviation)."""
    sample_period: float = 0.01
    """Control sample period (s): 100 Hz."""
    substeps: int = 10
    """Integration substeps per sample in the plant."""

    def __post_init__(self):
        for name in ("servo_wn", "servo_zeta", "rate_limit", "angle_limit", "torque_resolution",
                     "sample_period"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be finite and > 0, got {value}")
        if not (np.isfinite(self.torque_noise) and self.torque_noise >= 0):
            raise ValueError(f"torque_noise must be finite and >= 0, got {self.torque_noise}")
        if self.command_delay < 0 or not (np.isfinite(self.backlash) and self.backlash >= 0):
            raise ValueError("command_delay and backlash must be >= 0")
        if self.encoder_counts < 1 or self.substeps < 1:
            raise ValueError("encoder_counts and substeps must be >= 1")


@dataclass
class CompliantActuator(ParametrisedPlant):
    """Simulated compliant actuator; input: motor angle command (rad); output: torque (N m)."""

    params: CompliantParams = field(default_factory=CompliantParams)

    def reset(self, seed: int) -> Measurement:
        """Start at rest at zero torque on the ascending branch; seed the sensor noise.

        Parameters
        ----------
        seed : int
            Seed of the torque-sensor noise.

        Returns
        -------
        Measurement
            The first measurement, at rest.
        """
        p = self.params
        self._rng = np.random.default_rng(seed)
        self._hys = p.hysteresis.initial_state()
        self._theta = float(p.geometry.theta(self._hys[0]))  # θ1 at the output
        self._motor = self._theta  # backlash centred
        self._omega = 0.0
        self._queue = [self._theta] * p.command_delay
        self._t = 0.0
        return self._measure()

    def step(self, theta_cmd: float) -> Measurement:
        """Apply the motor angle command (rad) for one sample.

        Parameters
        ----------
        theta_cmd : float
            Motor angle command (rad), clipped to ±``angle_limit``; the drive acts on it
            ``command_delay`` samples later.

        Returns
        -------
        Measurement
            The measurement at the end of the sample.
        """
        if not np.isfinite(theta_cmd):
            raise ValueError(f"plant input must be finite, got {theta_cmd}")
        p = self.params
        self._queue.append(float(np.clip(theta_cmd, -p.angle_limit, p.angle_limit)))
        cmd = self._queue.pop(0)
        h = p.sample_period / p.substeps
        for _ in range(p.substeps):
            acc = p.servo_wn**2 * (cmd - self._motor) - 2 * p.servo_zeta * p.servo_wn * self._omega
            self._omega = float(np.clip(self._omega + h * acc, -p.rate_limit, p.rate_limit))
            self._motor += h * self._omega  # semi-implicit Euler at 1 ms: stable for ωs h = 0.06
            self._theta = min(max(self._theta, self._motor - p.backlash), self._motor + p.backlash)
            self._hys, _ = p.hysteresis.step(self._hys, float(p.geometry.s(self._theta)))
        self._t += p.sample_period
        return self._measure()

    def _measure(self) -> Measurement:
        p = self.params
        quantum = 2 * np.pi / p.encoder_counts
        tau = p.hysteresis.output(self._hys)
        noisy = tau + p.torque_noise * self._rng.standard_normal()
        return Measurement(
            t=self._t,
            y=float(np.round(noisy / p.torque_resolution) * p.torque_resolution),
            sensors={"angle": float(np.round(self._motor / quantum) * quantum)},
            truth={"torque": tau, "angle": self._theta, "s": float(self._hys[0])},
        )


def servo_rhs(p: CompliantParams, x, theta_cmd) -> list:
    """Time derivative of ``x = [θ1, θ1']`` under the position loop, without the rate limit.

    Parameters
    ----------
    p : CompliantParams
        The actuator parameters.
    x : array_like or SX
        State ``[θ1, θ1']`` (rad, rad/s).
    theta_cmd : float or SX
        Motor angle command (rad).

    Returns
    -------
    list
        ``[θ1', θ1'']`` (rad/s, rad/s²).
    """
    return [x[1], p.servo_wn**2 * (theta_cmd - x[0]) - 2 * p.servo_zeta * p.servo_wn * x[1]]


def prediction_model(p: CompliantParams, eps: float, substeps: int = 2,
                     direction_eps: float | None = None) -> PredictionModel:
    """Smooth model ``x = [θ1, θ1', s_last, up, s01, s02, τ_r, τ, q_1..q_D]``, d = torque offset.

    The servo (no backlash, no rate limit) moves θ1; the power-function hysteresis follows
    s(θ1), eq. (8); ``q`` is the command delay line (``p.command_delay`` samples). Sensors:
    motor angle and torque.

    Parameters
    ----------
    p : CompliantParams
        The nominal parameters.
    eps : float
        Smoothing width of the hysteresis (see its ``smooth_step``).
    substeps : int, optional
        RK4 steps per sample.
    direction_eps : float, optional
        Smoothing width of the input direction (None: ``eps``).

    Returns
    -------
    PredictionModel
        The model, its CasADi Functions named ``compliant...``.
    """
    dynamics = Dynamics(
        state_names=("angle", "rate"), rhs=lambda x, u, h, d: servo_rhs(p, x, u),
        hysteresis_input=lambda x, u: p.geometry.s(x[0], xp=ca),
        sensor_names=("angle", "y"), measure=lambda x, h, y: [x[0], y])
    return build_prediction_model(p.hysteresis, p.sample_period, dynamics=dynamics, eps=eps,
                                  direction_eps=direction_eps, disturbance="output",
                                  delay_samples=p.command_delay, substeps=substeps, name="compliant")


def inverse_inputs(p: CompliantParams, x, d, refs):
    """Motor angles that the inverse model gives for ``refs − d`` from the state ``x`` of :func:`prediction_model`.

    NumPy, or CasADi expressions for a generated controller.

    Parameters
    ----------
    p : CompliantParams
        The nominal parameters.
    x : array_like or SX
        State of :func:`prediction_model`.
    d : array_like or SX
        Its disturbance, the torque offset (N m).
    refs : array_like or SX
        Torque references (N m), one per sample.

    Returns
    -------
    ndarray or SX
        One motor angle (rad) per reference, clipped to ±``angle_limit``.
    """
    hys: PowerFunctionHysteresis = p.hysteresis
    if symbolic(x):
        st, tau = ca.SX.sym("state", 6), ca.SX.sym("tau")  # one Function called per sample: small C
        inverse_step = ca.Function("power_function_inverse_step", [st, tau], [*hys.inverse_step(st, tau)])
        state = ca.vertcat(x[2], ca.if_else(x[3] >= 0.5, 1.0, 0.0), x[4:8])
        s_seq = []
        for j in range(refs.shape[0]):
            state, s = inverse_step(state, refs[j] - d[0])
            s_seq.append(s)
        return clip(p.geometry.theta(ca.vertcat(*s_seq)), -p.angle_limit, p.angle_limit)
    state = np.asarray(x[2:8], float).copy()
    state[1] = 1.0 if state[1] >= 0.5 else 0.0
    out = np.empty(len(refs))
    for j, r in enumerate(refs):
        state, s = hys.inverse_step(state, float(r) - float(d[0]))
        out[j] = float(p.geometry.theta(s))
    return np.clip(out, -p.angle_limit, p.angle_limit)


def initial_state(p: CompliantParams, z):
    """Model state at rest from the first sensor vector ``[motor angle, torque]`` (NumPy, or CasADi expressions).

    Parameters
    ----------
    p : CompliantParams
        The nominal parameters.
    z : array_like or SX
        Sensor vector ``[motor angle, torque]``; only the angle is read.

    Returns
    -------
    ndarray or SX
        State of :func:`prediction_model`: θ1 at the angle, at rest, the hysteresis started at its
        s(θ1), the delay line filled with the angle.
    """
    if symbolic(z):
        s = p.geometry.s(z[0], xp=ca)
        return ca.vertcat(z[0], 0.0, p.hysteresis.initial_state(s), ca.repmat(z[0], p.command_delay, 1))
    s = float(p.geometry.s(z[0]))
    return np.concatenate(([z[0], 0.0], p.hysteresis.initial_state(s), np.full(p.command_delay, z[0])))


def linear_model(p: CompliantParams, substeps: int = 2) -> PredictionModel:
    """The servo alone, in torque units, for ``inverse-lmpc``.

    The virtual torque ``v`` (the power-function model's output that the inverse compensation
    realises) follows the command as θ1 does, ``x = [τ_v, τ_v', q_1..q_D]``, ``y = τ_v + d``.
    Sensors: ``τ_v`` (the model's torque at the measured motor angle) and the torque.

    Parameters
    ----------
    p : CompliantParams
        The nominal parameters.
    substeps : int, optional
        RK4 steps per sample.

    Returns
    -------
    PredictionModel
        Input ``v`` (N m), sensors named ``angle`` and ``y``.
    """
    D = p.command_delay
    x, v, d = ca.SX.sym("x", 2 + D), ca.SX.sym("v"), ca.SX.sym("d")
    command = x[2] if D else v
    x_dyn = rk4(lambda xs, _t: ca.vertcat(*servo_rhs(p, xs, command)), x[:2], p.sample_period / substeps, substeps)
    x_next = ca.vertcat(x_dyn, *[x[2 + i] for i in range(1, D)], *([v] if D else []))
    names = ("torque_v", "torque_v_rate", *(f"delay_{i + 1}" for i in range(D)))
    return PredictionModel(
        step=ca.Function("compliant_linear_step", [x, v, d], [x_next], ["x", "u", "d"], ["x_next"]),
        output=ca.Function("compliant_linear_output", [x, d], [x[0] + d], ["x", "d"], ["y"]),
        measure=ca.Function("compliant_linear_measure", [x, d], [ca.vertcat(x[0], x[0] + d)], ["x", "d"], ["z"]),
        sample_period=p.sample_period, state_names=names, sensor_names=("angle", "y"))
