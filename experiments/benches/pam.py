"""Bench ``pam``: antagonistic pneumatic-muscle joint with Maxwell-slip hysteresis (vo2012).

Controllers: ``pi`` (PI on the angle error, output Δp command), ``pi-hc`` (the same PI plus
the Maxwell-slip hysteresis compensation fed by the measured angle, vo2012 Fig. 1) and
``nmpc`` (offset-free NMPC with the smoothed Maxwell-slip model, warm-started from the
inverse model). Scenarios: square waves of 10–40° at 0.1 Hz (two cycles, Fig. 7) and a
30° sine at 0.1 Hz (our addition).
"""

from __future__ import annotations

from dataclasses import replace

import casadi as ca
import numpy as np

from experiments.baselines import Pid, PidGains
from experiments.bench import Bench, ControllerSpec, NmpcAdapter, Scenario
from models.maxwell_slip import MaxwellSlip
from mpc import DisturbanceEKF, Nmpc, NmpcController, NmpcSettings, PredictionModel
from plants.base import Measurement
from plants.pam_joint import (
    PamJoint,
    PamJointParams,
    constraint_pressure,
    joint_acceleration,
    perturbed_hysteresis,
    torque_slope,
)

NOMINAL = PamJointParams()
"""What the controllers believe: Table 1 hysteresis, no creep, no volume coupling."""

PLANT = replace(
    NOMINAL,
    hysteresis=perturbed_hysteresis(NOMINAL.hysteresis, k_scale=1.08, w_scale=0.92),
    torque_per_bar=0.95 * NOMINAL.torque_per_bar,
    passive_stiffness=1.04 * NOMINAL.passive_stiffness,
    damping=1.3 * NOMINAL.damping,
    pressure_wn=0.9 * NOMINAL.pressure_wn,
    pressure_zeta=0.8 * NOMINAL.pressure_zeta,
    volume_coupling=0.0015,
    creep_torque=0.2,
)
"""The simulated truth: hysteresis elements ±8 %, a0 −5 %, stiffness +4 %, damping +30 %,
a slower, less damped pressure loop with a slew limit and volume coupling, and a 0.2 N m
creep drift over 20 s (vo2012 Section 1: creep makes the joint time-varying)."""


class PamPi:
    """vo2012 Fig. 1: PI on the angle error, optionally plus Δp_hys from the MS model.

    The gains (group ``pi``) are the same with and without compensation, as in the paper.
    """

    horizon = 0

    def __init__(self, gains: PidGains, model: PamJointParams, compensate: bool):
        self.model = model
        self.compensate = compensate
        self.pid = Pid(gains, model.sample_period, (-model.dp_limit, model.dp_limit))
        self.reset()

    def reset(self) -> None:
        """Clear the integrator and the compensator's memory."""
        self.pid.reset()
        self._hys = None
        self.predicted_output = float("nan")

    def step(self, measurement: Measurement, ref_window) -> float:
        """PI output (+ compensation) for this sample."""
        comp = 0.0
        if self.compensate:
            if self._hys is None:
                self._hys = self.model.hysteresis.initial_state(measurement.y)
            self._hys, comp = self.model.hysteresis.step(self._hys, measurement.y)
        return self.pid.update(float(ref_window[0]) - measurement.y, comp)

    def stats(self) -> None:
        return None


# ---------------------------------------------------------------------------------------
# Nominal prediction model: x = [θ, ω, Δp, Δp', q_1..q_D, F_1..F_M], d = torque (N m)
# ---------------------------------------------------------------------------------------

def prediction_model(p: PamJointParams, eps: float, substeps: int = 2) -> PredictionModel:
    """Smooth discrete-time model of the joint for the NMPC and its EKF.

    The pressure command passes a ``D``-sample delay line (states ``q``); the hysteresis
    elements move with θ through :func:`models.smooth.smooth_clip` relative to the sample's
    start, so a monotone θ within a sample gives the exact Maxwell-slip update up to eps.
    """
    ms: MaxwellSlip = p.hysteresis
    D, M = p.delay_samples, ms.n_elements
    x = ca.SX.sym("x", 4 + D + M)
    u = ca.SX.sym("u")
    d = ca.SX.sym("d")
    theta0 = x[0]
    forces0 = [x[4 + D + i] for i in range(M)]
    dp_cmd = x[4] if D > 0 else u

    def rhs(s):
        dp_hys = ca.sum1(ca.vertcat(*ms.smooth_forces(forces0, theta0, s[0], eps)))
        acc = joint_acceleration(p, s[0], s[1], s[2], dp_hys, d, xp=ca)
        dd = p.pressure_wn**2 * (dp_cmd - s[2]) - 2 * p.pressure_zeta * p.pressure_wn * s[3]
        return ca.vertcat(s[1], acc, s[3], dd)

    s = x[:4]
    h = p.sample_period / substeps
    for _ in range(substeps):
        k1 = rhs(s)
        k2 = rhs(s + h / 2 * k1)
        k3 = rhs(s + h / 2 * k2)
        k4 = rhs(s + h * k3)
        s = s + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    queue = [x[4 + i] for i in range(1, D)] + ([u] if D > 0 else [])
    forces = ms.smooth_forces(forces0, theta0, s[0], eps)
    x_next = ca.vertcat(s, *queue, *forces)
    names = ("angle", "rate", "pressure", "pressure_rate", *(f"cmd_delay_{i + 1}" for i in range(D)),
             *(f"ms_force_{i + 1}" for i in range(M)))
    return PredictionModel(
        step=ca.Function("pam_step", [x, u, d], [x_next], ["x", "u", "d"], ["x_next"]),
        output=ca.Function("pam_output", [x, d], [x[0]], ["x", "d"], ["y"]),
        measure=ca.Function("pam_measure", [x, d], [ca.vertcat(x[0], x[2])], ["x", "d"], ["z"]),
        sample_period=p.sample_period,
        state_names=names,
    )


