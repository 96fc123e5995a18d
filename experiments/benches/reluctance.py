"""Bench ``reluctance``: current-driven reluctance actuator linearisation (katalenic2013).

Force is not measured in operation: all three controllers are feed-forward and use the
model identified from simulated, noisy major-loop measurements (Section 3.5), never the
plant's true parameters.

* ``poly-inverse``: one single-valued 4th-order polynomial i(√F, g) over all air gaps,
  fitted to both branches of the identification data (√F since F ∝ i²; ref. [2] of the paper);
* ``hyst-inverse``: i = IH[Lut(F_ref, g)] (eq. (12a), Fig. 10), its command rate-limited to
  the amplifier's slew limit;

Both inverses command the force wanted at the next sample, when their current takes effect.
* ``inverse-lmpc``: the inverse of eq. (12a) in series with the current (its memory follows
  the currents sent), and a linear MPC on what remains: the force one sample after the
  command, with the NMPC's horizon, current bounds, slew limit and preview;
* ``nmpc``: currents over a horizon within the current bounds and slew limit, predicting
  F = Lut⁻¹(H[i], g) (eq. (12b)) with the smooth H.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from hystmpc.experiments.baselines import HystInverse, InverseCompensation, PolyInverse
from hystmpc.experiments.bench import MULTIPLE_SHOOTING, Bench, ControllerSpec
from hystmpc.experiments.benches.reluctance_identification import (
    IdentificationSettings,
    RigSettings,
    identified_model,
    rig,
)
from hystmpc.experiments.runner import Scenario
from hystmpc.experiments.signals import smooth_path, staircase
from hystmpc.models.prediction import Smoothing
from hystmpc.models.reluctance import prediction_model
from hystmpc.mpc import InputBounds, NmpcController, NmpcSettings, RtiSettings, SolverSettings
from hystmpc.mpc.linear_mpc import InverseLinearMpc, LinearMpcSettings, one_sample_delay
from hystmpc.plants.reluctance import C_CORE, ReluctanceActuator, ReluctanceParams


@dataclass(frozen=True)
class ForceTableSettings:
    """How the NMPC's model reads force off the identified table, F = Lut⁻¹(X, g) (eq. (12b))."""

    kink_eps: float = 0.0
    """Width (A, in H's output X) over which each kink of the table's polyline is rounded;
    0: the polyline itself, found by binary search. Rounded, its ~100 kinks cost one
    square root each, a large share of the C controller's step (docs/reluctance.md)."""

    def __post_init__(self):
        if not (np.isfinite(self.kink_eps) and self.kink_eps >= 0):
            raise ValueError(f"kink_eps must be finite and >= 0 (0: the exact polyline), got {self.kink_eps}")


def _build(kind: str, config: dict):
    """``poly-inverse``, ``hyst-inverse``, ``lmpc`` or ``nmpc`` on the identified model of the configured rig."""
    plant, gap, _ = rig(config)
    model = identified_model(config)
    slew = plant.slew_limit * plant.sample_period
    if kind == "poly":
        return PolyInverse(model, gap, plant.current_limit)
    if kind == "hyst":
        return HystInverse(model, gap, plant.current_limit, slew)
    if kind == "lmpc":
        compensation = InverseCompensation(
            model.operator(gap), sensors=lambda m, comp: [],
            virtual_of=lambda x: float(model.force_of_x(x, gap)),
            hysteresis_output_of=lambda f: float(model.x_of_force(max(f, 0.0), gap)))
        return InverseLinearMpc(one_sample_delay(plant.sample_period), compensation,
                                InputBounds(0.0, plant.current_limit, slew), config["lmpc"], process_noise=[0.0],
                                measurement_noise=[], initial_state=lambda z: np.zeros(1), initial_covariance=[0.0])
    smoothing: Smoothing = config["smoothing"]
    pm = prediction_model(model, gap, plant.sample_period, smoothing.eps, smoothing.direction,
                          kink_eps=config["table"].kink_eps)
    # feed-forward: the exact H, run on the currents sent, re-anchors the smooth prediction every sample
    return NmpcController(pm, InputBounds(0.0, plant.current_limit, slew), config["nmpc"], config["solver"],
                          jump_threshold=20.0)


