"""Generic NMPC on the pam bench: prediction model, derivatives, closed loop, offset-free."""

from dataclasses import replace

import casadi as ca
import numpy as np
import pytest

from hystmpc.experiments.benches.pam import BENCH, NOMINAL
from hystmpc.experiments.runner import Scenario
from hystmpc.mpc import NlpSettings, NmpcSettings, SolverSettings
from hystmpc.plants.pam_joint import PamJoint, inverse_inputs, prediction_model


def test_prediction_model_tracks_the_nominal_plant():
    """Same parameters, no noise: the smooth model's open-loop prediction stays close."""
    params = replace(NOMINAL, pressure_noise_bar=0.0, substeps=40)
    model = prediction_model(params, eps=1e-4)
    plant = PamJoint(params)
    plant.reset(0)
    u = 3.0 * np.sin(2 * np.pi * 0.3 * np.arange(300) * params.sample_period)
    xs = model.rollout(np.zeros(model.nx), u, [0.0])
    truth = []
    for uk in u:
        truth.append(plant.step(uk).truth["angle"])
    err = np.abs(xs[1:, 0] - np.asarray(truth))
    assert err.max() < 0.15  # deg, over 6 s open loop, amplitude ~25 deg
    assert err.max() > 0  # the two are different code paths


def test_prediction_model_derivatives_match_finite_differences():
    model = prediction_model(NOMINAL, eps=1e-2)
    x, u, d = ca.SX.sym("x", model.nx), ca.SX.sym("u"), ca.SX.sym("d")
    z = ca.vertcat(x, u, d)
    jac = ca.Function("j", [z], [ca.jacobian(model.step(x, u, d), z)])
    f = ca.Function("f", [z], [model.step(x, u, d)])
    rng = np.random.default_rng(2)
    for _ in range(5):
        point = np.concatenate(([rng.uniform(-30, 30), rng.normal(0, 50), rng.normal(0, 3), rng.normal(0, 10)],
                                rng.uniform(-0.9, 0.9, 4) * np.asarray(NOMINAL.hysteresis.w),
                                rng.normal(0, 3, NOMINAL.delay_samples),
                                [rng.normal(0, 3), rng.normal(0, 0.2)]))
        analytic = np.asarray(jac(point))
        numeric = np.empty_like(analytic)
        for j in range(len(point)):
            h = 1e-6 * max(1.0, abs(point[j]))
            plus, minus = point.copy(), point.copy()
            plus[j] += h
            minus[j] -= h
            numeric[:, j] = (np.asarray(f(plus)).ravel() - np.asarray(f(minus)).ravel()) / (2 * h)
        np.testing.assert_allclose(analytic, numeric, rtol=1e-5, atol=1e-6)


def test_inverse_inputs_follow_a_slow_monotone_reference():
    """Along a slow ramp (no overshoot, so no unplanned reversal) the static inverse
    of eqs. (2)–(3) with the hysteresis path tracks; a step would overshoot, reverse the
    hysteresis and settle elsewhere, which is why the NMPC only uses it as a warm start."""
    model = prediction_model(NOMINAL, eps=1e-4)
    refs = np.concatenate((np.linspace(0.0, 15.0, 400), np.full(200, 15.0)))
    u = inverse_inputs(NOMINAL, np.zeros(model.nx), [0.0], refs)
    xs = model.rollout(np.zeros(model.nx), u, [0.0])
    assert np.max(np.abs(xs[1:, 0] - refs)) < 0.3
    assert xs[-1, 0] == pytest.approx(15.0, abs=0.05)


def test_nmpc_closed_loop_short_scenario_beats_pi_hc():
    scenario = BENCH.scenarios["sine-30"]
    config = BENCH.configure()
    nmpc = BENCH.run(scenario, "nmpc", config, duration=4.0)
    pi_hc = BENCH.run(scenario, "pi-hc", config, duration=4.0)
    assert nmpc.solver["failures"] == 0 and nmpc.solver["fallbacks"] == 0
    assert np.all(np.isfinite(nmpc.input)) and np.all(np.isfinite(nmpc.output))
    assert np.all(np.abs(nmpc.input) <= NOMINAL.dp_limit)
    du = np.abs(np.diff(nmpc.input))
    assert du.max() <= NOMINAL.pressure_slew * NOMINAL.sample_period + 1e-9
    assert nmpc.metrics["rmse"] <= 0.5 * pi_hc.metrics["rmse"]


