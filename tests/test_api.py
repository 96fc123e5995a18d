"""The public API at its edges: dead time, no dynamics, bad dynamics, unreachable targets, bad references."""

import numpy as np
import pytest

from hystmpc.experiments import PidController, PidGains, get_bench, inverse_feedforward_pid, simulate
from hystmpc.models import Dynamics, MaxwellSlip, PrandtlIshlinskii, build_prediction_model
from hystmpc.mpc import InputBounds, NmpcController, NmpcSettings
from hystmpc.mpc.observer import Estimate, memory_inverse
from hystmpc.plants import HysteresisActuator

PI = PrandtlIshlinskii(0.5, (0.5, 1.0), (0.3, 0.2))
LAG = Dynamics(("y",), lambda x, u, h, d: [20.0 * (h - x[0])], output=lambda x, h: x[0], steady_input=lambda y: y)


def test_the_inverse_warm_start_accounts_for_the_inputs_still_in_the_dead_time():
    model = build_prediction_model(PI, 0.01, dynamics=LAG, delay_samples=2)
    inverse = memory_inverse(model.memory, model.sample_period)
    state = PI.initial_state(0.0)
    for u in (2.0, 3.0):
        state, _ = PI.step(state, u)
    queue = np.array([3.0, 1.2])
    refs = np.array([2.1, 2.2, 2.3, 2.4, 2.5])
    u = inverse(Estimate(np.zeros(model.nx), np.zeros(1), state, None, queue), refs)
    for applied in (*queue, *u[:3]):
        state, y = PI.step(state, applied)
    assert y == pytest.approx(refs[2 + 2], abs=1e-9)  # u_2 reaches the hysteresis after the two queued inputs


def test_a_measured_hysteresis_without_dynamics_is_tracked_offset_free():
    model = build_prediction_model(PI, 0.01, eps=1e-3)
    assert model.memory is not None and model.memory.n_dynamic == 0
    plant = HysteresisActuator(PrandtlIshlinskii(0.52, (0.5, 1.0), (0.3, 0.2)), 0.01, noise=0.001)
    nmpc = NmpcController(model, InputBounds(-10.0, 10.0), NmpcSettings(horizon=5), sensor_noise=0.001)
    run = simulate(plant, nmpc, lambda t: 2.0 + np.sin(2 * np.pi * t), duration=2.0)
    assert run.solver["failures"] == 0
    assert np.sqrt(np.mean((run.reference - run.output)[100:] ** 2)) < 0.01  # the 4 % gain error is estimated


@pytest.mark.parametrize("rhs, match", [(lambda x, u, h, d: [h - x[0]], "gives 1 entries for 2 states"),
                                        (lambda x, u, h, d: [h, h, h], "gives 3 entries for 2 states")])
def test_dynamics_with_the_wrong_number_of_derivatives_are_refused(rhs, match):
    with pytest.raises(ValueError, match=match):
        build_prediction_model(PI, 0.01, dynamics=Dynamics(("a", "b"), rhs, output=lambda x, h: x[0]))


def test_a_scalar_rhs_serves_a_one_state_model_and_plant():
    dynamics = Dynamics(("y",), lambda x, u, h, d: 20.0 * (h - x[0]), output=lambda x, h: x[0])
    model = build_prediction_model(PI, 0.01, dynamics=dynamics)
    plant = HysteresisActuator(PI, 0.01, dynamics)
    plant.reset(0)
    x = model.step(np.zeros(model.nx), 1.0, 0.0)
    assert float(x[0]) == pytest.approx(plant.step(1.0).y, rel=1e-3)


def test_a_plant_without_sensors_runs_and_bad_noise_names_are_refused():
    plant = HysteresisActuator(PI, 0.01, Dynamics(sensor_names=()))
    assert plant.step(1.0).sensors == {}
    with pytest.raises(ValueError, match=r"noise names sensors \['position'\]"):
        HysteresisActuator(PI, 0.01, LAG, noise={"position": 0.1})


def test_inverse_feedforward_holds_where_the_model_cannot_reach():
    ms = MaxwellSlip(k=(1.0,), w=(1.0,))  # output within (-1, 1)
    plant = HysteresisActuator(ms, 0.01)
    controller = inverse_feedforward_pid(ms, PidGains(ki=1.0), 0.01, (-5.0, 5.0))
    run = simulate(plant, controller, lambda t: 1.5 * np.sin(2 * np.pi * t), duration=1.0)
    assert np.all(np.isfinite(run.input))


def test_references_are_checked_and_a_constant_one_is_fine():
    plant, controller = HysteresisActuator(PI, 0.01), PidController(PidGains(ki=1.0), 0.01, (-5.0, 5.0))
    assert simulate(plant, controller, lambda t: 1.0, duration=0.1).reference.shape == (10,)
    with pytest.raises(ValueError, match="not finite at t = 0.05 s"):
        simulate(plant, controller, np.r_[np.zeros(5), np.nan, np.zeros(4)])


def test_a_bench_scenario_refuses_a_conflicting_condition():
    bench = get_bench("reluctance")
    with pytest.raises(ValueError, match="rig.gap_mm=1.4 conflicts with scenario 'ramp-1.2mm'"):
        bench.prepare("ramp-1.2mm", "poly-inverse", bench.configure(["rig.gap_mm=1.4"]))


def test_a_disturbance_that_enters_nowhere_is_refused():
    with pytest.raises(ValueError, match="rhs never reads d"):
        build_prediction_model(PI, 0.01, dynamics=LAG, disturbance="dynamics")


def test_any_controller_that_reads_nmpc_settings_gets_the_runtime_and_planner_they_ask_for():
    """Bench.build_controller has no name special case: pam's NMPC renamed ``mpc`` still takes
    the plan of its spec's planner with ``inverse_plan=linear-mpc``, without a planner it is
    refused, and ``runtime=c`` with a solver the generated controller lacks is refused by
    the same check the command line runs (Bench.validate)."""
    import dataclasses

    pam = get_bench("pam")
    spec = dataclasses.replace(pam.controllers["nmpc"], name="mpc")
    bench = dataclasses.replace(pam, controllers={"mpc": spec, "inverse-lmpc": pam.controllers["inverse-lmpc"]})
    planned = bench.configure(["nmpc.inverse_plan=linear-mpc"])
    controller = bench.build_controller("mpc", planned)
    assert type(controller.planner).__name__ == "InverseLinearMpc"
    alone = dataclasses.replace(bench, controllers={"mpc": spec})
    with pytest.raises(ValueError, match="takes the plan of the inverse-lmpc baseline, which bench 'pam' lacks"):
        alone.build_controller("mpc", planned)
    unnamed = dataclasses.replace(spec, planner="")
    nameless = dataclasses.replace(bench, controllers={**bench.controllers, "mpc": unnamed})
    with pytest.raises(ValueError, match="controller 'mpc' names none; set nmpc.inverse_plan=static"):
        nameless.build_controller("mpc", planned)
    wrong = bench.configure(["nmpc.runtime=c", "nmpc.solver=ipopt"])
    with pytest.raises(ValueError, match="nmpc.runtime=c runs the generated controller, whose solver is the RTI step"):
        bench.validate(wrong, ["mpc"])
    bench.validate(wrong, ["inverse-lmpc"])  # a controller that reads no NMPC settings is not checked against them
    with pytest.raises(ValueError, match="whose solver is the RTI step"):
        bench.prepare("square-20", "mpc", wrong)  # a Python caller gets the same check
