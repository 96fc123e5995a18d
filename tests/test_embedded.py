"""The whole controller as CasADi Functions (mpc.embedded) and as generated C (mpc.codegen, experiments.firmware)."""

from dataclasses import replace

import casadi as ca
import numpy as np
import pytest

from hystmpc.experiments.benches import get_bench
from hystmpc.models.base import interp
from hystmpc.mpc.embedded import (
    FunctionController,
    MemoryLayout,
    controller_functions,
    feasible_guess_expr,
    rti_steps_expr,
)
from hystmpc.mpc.rti import feasible_guess, rti_steps
from hystmpc.plants.base import Measurement


def _pam(*assignments):
    bench = get_bench("pam")
    config = bench.configure(["nmpc.solver=rti", *assignments])
    return bench, config


def _python_and_generated(bench_name: str, scenario: str, duration: float, assignments=()):
    """The Python controller's run and its Functions' run (in-process) on the same plant."""
    bench = get_bench(bench_name)
    # as the generated controller is built: the linear MPC planner's QP, dea's creep window where unset
    config = bench.generated_config(bench.configure(["nmpc.solver=rti", "nmpc.runtime=python", *assignments]))
    python = bench.run(scenario, "nmpc", config, duration=duration)
    prepared = bench.prepare(scenario, "nmpc", config)
    functions = FunctionController(prepared.controller, *controller_functions(prepared.controller))
    generated = bench.run(scenario, "nmpc", duration=duration, prepared=replace(prepared, controller=functions))
    return python, generated, functions


@pytest.mark.parametrize(("bench_name", "scenario", "duration", "moves", "assignments"), [
    ("pam", "square-20", 4.0, 1.0, ()),  # the EKF on the whole state, pam's inverse and rest state
    ("pam", "square-20", 4.0, 1.0, ("nmpc.r_input=0.01",)),  # the inverse every sample (u_ff), shifted guesses
    ("compliant", "sine-2", 2.0, 0.05, ()),  # power-function turning points, Newton steps for θ(s)
    # the exact memory without sensors: the parametric hysteresis run exactly on the currents
    # sent (Lambert W as Halley steps), the inverse through the look-up table
    ("reluctance", "reversals-1.75mm", 0.3, 1.0, ()),
    # the exact KP memory, the creep memory over a window, the EKF on the mechanics, single
    # shooting, and the inverse through the creep inverse and the KP bisection
    # (and the EKF's learned gain error of W, which the inverse corrects for)
    ("dea", "square", 3.0, 2.0, ("memory.window=50", "nmpc.inverse_plan=static")),
    # two starts each sample: the RTI steps from the shifted plan and from the inverse, the cheaper plan kept
    ("dea", "single-sine", 1.0, 0.5, ("memory.window=50", "nmpc.multistart=true", "nmpc.r_rate=0.01",
                                      "nmpc.inverse_plan=static")),
    # dea's default: two starts, the second from the linear MPC's plan (its Kalman filter, box QP and KP inverse
    # chain, the same Functions in Python with lmpc.qp=ipm), r_input pulling towards that plan, a window of 200
    ("dea", "square", 1.5, 2.0, ()),
    ("pam", "square-20", 4.0, 1.0, ("nmpc.multistart=true",)),  # the condensed multiple-shooting step's cost
    # the second start only where the first plan tracks worse than 0.5° RMS (after the jumps)
    ("pam", "square-20", 4.0, 1.0, ("nmpc.multistart=true", "nmpc.second_start_error=0.5")),
    # ... with the shifted start at start-up (the second start's inverse also serves the fallback),
    # and with r_input > 0 (the inverse every sample, reused by the second start)
    ("pam", "square-20", 4.0, 1.0, ("nmpc.multistart=true", "nmpc.second_start_error=0.5", "nmpc.warm_start=shift")),
    ("pam", "square-20", 4.0, 1.0, ("nmpc.multistart=true", "nmpc.second_start_error=0.5", "nmpc.r_input=0.01")),
    # ... and none for 3 samples after one that lost
    ("pam", "square-20", 4.0, 1.0, ("nmpc.multistart=true", "nmpc.second_start_error=0.5",
                                    "nmpc.second_start_pause=3")),
])
def test_the_functions_repeat_the_python_controller(bench_name, scenario, duration, moves, assignments):
    python, generated, functions = _python_and_generated(bench_name, scenario, duration, assignments)
    assert np.max(np.abs(python.input - generated.input)) <= 1e-9
    assert np.max(np.abs(python.predicted[1:] - generated.predicted[1:])) <= 1e-9
    assert functions.stats()["failures"] == python.solver["failures"]
    assert np.ptp(generated.input) > moves  # the inputs moved: estimator and memory were exercised
    if bench_name == "reluctance":  # its third RTI step, taken only when the second did not settle
        assert python.solver["iterations_median"] == 2 and python.solver["iterations_max"] == 3
    if "nmpc.multistart=true" in assignments:
        solves = len(python.input) - 1  # the first sample starts from the inverse
        if any(a.startswith("nmpc.second_start_error") for a in assignments):  # some samples solved twice
            assert 0 < python.solver["second_starts"] < solves / 2
        else:  # every sample solved twice, both starts' plans sent
            assert python.solver["second_starts"] == solves
            assert 0 < python.solver["inverse_starts_kept"] < solves


