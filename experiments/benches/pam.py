"""Bench ``pam``: antagonistic pneumatic-muscle joint with Maxwell-slip hysteresis (vo2012).

Controllers: ``pi`` (PI on the angle error, output Δp command), ``pi-hc`` (the same PI plus
the Maxwell-slip hysteresis compensation fed by the measured angle, vo2012 Fig. 1) and
``nmpc`` (offset-free NMPC with the smoothed Maxwell-slip model, warm-started from the
inverse model). Scenarios: square waves of 10–40° at 0.1 Hz (two cycles, Fig. 7) and a
30° sine at 0.1 Hz (our addition).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from hystmpc.experiments.baselines import AdditiveCompensation, HysteresisCompensation, PidController, PidGains
from hystmpc.experiments.bench import MULTIPLE_SHOOTING, Bench, ControllerSpec
from hystmpc.experiments.runner import Scenario
from hystmpc.models.prediction import Smoothing
from hystmpc.mpc import (
    DisturbanceEKF,
    InputBounds,
    NmpcController,
    NmpcSettings,
    RtiSettings,
    SolverSettings,
    StateObserver,
)
from hystmpc.mpc.linear_mpc import InverseLinearMpc, LinearMpcSettings
from hystmpc.plants.pam_joint import (
    ESTIMATES,
    PamJoint,
    PamJointParams,
    inverse_inputs,
    linear_model,
    perturbed_hysteresis,
    prediction_model,
    rest_state,
    static_compensation,
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


@dataclass(frozen=True)
class DisturbanceNoise:
    """Process noise of a Kalman filter on the joint where the model is least sure.

    Set by ``--set lmpc_estimator.KEY=VALUE`` for ``inverse-lmpc``.

    The filter estimates the joint's states and an unknown torque ``d``. If it trusts the
    model's velocity dynamics and lets ``d`` move fast, an inertia or gain error in the
    model is read as a torque that changes with the acceleration, and the NMPC's answer to
    it closes a 3–4 Hz limit cycle (docs/pam.md). A large velocity noise makes the estimate
    follow the encoder instead; ``d`` then takes up what stays: creep, payload, friction.
    """

    velocity: float = 10.0
    """Variance per sample of the joint rate ω ((deg/s)²)."""
    disturbance: float = 1e-3
    """Variance per sample of the disturbance torque d ((N m)²)."""

    def __post_init__(self):
        for name in ("velocity", "disturbance"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be finite and > 0, got {value}")


@dataclass(frozen=True)
class EstimatorNoise(DisturbanceNoise):
    """The NMPC's EKF (``--set estimator.KEY=VALUE``).

    :class:`DisturbanceNoise` plus three model errors it learns
    (:data:`~hystmpc.plants.pam_joint.ESTIMATES`), each a random walk of a relative error.
    Learning the torque gain removes the slow tracking error a wrong a0 or stiffness leaves on a
    sine; learning the pressure loop's ωp and ζp removes the ringing after steps on a joint whose
    valve loop is less damped than the model's (docs/pam.md, "Robustness").
    """

    gain: float = 1e-6
    """Variance per sample of the relative error of the muscles' torque per bar (0: not
    estimated)."""
    pressure_frequency: float = 1e-5
    """Variance per sample of the relative error of the pressure loop's natural frequency
    (0: not estimated)."""
    pressure_damping: float = 1e-4
    """Variance per sample of the relative error of the pressure loop's damping ratio (0: not
    estimated)."""
    initial: float = 0.04
    """Variance of each estimated relative error before the first measurement (0.04: a
    standard deviation of 20 %)."""

    def __post_init__(self):
        super().__post_init__()
        if not (np.isfinite(self.initial) and self.initial > 0):
            raise ValueError(f"initial must be finite and > 0, got {self.initial}")
        for name in ESTIMATES:
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be finite and >= 0 (0: not estimated), got {value}")
        if self.initial != EstimatorNoise.initial and not any(getattr(self, name) > 0 for name in ESTIMATES):
            raise ValueError(f"initial={self.initial} applies to the learned model errors, but "
                             f"{', '.join(ESTIMATES)} are all 0 (nothing is learned)")


def _build_pi(config: dict, compensate: bool) -> PidController:
    """vo2012 Fig. 1: PI on the angle error, optionally plus Δp_hys from the MS model.

    The gains (group ``pi``) are the same with and without compensation, as in the paper.
    """
    model: PamJointParams = config["model"]
    return PidController(config["pi"], model.sample_period, (-model.dp_limit, model.dp_limit),
                         HysteresisCompensation(model.hysteresis) if compensate else None)


def _build_nmpc(config: dict) -> NmpcController:
    """The ``nmpc`` controller: EKF on [θ, Δp] sensors, NLP, inverse warm start."""
    model: PamJointParams = config["model"]
    smoothing: Smoothing = config["smoothing"]
    noise: EstimatorNoise = config["estimator"]
    estimates = tuple(name for name in ESTIMATES if getattr(noise, name) > 0)
    pm = prediction_model(model, smoothing.eps, smoothing.direction, estimates=estimates)
    D, M = model.delay_samples, model.hysteresis.n_elements
    q_noise = ([1e-6, noise.velocity, 1e-5, 1e-2] + [1e-7] * M + [1e-12] * D + [noise.disturbance]
               + [getattr(noise, name) for name in estimates])
    quantum = 360.0 / model.encoder_counts
    ekf = DisturbanceEKF(pm, q_noise, [quantum**2 / 12 + 1e-6, model.pressure_noise_bar**2 + 1e-6])
    p0 = [1e-3, 1.0, 1e-3, 1.0] + [1e-4] * M + [1e-12] * D + [0.1] + [noise.initial] * len(estimates)
    observer = StateObserver(pm, ekf, lambda z: rest_state(model, z), p0)
    bounds = InputBounds(-model.dp_limit, model.dp_limit, model.pressure_slew * model.sample_period)
    learns_gain = "gain" in estimates
    return NmpcController(pm, bounds, config["nmpc"], config["solver"], observer=observer,
                          inverse=lambda est, refs: inverse_inputs(model, est.x, est.d, refs, learns_gain),
                          jump_threshold=1.0)


def _build_inverse_lmpc(config: dict) -> InverseLinearMpc:
    """``inverse-lmpc``: a compensation from the measured angle and a linear MPC on the joint.

    The compensation is the Maxwell-slip compensation of ``pi-hc`` plus the static balance
    (eq. (2)) beyond its slope at 0, both from the measured angle; the linear MPC is on the joint
    linearised at 0, with the NMPC's horizon, bounds and preview, and a Kalman filter with the
    NMPC's disturbance model (its own noise, group ``lmpc_estimator``).
    """
    model: PamJointParams = config["model"]
    hysteresis = HysteresisCompensation(model.hysteresis)

    def offset(measurement):
        return hysteresis(measurement, None) + static_compensation(model, measurement.y)

    offset.reset = hysteresis.reset
    compensation = AdditiveCompensation(offset, lambda m, c: [m.y, m.sensors["pressure"] - c])
    D = model.delay_samples
    noise: DisturbanceNoise = config["lmpc_estimator"]
    quantum = 360.0 / model.encoder_counts
    bounds = InputBounds(-model.dp_limit, model.dp_limit, model.pressure_slew * model.sample_period)
    return InverseLinearMpc(
        linear_model(model), compensation, bounds, config["lmpc"],
        process_noise=[1e-6, noise.velocity, 1e-5, 1e-2] + [1e-12] * D + [noise.disturbance],
        measurement_noise=[quantum**2 / 12 + 1e-6, model.pressure_noise_bar**2 + 1e-6],
        initial_state=lambda z: np.concatenate(([z[0], 0.0, z[1], 0.0], np.zeros(D))),
        initial_covariance=[1e-3, 1.0, 1e-3, 1.0] + [1e-12] * D + [0.1])


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
    # PI gains (bar/deg, bar/(deg s)) from a grid search; see docs/pam.md. The RTI step's full step is
    # the lowest-cost one on every recorded sample, so `descent` skips the shorter steps' costs.
    return {"plant": PLANT, "model": NOMINAL, "pi": PidGains(kp=0.08, ki=0.4), "nmpc": NmpcSettings(r_rate=10.0),
            "smoothing": Smoothing(eps=1e-3), "solver": SolverSettings(rti=RtiSettings(line_search="descent")),
            "estimator": EstimatorNoise(),
            "lmpc": LinearMpcSettings(horizon=20, r_rate=30.0),
            "lmpc_estimator": DisturbanceNoise(velocity=1.0, disturbance=1e-2)}


NMPC_GROUPS = ("model", "nmpc", "smoothing", "solver", "estimator")
MODEL_ONLY = "the controllers' model has no {}; it is the plant's (plant.{})"

BENCH = Bench(
    name="pam",
    description="Antagonistic pneumatic-muscle joint, Maxwell-slip Δp/angle hysteresis (vo2012)",
    paper="vo2012_maxwell_slip_pneumatic_muscle_joint",
    output_name="angle",
    units="deg",
    input_units="bar",
    sensor_units=(("pressure", "bar, the measured pressure difference"),),
    sample_period=NOMINAL.sample_period,
    scenarios={s.name: s for s in [_square(a) for a in (10, 20, 30, 40)] + [_sine(30)]},
    controllers={
        "pi": ControllerSpec("pi", "PI on the angle error, no compensation",
                             lambda c: _build_pi(c, compensate=False), ("model", "pi")),
        "pi-hc": ControllerSpec("pi-hc", "PI + Maxwell-slip hysteresis compensation (Fig. 1)",
                                lambda c: _build_pi(c, compensate=True), ("model", "pi")),
        "inverse-lmpc": ControllerSpec("inverse-lmpc", "Maxwell-slip and static compensation + linear MPC (OSQP)",
                                       _build_inverse_lmpc, ("model", "lmpc", "lmpc_estimator")),
        "nmpc": ControllerSpec("nmpc", "offset-free NMPC, smoothed Maxwell-slip model, inverse warm start",
                               _build_nmpc, NMPC_GROUPS, planner="inverse-lmpc"),
    },
    defaults=_defaults,
    make_plant=lambda c: PamJoint(c["plant"]),
    plant_groups=("plant",),
    output_range=(-45.0, 45.0),
    input_bounds=(-NOMINAL.dp_limit, NOMINAL.dp_limit),
    loop=("angle", "dp_hys", "joint angle [deg]", "Δp_hys [bar]"),
    default_scenario="square-20",
    fixed={
        "plant.sample_period": "the bench samples at 20 ms (vo2012)",
        "model.sample_period": "the bench samples at 20 ms (vo2012)",
        "model.creep_torque": MODEL_ONLY.format("creep (the disturbance estimate takes it up)", "creep_torque"),
        "model.creep_time": MODEL_ONLY.format("creep (the disturbance estimate takes it up)", "creep_time"),
        "model.substeps": "the prediction model integrates with 2 RK4 steps per sample; plant.substeps is the "
                          "plant's",
    } | MULTIPLE_SHOOTING,
)
