"""Bench ``compliant``: nonlinear-stiffness compliant actuator, torque tracking (zhou2024).

Controllers: ``pid`` (torque PID whose output is the motor angle command), ``inverse-ff-pid``
(Fig. 14: the inverse power-function model turns τ_ref into s, eq. (8) inverted turns s
into the motor angle, and the same PID corrects the rest) and ``nmpc`` (torque-tracking
NMPC on the smoothed model, warm-started from the inverse model). Scenarios:
τ_ref = A·sin(0.2πt) N m for 20 s with A = 0.5, 1, 2 (Section V-C).
"""

from __future__ import annotations

from dataclasses import replace

import casadi as ca
import numpy as np

from experiments.baselines import Pid, PidGains
from experiments.bench import Bench, ControllerSpec, NmpcAdapter, Scenario
from models.power_function import PowerFunctionHysteresis
from mpc import DisturbanceEKF, Nmpc, NmpcController, NmpcSettings, PredictionModel
from plants.base import Measurement
from plants.compliant import CompliantActuator, CompliantParams

NOMINAL = CompliantParams()
"""What the controllers believe: Tables V–VII and our servo estimate."""

_H = NOMINAL.hysteresis
PLANT = replace(
    NOMINAL,
    hysteresis=replace(
        _H, torque_scale=1.03, k01=1.25 * _H.k01, k02=1.25 * _H.k02,
        exponent_positive=tuple(0.9 * g for g in _H.exponent_positive),
        exponent_negative=tuple(0.9 * g for g in _H.exponent_negative)),
    geometry=replace(NOMINAL.geometry, pretension=24.0),
    servo_wn=50.0,
    servo_zeta=0.7,
    backlash=0.002,
)
"""The simulated truth: torques +3 %, transitions 25 % wider with exponents −10 %, spring
pretension 24.0 N instead of 23.2 N, a slower, less damped position loop and ±2 mrad of
gearhead backlash that the motor encoder cannot see (zhou2024 Section VI names clearance
as a source of hysteresis)."""

PAPER_TABLE_IV = {0.5: (0.019, 0.053), 1.0: (0.025, 0.076), 2.0: (0.039, 0.133)}
"""zhou2024 Table IV, proposed inverse model + PID: RMSE and max error (N m)."""


class CompliantPid:
    """Torque PID on the motor angle, optionally with the inverse model as feed-forward."""

    horizon = 0

    def __init__(self, gains: PidGains, model: CompliantParams, feedforward: bool):
        self.model = model
        self.feedforward = feedforward
        self.pid = Pid(gains, model.sample_period, (-model.angle_limit, model.angle_limit))
        self.reset()

    def reset(self) -> None:
        """Clear the PID and the inverse model's memory."""
        self.pid.reset()
        self._inverse_state = self.model.hysteresis.initial_state()
        self.predicted_output = float("nan")

    def step(self, measurement: Measurement, ref_window) -> float:
        """Motor angle command for this sample."""
        ref = float(ref_window[0])
        ff = 0.0
        if self.feedforward:
            self._inverse_state, s_ref = self.model.hysteresis.inverse_step(self._inverse_state, ref)
            ff = float(self.model.geometry.theta(s_ref))
        return self.pid.update(ref - measurement.y, ff)

    def stats(self) -> None:
        return None


def prediction_model(p: CompliantParams, eps: float, substeps: int = 2,
                     direction_eps: float | None = None) -> PredictionModel:
    """Smooth model: x = [θ1, θ1', s_last, up, s01, s02, τ_r, τ, q_1..q_D], d = torque offset.

    ``q`` is the command delay line (``p.command_delay`` samples).
    """
    D = p.command_delay
    x = ca.SX.sym("x", 8 + D)
    u = ca.SX.sym("u")
    d = ca.SX.sym("d")
    h = p.sample_period / substeps
    cmd = x[8] if D > 0 else u

    def rhs(q):
        return ca.vertcat(q[1], p.servo_wn**2 * (cmd - q[0]) - 2 * p.servo_zeta * p.servo_wn * q[1])

    q = x[:2]
    for _ in range(substeps):
        k1 = rhs(q)
        k2 = rhs(q + h / 2 * k1)
        k3 = rhs(q + h / 2 * k2)
        k4 = rhs(q + h * k3)
        q = q + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    hys_next, _ = p.hysteresis.smooth_expressions(x[2:8], p.geometry.s(q[0], xp=ca), eps, direction_eps)
    queue = [x[8 + i] for i in range(1, D)] + ([u] if D > 0 else [])
    x_next = ca.vertcat(q, hys_next, *queue)
    names = ("angle", "rate", "s_last", "up", "s01", "s02", "tau_r", "torque",
             *(f"cmd_delay_{i + 1}" for i in range(D)))
    return PredictionModel(
        step=ca.Function("compliant_step", [x, u, d], [x_next], ["x", "u", "d"], ["x_next"]),
        output=ca.Function("compliant_output", [x, d], [x[7] + d], ["x", "d"], ["y"]),
        measure=ca.Function("compliant_measure", [x, d], [ca.vertcat(x[0], x[7] + d)], ["x", "d"], ["z"]),
        sample_period=p.sample_period,
        state_names=names,
    )