def inverse_inputs(p: PamJointParams, x, d, refs) -> np.ndarray:
    """Static inverse along the reference: Δp_cons(r) + Δp_hys(path) − d/a(r), eqs. (2)–(3).

    The command reaches the pressure ``D`` samples later, so input ``j`` aims at ``r_{j+D}``.
    """
    D, M = p.delay_samples, p.hysteresis.n_elements
    refs = np.asarray(refs, float)
    n = len(refs)
    hys = np.concatenate(([x[0]], np.clip(x[4 + D: 4 + D + M], -np.asarray(p.hysteresis.w),
                                          np.asarray(p.hysteresis.w))))
    need = np.empty(n)
    for j in range(n):
        r = refs[min(j + D, n - 1)]
        hys, dp_hys = p.hysteresis.step(hys, r)
        need[j] = constraint_pressure(p, r) + dp_hys - float(d[0]) / torque_slope(p, r)
    return need


def build_nmpc(model: PamJointParams, settings: NmpcSettings) -> NmpcAdapter:
    """The ``nmpc`` controller: EKF on [θ, Δp] sensors, NLP, inverse warm start."""
    pm = prediction_model(model, settings.eps)
    D, M = model.delay_samples, model.hysteresis.n_elements
    nmpc = Nmpc(pm, settings, -model.dp_limit, model.dp_limit, model.pressure_slew * model.sample_period)
    q_noise = [1e-6, 1e-2, 1e-5, 1e-2] + [1e-12] * D + [1e-7] * M + [1e-4]
    quantum = 360.0 / model.encoder_counts
    ekf = DisturbanceEKF(pm, q_noise, [quantum**2 / 12 + 1e-6, model.pressure_noise_bar**2 + 1e-6])
    p0 = [1e-3, 1.0, 1e-3, 1.0] + [1e-12] * D + [1e-4] * M + [0.1]

    def initial_state(z):
        return np.concatenate(([z[0], 0.0, z[1], 0.0], np.zeros(D + M)))

    controller = NmpcController(nmpc, ekf, initial_state, lambda x, d, r: inverse_inputs(model, x, d, r), p0,
                                jump_threshold=1.0)
    return NmpcAdapter(controller, lambda m: np.array([m.y, m.sensors["pressure"]]))


def _square(amplitude: float) -> Scenario:
    def reference(t):
        t = np.asarray(t, float)
        return np.where(np.mod(t, 10.0) < 5.0, amplitude, -amplitude)
    return Scenario(f"square-{amplitude:g}", f"±{amplitude:g}° square wave, 0.1 Hz, two cycles (Fig. 7)",
                    20.0, reference)


def _sine(amplitude: float) -> Scenario:
    def reference(t):
        return amplitude * np.sin(2 * np.pi * 0.1 * np.asarray(t, float))
    return Scenario(f"sine-{amplitude:g}", f"{amplitude:g}° sine, 0.1 Hz, two cycles", 20.0, reference)


def _defaults() -> dict:
    # PI gains (bar/deg, bar/(deg s)) from a grid search; see docs/pam.md.
    return {"plant": PLANT, "model": NOMINAL, "pi": PidGains(kp=0.08, ki=0.4), "nmpc": NmpcSettings()}


def _scenarios() -> dict[str, Scenario]:
    scenarios = [_square(a) for a in (10, 20, 30, 40)] + [_sine(30)]
    return {s.name: s for s in scenarios}


BENCH = Bench(
    name="pam",
    description="Antagonistic pneumatic-muscle joint, Maxwell-slip Δp/angle hysteresis (vo2012)",
    paper="vo2012_maxwell_slip_pneumatic_muscle_joint",
    output_name="angle",
    units="deg",
    input_units="bar",
    sample_period=NOMINAL.sample_period,
    scenarios=_scenarios(),
    controllers={
        "pi": ControllerSpec("pi", "PI on the angle error, no compensation",
                             lambda c: PamPi(c["pi"], c["model"], compensate=False)),
        "pi-hc": ControllerSpec("pi-hc", "PI + Maxwell-slip hysteresis compensation (Fig. 1)",
                                lambda c: PamPi(c["pi"], c["model"], compensate=True)),
        "nmpc": ControllerSpec("nmpc", "offset-free NMPC, smoothed Maxwell-slip model, inverse warm start",
                               lambda c: build_nmpc(c["model"], c["nmpc"])),
    },
    defaults=_defaults,
    make_plant=lambda c: PamJoint(c["plant"]),
    output_range=(-45.0, 45.0),
    input_bounds=(-NOMINAL.dp_limit, NOMINAL.dp_limit),
    loop=("angle", "dp_hys", "joint angle [deg]", "Δp_hys [bar]"),
    default_scenario="square-20",
)