def test_nmpc_is_offset_free_under_constant_model_mismatch():
    """A constant torque the model does not know (and +10 % payload) leaves no offset."""
    config = BENCH.configure()
    config["plant"] = replace(NOMINAL, pressure_noise_bar=0.0, creep_torque=0.4, creep_time=0.02,
                              payload_kg=1.1)
    config["nmpc"] = replace(config["nmpc"], horizon=10)
    scenario = Scenario("hold-12", "constant 12 deg", 6.0, lambda t: np.full_like(np.asarray(t, float), 12.0))
    run = BENCH.run(scenario, "nmpc", config)
    quantum = 360.0 / NOMINAL.encoder_counts
    tail = run.reference[-50:] - run.output[-50:]
    assert abs(tail.mean()) <= quantum
    assert run.solver["failures"] == 0


def test_failed_solve_falls_back_and_is_counted():
    """One iteration per sample cannot converge: every step falls back, none sends NaN."""
    config = BENCH.configure()
    config["nmpc"] = NmpcSettings(horizon=5, solver="ipopt")
    config["solver"] = SolverSettings(ipopt=NlpSettings(max_iter=1))
    run = BENCH.run("square-10", "nmpc", config, duration=0.5)
    assert run.solver["failures"] > 0
    assert run.solver["fallbacks"] == run.solver["failures"]
    assert np.all(np.isfinite(run.input))


@pytest.mark.parametrize("change, match", [
    ({"horizon": 1}, "horizon must be >= 2"),
    ({"solver": "nosuch"}, "allowed: ipopt, sqp"),
    ({"warm_start": "hot"}, "allowed: inverse, shift, cold"),
    ({"q_output": 0.0}, "q_output must be finite and > 0"),
    ({"second_start_pause": -1}, "second_start_pause must be >= 0"),
])
def test_settings_validation(change, match):
    with pytest.raises(ValueError, match=match):
        NmpcSettings(**change)


def test_extra_disturbances_reach_the_dynamics_only():
    """``Dynamics.disturbances`` > 1 gives ``rhs`` a vector ``d`` (and the model ``nd``
    entries); other places for ``d``, or a count below 1, are refused."""
    from hystmpc.models.maxwell_slip import MaxwellSlip
    from hystmpc.models.prediction import Dynamics, build_prediction_model
    hysteresis = MaxwellSlip(k=(1.0,), w=(0.5,))
    dynamics = Dynamics(state_names=("v",), rhs=lambda x, u, h, d: [-x[0] + h * (1 + d[1]) + d[0]], disturbances=2)
    model = build_prediction_model(hysteresis, 0.01, dynamics=dynamics, disturbance="dynamics")
    assert model.nd == 2
    x = np.zeros(model.nx)
    assert not np.allclose(np.asarray(model.step(x, 0.3, [0.0, 0.5])), np.asarray(model.step(x, 0.3, [0.0, 0.0])))
    lazy = Dynamics(state_names=("v",), rhs=lambda x, u, h, d: [-x[0] + h + d[0]], disturbances=2)
    with pytest.raises(ValueError, match=r"never reads d\[1\] of its 2 disturbances"):
        build_prediction_model(hysteresis, 0.01, dynamics=lazy, disturbance="dynamics")
    with pytest.raises(ValueError, match="2 disturbances need disturbance='dynamics'"):
        build_prediction_model(hysteresis, 0.01, dynamics=dynamics, disturbance="output")
    for bad in (0, 1.5, True):
        with pytest.raises(ValueError, match="disturbances must be an integer >= 1"):
            Dynamics(state_names=("v",), rhs=lambda x, u, h, d: [x[0]], disturbances=bad)


def test_the_second_start_waits_for_a_plan_that_costs_more_and_ends_off():
    """Off: a failed plan; else, unless paused, one that costs more than ``q·N·e²`` and ends
    further than ``e`` from the reference (a NaN counts as over)."""
    from hystmpc.mpc.controller import NmpcController
    from hystmpc.mpc.problem import Solution

    settings = NmpcSettings(horizon=10, q_output=4.0, multistart=True, second_start_error=0.5)
    judge = NmpcController.__new__(NmpcController)  # the test reads the settings alone
    judge.settings = settings
    limit = 4.0 * 10 * 0.5 ** 2

    def off(success=True, cost=2 * limit, end=1.0, paused=False):
        plan = Solution(u_plan=np.zeros((10, 1)), x_plan=None, success=success, status="", iterations=1,
                        solve_time=0.0, cost=cost, end_error=end)
        return judge._plan_is_off(plan, paused)

    assert off() and off(end=-1.0) and off(cost=np.nan) and off(end=np.nan)
    assert not off(cost=limit) and not off(end=0.5) and not off(end=-0.4)  # costs little, or ends on
    assert not off(paused=True) and off(success=False, paused=True, cost=0.0, end=0.0)
    judge.settings = replace(settings, second_start_error=0.0)
    assert off(cost=0.0, end=0.0, paused=True)  # 0: every sample