def _scenarios() -> dict[str, Scenario]:
    out = [Scenario(f"ramp-{gap:g}mm", f"E-core, {gap:g} mm: 0 → 400 N → 0 in 8 s (Fig. 11)", 8.0,
                    smooth_path([0.0, 400.0, 0.0], 4.0), (f"rig.gap_mm={gap}", "rig.core=E"))
           for gap in (1.2, 1.3, 1.5, 1.7)]
    out.append(Scenario("reversals-1.75mm", "E-core, 1.75 mm: non-periodic, higher-order reversal curves (Fig. 13)",
                        8.0, smooth_path([0, 350, 100, 300, 150, 250, 50, 400, 0], 1.0),
                        ("rig.gap_mm=1.75", "rig.core=E")))
    out.append(Scenario("ccore-ramp-1.5mm", "C-core, 1.5 mm: 0 → 240 N → 0 in 8 s (Fig. 12)", 8.0,
                        smooth_path([0.0, 240.0, 0.0], 4.0), ("rig.gap_mm=1.5", "rig.core=C")))
    out.append(Scenario("steps-1.5mm", "E-core, 1.5 mm: force steps every 0.1 s; the slew limit binds", 0.7,
                        staircase([50, 250, 100, 350, 150, 300, 50], 0.1), ("rig.gap_mm=1.5", "rig.core=E")))
    return {s.name: s for s in out}


def _defaults() -> dict:
    return {"rig": RigSettings(), "ecore": ReluctanceParams(), "ccore": C_CORE,
            "identification": IdentificationSettings(),
            # rti-c: no failed solve (sqp failed 15-76 times per run) and every perturbed
            # actuator's steps won. The exact table and 2 steps per sample (not the rounded
            # table and 3) fit the 5 kHz period in C; the 'descent' line search brings the C
            # controller's median step from 30 % to 21 % of the period. It runs as C ('auto'):
            # in Python the controller takes more than the whole period. A third step on the
            # 0.5-1.4 % of samples whose second step still moved the plan by over 1 uA gives
            # back what 'descent' cost on ramp-1.3mm (docs/reluctance.md)
            "nmpc": NmpcSettings(horizon=16, q_output=1.0, r_rate=1.0, solver="rti-c", runtime="auto"),
            "lmpc": LinearMpcSettings(horizon=16, q_output=1.0, r_rate=1e-6),
            "smoothing": Smoothing(eps=1e-5), "table": ForceTableSettings(),
            "solver": SolverSettings(rti=RtiSettings(iterations=2, extra_step_tolerance=1e-6,
                                                     line_search="descent")).uniform(max_iter=50)}


IDENTIFIED = ("rig", "ecore", "ccore", "identification")
SAMPLED = "the bench samples at 5 kHz (katalenic2013)"

BENCH = Bench(
    name="reluctance",
    description="Current-driven reluctance actuator, parametric (Lambert W) hysteresis (katalenic2013)",
    paper="katalenic2013_reluctance_actuator_hysteresis_linearization",
    output_name="force",
    units="N",
    input_units="A",
    sample_period=ReluctanceParams().sample_period,
    scenarios=_scenarios(),
    controllers={
        "poly-inverse": ControllerSpec("poly-inverse", "single-valued 4th-order polynomial inverse",
                                       functools.partial(_build, "poly"), IDENTIFIED),
        "hyst-inverse": ControllerSpec("hyst-inverse", "IH[Lut(F, g)], eq. (12a), Fig. 10",
                                       functools.partial(_build, "hyst"), IDENTIFIED),
        "inverse-lmpc": ControllerSpec("inverse-lmpc", "IH[Lut(F, g)] + linear MPC (OSQP) with the slew limit",
                                       functools.partial(_build, "lmpc"), (*IDENTIFIED, "lmpc")),
        "nmpc": ControllerSpec("nmpc", "feed-forward NMPC: currents over a horizon, slew limit, F = Lut⁻¹(H[i])",
                               functools.partial(_build, "nmpc"), (*IDENTIFIED, "nmpc", "smoothing", "table", "solver"),
                               planner="inverse-lmpc"),
    },
    defaults=_defaults,
    make_plant=lambda c: ReluctanceActuator(rig(c)[0], rig(c)[1]),
    plant_groups=("rig", "ecore", "ccore"),
    output_range=(0.0, 450.0),
    input_bounds=(0.0, ReluctanceParams().current_limit),
    loop=("current", "force", "current [A]", "force [N]"),
    default_scenario="ramp-1.5mm",
    error_vs_reference=True,
    fixed={"ecore.sample_period": SAMPLED, "ccore.sample_period": SAMPLED} | MULTIPLE_SHOOTING,
)