def test_failures_and_lost_estimates_take_the_python_controllers_fallbacks():
    """A NaN sensor restarts the estimate (status 2), a QP that cannot converge is a failure
    (status 1): both send the same finite, bounded input as the Python controller."""
    bench, config = _pam("solver.rti.qp=ipm", "solver.rti.qp_iterations=10")  # 10 IPM iterations often fail
    python = bench.build_controller("nmpc", config)
    functions = FunctionController(python, *controller_functions(python))
    python.reset()
    rng = np.random.default_rng(3)
    window = np.full(python.horizon + 1, 20.0)
    u_py, u_fn = [], []
    for k in range(60):
        angle = 20.0 * (1 - np.exp(-k / 15)) + rng.normal(0, 0.05)
        meas = Measurement(t=0.02 * k, y=np.nan if k == 30 else angle, sensors={"pressure": 2.0 + 0.01 * k})
        u_py.append(python.step(meas, window))
        u_fn.append(functions.step(meas, window))
    # the restart at the NaN sample starts from the NaN sensor, so the next sample restarts again
    assert python.estimator_resets == 2 and functions.statuses.get(2) == 2
    assert python.failures > 1 and functions.stats()["failures"] == python.failures
    assert np.all(np.isfinite(u_fn)) and np.max(np.abs(np.diff(u_fn))) <= python.bounds.rate + 1e-12
    np.testing.assert_allclose(u_fn, u_py, rtol=0, atol=1e-9)


def test_the_rate_feasible_guess_is_the_same_expression():
    u = ca.MX.sym("u", 6)
    f = ca.Function("f", [u], [feasible_guess_expr(u, 0.3, -1.0, 1.0, 0.25)])
    guess = np.array([2.0, -2.0, 0.9, 0.1, -0.5, 0.7])
    np.testing.assert_array_equal(np.asarray(f(guess)).ravel(), feasible_guess(guess, 0.3, -1.0, 1.0, 0.25))


@pytest.mark.parametrize("nan_first", [False, True])
@pytest.mark.parametrize("tolerance", [np.inf, 0.3, 0.2])
def test_the_rti_steps_expressions_repeat_rti_steps(nan_first, tolerance):
    """Steps that halve the distance to 1 (the second moves by 0.25: a third below 0.25),
    optionally with a NaN error on the first: the same iterate, worst error (a NaN stays,
    whether the extra step is taken or not) and failure as the Python loop."""
    w, p = ca.MX.sym("w", 2), ca.MX.sym("p")
    error = ca.if_else(w[0] < 0.1, np.nan, 1e-12) if nan_first else ca.MX(1e-12)
    halve = ca.Function("halve", [w, p], [w + (1.0 - w) / 2, error])
    python_w, python_worst, _ = rti_steps(halve, np.zeros(2), 0.0, 2, tolerance)
    w0 = ca.MX.sym("w0", 2)
    expr = ca.Function("steps", [w0, p], list(rti_steps_expr(halve, w0, p, 2, tolerance)))
    w_out, worst, broken = (np.asarray(v).ravel() for v in expr(np.zeros(2), 0.0))
    assert np.array_equal(w_out, python_w) and float(broken[0]) == 0.0
    assert np.isnan(worst[0]) == np.isnan(python_worst) == nan_first
    assert nan_first or worst[0] == python_worst