def inverse_inputs(p: CompliantParams, x, d, refs) -> np.ndarray:
    """Motor angles that the inverse model gives for ``refs − d`` from the state ``x``."""
    hys: PowerFunctionHysteresis = p.hysteresis
    state = np.asarray(x[2:8], float).copy()
    state[1] = 1.0 if state[1] >= 0.5 else 0.0
    out = np.empty(len(refs))
    for j, r in enumerate(refs):
        state, s = hys.inverse_step(state, float(r) - float(d[0]))
        out[j] = float(p.geometry.theta(s))
    return np.clip(out, -p.angle_limit, p.angle_limit)


def build_nmpc(model: CompliantParams, settings: NmpcSettings) -> NmpcAdapter:
    """The ``nmpc`` controller: EKF on [motor angle, torque] sensors, NLP, inverse warm start."""
    pm = prediction_model(model, settings.eps, direction_eps=settings.direction_eps or None)
    nmpc = Nmpc(pm, settings, -model.angle_limit, model.angle_limit, model.rate_limit * model.sample_period)
    quantum = 2 * np.pi / model.encoder_counts
    r_tau = model.torque_resolution**2 / 12 + model.torque_noise**2
    D = model.command_delay
    q_noise = [1e-9, 1e-4, 1e-12, 1e-12, 1e-12, 1e-12, 1e-10, 1e-8] + [1e-14] * D + [1e-6]
    ekf = DisturbanceEKF(pm, q_noise, [quantum**2 / 12 + 1e-12, r_tau])
    p0 = [1e-8, 1e-4, 1e-10, 1e-12, 1e-10, 1e-10, 1e-6, 1e-6] + [1e-14] * D + [1e-2]
    hys = model.hysteresis

    def initial_state(z):
        s = float(model.geometry.s(z[0]))
        return np.concatenate(([z[0], 0.0], hys.initial_state(s), np.full(D, z[0])))

    controller = NmpcController(nmpc, ekf, initial_state, lambda x, d, r: inverse_inputs(model, x, d, r), p0,
                                jump_threshold=0.2)
    return NmpcAdapter(controller, lambda m: np.array([m.sensors["angle"], m.y]))


def _sine(amplitude: float) -> Scenario:
    def reference(t):
        return amplitude * np.sin(0.2 * np.pi * np.asarray(t, float))
    return Scenario(f"sine-{amplitude:g}", f"τ_ref = {amplitude:g}·sin(0.2πt) N m (Section V-C)", 20.0, reference)


def _defaults() -> dict:
    return {"plant": PLANT, "model": NOMINAL, "pid": PidGains(kp=0.0, ki=2.0, kd=0.005),
            "nmpc": NmpcSettings(horizon=10, q_output=1e4, r_rate=10.0, eps=2e-4, warm_multipliers=True)}


BENCH = Bench(
    name="compliant",
    description="Nonlinear-stiffness compliant actuator, power-function hysteresis (zhou2024)",
    paper="zhou2024_power_function_hysteresis_compliant_actuator",
    output_name="torque",
    units="N m",
    input_units="rad",
    sample_period=NOMINAL.sample_period,
    scenarios={s.name: s for s in (_sine(0.5), _sine(1.0), _sine(2.0))},
    controllers={
        "pid": ControllerSpec("pid", "torque PID on the motor angle",
                              lambda c: CompliantPid(c["pid"], c["model"], feedforward=False)),
        "inverse-ff-pid": ControllerSpec("inverse-ff-pid", "inverse power-function model + PID (Fig. 14)",
                                         lambda c: CompliantPid(c["pid"], c["model"], feedforward=True)),
        "nmpc": ControllerSpec("nmpc", "torque NMPC, smoothed power-function model, inverse warm start",
                               lambda c: build_nmpc(c["model"], c["nmpc"])),
    },
    defaults=_defaults,
    make_plant=lambda c: CompliantActuator(c["plant"]),
    output_range=(-2.5, 2.5),
    paper_figures={(f"sine-{a:g}", "inverse-ff-pid"): {"rmse": r, "max_abs_error": m}
                   for a, (r, m) in PAPER_TABLE_IV.items()},
    input_bounds=(-NOMINAL.angle_limit, NOMINAL.angle_limit),
    loop=("s", "torque", "virtual deformation s (Table V units)", "torque [N m]"),
    default_scenario="sine-1",
)