def test_memory_layout_packs_the_named_parts_in_order():
    layout = MemoryLayout((("x", 3), ("d", 1), ("P", 16)), horizon=4, initial_values=(("x", (0.0, 1.0, 0.0)),))
    assert layout.size == 3 + 1 + 16 + 1 + 1 + 4 + 1 + 1 + 1 + 1 + 1 + 1
    assert list(layout.initial()[:4]) == [0.0, 1.0, 0.0, 0.0] and not layout.initial()[4:].any()
    mem = ca.MX.sym("mem", layout.size)
    f = ca.Function("f", [mem], [layout.pack(mem, u_last=7.0, plan=ca.DM([1, 2, 3, 4]))])
    out = np.asarray(f(np.zeros(layout.size))).ravel()
    assert out[layout.slices["u_last"]][0] == 7.0 and list(out[layout.slices["plan"]]) == [1, 2, 3, 4]
    with pytest.raises(ValueError, match="unknown memory parts"):
        layout.pack(mem, covariance=0)


def test_controllers_without_a_casadi_form_are_refused_with_the_reason():
    bench = get_bench("dea")
    with pytest.raises(ValueError, match="give the creep sums a window"):  # the whole history: unbounded
        controller_functions(bench.build_controller("nmpc", bench.configure(["nmpc.solver=rti"])))
    with pytest.raises(ValueError, match="lmpc.qp is 'osqp': set lmpc.qp=ipm"):  # the planner's QP, as generated
        controller_functions(bench.build_controller("nmpc", bench.configure(["nmpc.solver=rti", "memory.window=50"])))
    bench, config = _pam()
    numpy_only = bench.build_controller("nmpc", config)
    numpy_only.observer.initial_state = lambda z: np.concatenate(([float(z[0])], np.zeros(numpy_only.model.nx - 1)))
    with pytest.raises(ValueError, match="initial_state does not accept CasADi expressions"):
        controller_functions(numpy_only)
    with pytest.raises(ValueError, match="build the controller with nmpc.solver=rti"):
        controller_functions(bench.build_controller("nmpc", bench.configure()))  # rti-c: a compiled step


def test_symbolic_interp_is_numpys():
    x = ca.SX.sym("x")
    xp, fp = [0.0, 0.5, 2.0, 3.0], [1.0, 2.0, -1.0, 4.0]
    f = ca.Function("f", [x], [interp(x, xp, fp)])
    points = np.array([-1.0, 0.0, 0.2, 0.5, 1.7, 2.0, 2.9999, 3.0, 7.0, np.nan])
    np.testing.assert_array_equal([float(f(v)) for v in points], np.interp(points, xp, fp))


def test_an_exact_memory_with_an_ekf_on_the_dynamics_repeats_the_python_controller():
    """The piezo example (Prandtl–Ishlinskii + second-order dynamics with a sensor): exact
    memory and an EKF on the dynamics, the inverse warm start through the Prandtl–Ishlinskii
    inverse's CasADi form (no search over the plays)."""
    from pathlib import Path

    bench = get_bench(str(Path(__file__).resolve().parents[1] / "docs" / "examples" / "piezo" / "piezo.toml"))
    config = bench.configure(["nmpc.solver=rti", "nmpc.runtime=python"], tuned=False)
    scenario = bench.scenarios[bench.default_scenario]
    prepared = bench.prepare(scenario, "nmpc", config)
    python = prepared.controller
    assert python.inverse is not None and python.observer.ekf is not None and python.observer.split
    functions = FunctionController(python, *controller_functions(python))
    reference = bench.run(scenario, "nmpc", duration=0.5, prepared=prepared)
    generated = bench.run(scenario, "nmpc", duration=0.5, prepared=replace(prepared, controller=functions))
    assert np.max(np.abs(reference.input - generated.input)) <= 1e-9
    assert np.ptp(generated.input) > 0.1


def test_padded_sensitivities_give_the_same_inputs_to_the_last_bit_in_less_memory(monkeypatch):
    """The condensed step's sensitivities as straight-line code (the default), as matrix products
    of their exact widths (past the size limit), and padded with exact zeros
    (solver.rti.sensitivity_block): the closed loop is the same bit for bit, and padding shrinks
    the step's work vector against the exact widths (RAM in C)."""
    from hystmpc.mpc import multiple_shooting
    bench = get_bench("pam")
    runs, work = {}, {}
    for name, block, limit in (("straight", 0, multiple_shooting.STRAIGHT_LINE_CONDENSING_LIMIT),
                               ("products", 0, 0), ("padded", 5, 0)):
        monkeypatch.setattr(multiple_shooting, "STRAIGHT_LINE_CONDENSING_LIMIT", limit)
        config = bench.configure(["nmpc.solver=rti", f"solver.rti.sensitivity_block={block}"])
        prepared = bench.prepare("square-20", "nmpc", config)
        rti = prepared.controller.problem.rti
        assert any(f.name() == "condense" for f in rti.find_functions()) == (name == "straight")
        work[name] = rti.sz_w()
        runs[name] = bench.run("square-20", "nmpc", duration=3.0, prepared=prepared)
    assert np.array_equal(runs["straight"].input, runs["products"].input)
    assert np.array_equal(runs["products"].input, runs["padded"].input)
    assert np.ptp(runs["straight"].input) > 1.0  # a step of the square was tracked
    assert work["padded"] < 0.9 * work["products"], work


@pytest.mark.parametrize(("bench_name", "assignments", "match"), [
    ("pam", ("solver.rti.sensitivity_block=-1",), "sensitivity_block must be >= 0"),
    ("pam", ("solver.rti.sensitivity_block=5", "solver.rti.condensed=false"), "applies to the condensed step only"),
    ("dea", ("solver.rti.sensitivity_block=5",), "needs a multiple-shooting problem"),
])
def test_sensitivity_block_is_refused_where_it_would_not_apply(bench_name, assignments, match):
    bench = get_bench(bench_name)
    with pytest.raises(ValueError, match=match):
        bench.build_controller("nmpc", bench.configure(["nmpc.solver=rti", *assignments]))


def test_the_linear_mpc_plans_failed_qps_are_counted_as_in_python():
    """dea's default (the linear MPC's plan as second start): a NaN displacement restarts both
    estimates from the NaN sensor, the planner's QP fails on it and the next sample, and the
    Functions count those failures (``planner_failures``) and send the Python controller's inputs."""
    bench = get_bench("dea")
    config = bench.generated_config(bench.configure(["nmpc.solver=rti"]))
    python = bench.build_controller("nmpc", config)
    functions = FunctionController(python, *controller_functions(python))
    python.reset()
    u_py, u_fn = [], []
    for k in range(30):
        reference = np.full(python.horizon + 1, 1.0 + 0.002 * k)
        meas = Measurement(t=0.01 * k, y=np.nan if k == 15 else 0.9 + 0.004 * k, sensors={})
        u_py.append(python.step(meas, reference))
        u_fn.append(functions.step(meas, reference))
    assert python.stats()["planner_failures"] >= 1
    assert functions.stats()["planner_failures"] == python.stats()["planner_failures"]
    assert np.all(np.isfinite(u_fn))
    np.testing.assert_allclose(u_fn, u_py, rtol=0, atol=1e-9)
