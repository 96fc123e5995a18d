"""Bench dea (wang2025): plant, the NMPC's split GL prediction, every controller briefly; full comparison (slow)."""

from dataclasses import replace

import numpy as np
import pytest

from hystmpc.experiments.benches.dea import BENCH, NOMINAL, PAPER_TABLE_2
from hystmpc.models.fckp import Fckp
from hystmpc.plants.dea import DeaActuator, prediction_model


def test_constant_voltage_creeps_upwards_and_settles_near_w():
    plant = DeaActuator(replace(NOMINAL, noise=0.0))
    plant.reset(0)
    ys, ws = [], []
    for _ in range(2000):
        m = plant.step(2.5)
        ys.append(m.y)
        ws.append(m.truth["W"])
    assert np.all(np.diff(ws[10:]) > 0)  # creep: W keeps rising under a constant input
    assert ys[-1] == pytest.approx(ws[-1], rel=0.03)  # x1 ≈ W at rest (g ≈ −f/x1)
    with pytest.raises(ValueError, match="finite"):
        plant.step(float("nan"))


def test_prediction_with_history_terms_matches_the_exact_model():
    """The NLP's prediction (smooth KP, in-horizon GL terms + history parameter, RK4) follows
    the exact nominal model with full creep memory over the horizon."""
    model = replace(NOMINAL, noise=0.0, disturbance=0.0)
    N = 15
    predict = prediction_model(model, eps=1e-4, direction_eps=1e-5).horizon_function(N)
    plant = DeaActuator(model)
    plant.reset(0)
    t = 0.01 * np.arange(400 + N)
    u = 2.5 + 1.0 * np.sin(2 * np.pi * 0.7 * t) + 0.3 * np.sin(2 * np.pi * 2.3 * t)
    for k in range(400):
        plant.step(u[k])
    x = plant._x.copy()
    params = np.concatenate((plant._kp, x, [0.0], plant._creep.history_terms(N)))
    y_pred = np.asarray(predict(params, u[400:400 + N])).ravel()
    y_true = np.array([plant.step(v).y for v in u[400:400 + N]])
    assert np.max(np.abs(y_pred - y_true)) < 2e-3


def test_forward_sensitivities_give_the_symbolic_jacobian_of_the_prediction():
    """The RTI step's small-code linearisation (sensitivities carried through the KP state,
    the GL sum and the membrane) equals CasADi's Jacobian of the unrolled prediction."""
    import casadi as ca
    N = 15
    model = prediction_model(replace(NOMINAL, noise=0.0), eps=1e-4, direction_eps=1e-5)
    predict, compact, jacobian = model.horizon_function(N), model.horizon_function(N, inline=False), \
        model.horizon_jacobian(N)
    rng = np.random.default_rng(0)
    U_sym = ca.SX.sym("U", N)
    for _ in range(5):
        params = np.concatenate((rng.uniform(-0.5, 0.5, len(model.hysteresis.state_names)), rng.normal(size=2) * 0.1,
                                 [0.01], rng.normal(size=N) * 0.1))
        U = rng.uniform(1.0, 5.0, N)
        symbolic = np.asarray(ca.Function("j", [U_sym], [ca.jacobian(predict(params, U_sym), U_sym)])(U))
        y, dy = (np.asarray(v) for v in jacobian(params, U))
        assert np.max(np.abs(dy - symbolic)) <= 1e-10 * (1 + np.max(np.abs(symbolic)))
        assert np.max(np.abs(dy[np.triu_indices(N, 1)])) == 0.0  # causal
        assert np.array_equal(y, np.asarray(predict(params, U)))
        assert np.array_equal(np.asarray(compact(params, U)), y)


@pytest.mark.parametrize("controller", ["pid", "backstepping", "bic", "linear-mpc", "nmpc"])
def test_every_controller_runs_within_the_input_range(controller):
    run = BENCH.run(BENCH.scenarios["single-sine"], controller, BENCH.configure(), duration=3.0)
    assert np.all(np.isfinite(run.input)) and np.all(np.isfinite(run.output))
    assert run.input.min() >= 0.0 and run.input.max() <= 10.0


def test_nmpc_beats_pid_without_failures_on_a_short_run():
    config = BENCH.configure()
    nmpc = BENCH.run(BENCH.scenarios["single-sine"], "nmpc", config, duration=4.0)
    pid = BENCH.run(BENCH.scenarios["single-sine"], "pid", config, duration=4.0)
    assert nmpc.solver["failures"] == 0
    assert nmpc.metrics["rmse"] < 0.2 * pid.metrics["rmse"]


def test_multistart_keeps_the_lower_cost_plan_of_the_two_starts():
    """``nmpc.multistart``: each sample solves from the shifted plan and from the inverse
    model's inputs and sends the first input of the plan with the lower cost; it needs gn
    or the RTI step, whose costs it compares."""
    config = BENCH.configure(["nmpc.multistart=true", "nmpc.r_rate=0.01"])
    prepared = BENCH.prepare("single-sine", "nmpc", config)
    controller, problem = prepared.controller, prepared.controller.problem
    solve, pairs = problem.solve, []

    def recording_solve(condition, u_prev, ref, u_guess, x_guess=None, u_ff=None):
        solution = solve(condition, u_prev, ref, u_guess, x_guess, u_ff=u_ff)
        if len(pairs) < 20:  # the cost it reports is the cost at its plan
            residual = np.asarray(problem._gn_eval(solution.u_plan.ravel(),
                                                   problem._parameters(condition, u_prev, ref, u_ff))[0]).ravel()
            assert solution.cost == pytest.approx(float(residual @ residual), rel=1e-12)
        pairs.append(solution)
        return solution
    problem.solve = recording_solve
    run = BENCH.run("single-sine", "nmpc", config, duration=1.0, prepared=prepared)
    assert run.solver["failures"] == 0 and 0 < run.solver["inverse_starts_kept"] < len(run.input)
    # the first sample starts from the inverse (no plan yet): one solve; then two per sample
    assert len(pairs) == 2 * len(run.input) - 1
    for k in range(1, len(run.input)):
        shifted, inverse = pairs[2 * k - 1], pairs[2 * k]
        best = inverse if inverse.cost < shifted.cost else shifted
        assert run.input[k] == controller.bounds.clip(float(best.u_plan[0, 0]), float(run.input[k - 1]))
    with pytest.raises(ValueError, match="solver gn or the RTI step reports.*'ipopt'.*set nmpc.multistart=false"):
        BENCH.build_controller("nmpc", BENCH.configure(["nmpc.solver=ipopt"]))  # two starts: dea's default
    # a shifted start from the first sample on: the inverse start runs every sample
    shift = BENCH.configure(["nmpc.multistart=true", "nmpc.warm_start=shift"])
    prepared = BENCH.prepare("single-sine", "nmpc", shift)
    solve, calls = prepared.controller.problem.solve, []
    prepared.controller.problem.solve = lambda *a, **k: calls.append(1) or solve(*a, **k)
    run = BENCH.run("single-sine", "nmpc", shift, duration=0.2, prepared=prepared)
    assert len(calls) == 2 * len(run.input)


def test_multistart_with_the_rti_step_reports_the_cost_of_its_plan():
    """With ``nmpc.solver=rti`` the RTI step's cost Function picks the plan (the same
    operations run in the generated controller, test_embedded)."""
    config = BENCH.configure(["nmpc.solver=rti", "memory.window=50"])
    prepared = BENCH.prepare("single-sine", "nmpc", config)
    problem, solve, checked = prepared.controller.problem, prepared.controller.problem.solve, []

    def recording_solve(condition, u_prev, ref, u_guess, x_guess=None, u_ff=None):
        solution = solve(condition, u_prev, ref, u_guess, x_guess, u_ff=u_ff)
        p = problem._parameters(condition, u_prev, ref, u_guess if u_ff is None else u_ff)
        assert solution.cost == float(problem.rti_cost(solution.u_plan.ravel(), p))
        checked.append(solution.cost)
        return solution
    problem.solve = recording_solve
    run = BENCH.run("single-sine", "nmpc", config, duration=0.5, prepared=prepared)
    assert run.solver["failures"] == 0 and 0 < run.solver["inverse_starts_kept"] < len(run.input)
    assert len(checked) == 2 * len(run.input) - 1 and np.all(np.isfinite(checked))


def test_window_changes_only_the_controllers_memory():
    config = BENCH.configure()
    from hystmpc.experiments.config import apply_overrides
    short = apply_overrides(config, ["memory.window=50"])
    assert short["memory"].length == 50 and config["memory"].length is None
    with pytest.raises(ValueError, match="window"):
        apply_overrides(config, ["memory.window=-1"])
    assert Fckp(NOMINAL.fckp).creep(50).window == 50


@pytest.mark.slow
def test_full_comparison_orderings_and_nmpc():
    """Issue 5, items 2–3 as far as they hold (see docs/dea.md for the calibration gap)."""
    config = BENCH.configure()
    rmse = {}
    for scenario in BENCH.scenarios:
        for controller in BENCH.controllers:
            run = BENCH.run(BENCH.scenarios[scenario], controller, config)
            assert np.all(np.isfinite(run.input)) and np.all(np.isfinite(run.output))
            if controller == "nmpc":
                assert run.solver["fallbacks"] == 0, scenario
            rmse[scenario, controller] = run.metrics["rmse"]
    ss = {c: rmse["single-sine", c] for c in BENCH.controllers}
    assert ss["bic"] < ss["backstepping"] < ss["pid"] and ss["linear-mpc"] < ss["pid"]
    assert ss["bic"] <= 3 * PAPER_TABLE_2["bic"][1]
    for scenario in ("single-sine", "composite"):
        assert rmse[scenario, "nmpc"] <= 0.5 * rmse[scenario, "bic"]
    papers = [c for c in BENCH.controllers if c != "inverse-lmpc"]
    for scenario in BENCH.scenarios:
        assert rmse[scenario, "nmpc"] == min(rmse[scenario, c] for c in papers), scenario
        # the exact FCKP inverse + linear MPC: beaten on composite, 1.15-1.34x better on the
        # other three (docs/dea.md); one start per sample was 1.4-4x behind it everywhere
        assert rmse[scenario, "nmpc"] < 1.5 * rmse[scenario, "inverse-lmpc"], scenario
    assert rmse["composite", "nmpc"] < rmse["composite", "inverse-lmpc"]


@pytest.mark.slow
def test_the_plants_creep_causes_almost_none_of_bics_error_on_composite():
    """Why Table 3 (creep compensation: 0.0235 -> 0.0133 mm) cannot be reproduced: even a
    creep-free plant leaves bic's RMSE within a few per cent of what it is with creep."""
    from hystmpc.experiments.config import apply_overrides
    config = BENCH.configure()
    with_creep = BENCH.run(BENCH.scenarios["composite"], "bic", config).metrics["rmse"]
    creep_free = apply_overrides(config, ["plant.fckp.creep_order=0"])
    without_creep = BENCH.run(BENCH.scenarios["composite"], "bic", creep_free).metrics["rmse"]
    assert abs(with_creep - without_creep) < 0.05 * with_creep  # Table 3 is a 43 % cut


def test_gn_compiled_gives_the_in_process_numbers_to_the_last_bit(monkeypatch, caplog):
    """gn compiles its residual and Jacobian; without a compiler it evaluates them in-process,
    after a notice, and the numbers are the same bit for bit (so are the closed loops)."""
    from hystmpc.mpc.codegen import CompilerNotFound, toolchain
    compiled = BENCH.build_controller("nmpc", BENCH.configure()).problem

    def no_compiler(*_, **__):
        raise CompilerNotFound("no C compiler found (test)")

    monkeypatch.setattr(toolchain, "compile_function", no_compiler)
    in_process = BENCH.build_controller("nmpc", BENCH.configure()).problem
    assert "evaluates its residual and Jacobian in-process" in caplog.text
    rng = np.random.default_rng(1)
    n_p = compiled._gn_eval.size1_in(1)
    for _ in range(5):
        u, p = rng.uniform(1.0, 6.0, compiled.horizon), rng.normal(size=n_p) * 0.1
        for a, b in zip(compiled._gn_eval(u, p), in_process._gn_eval(u, p), strict=True):
            assert np.array_equal(np.asarray(a), np.asarray(b))
        # the line search's residual-only Function gives the full evaluation's residual, bit for bit
        for problem in (compiled, in_process):
            assert np.array_equal(np.asarray(problem._gn_residual(u, p)), np.asarray(problem._gn_eval(u, p)[0]))


def test_rti_step_from_small_parts_equals_the_unrolled_one():
    from hystmpc.mpc.single_shooting import SingleShootingProblem
    controller = BENCH.build_controller("nmpc", BENCH.configure(["nmpc.solver=rti"]))
    small = controller.problem
    unrolled = SingleShootingProblem(small.predict, small.settings, controller.bounds, small.solvers)
    rng = np.random.default_rng(2)
    n_p = small.rti.size1_in(1)
    for _ in range(5):
        w, p = rng.uniform(1.0, 6.0, small.horizon), rng.normal(size=n_p) * 0.1
        a, b = (np.asarray(f(w, p)[0]) for f in (small.rti, unrolled.rti))
        assert np.max(np.abs(a - b)) <= 1e-9


def test_the_estimator_learns_a_shorter_stroke():
    """Only the stroke is off (85 % of the model's): the EKF's relative gain error of W
    settles near −15 %, and the offset stays small."""
    truth = replace(NOMINAL, fckp=replace(NOMINAL.fckp, stroke=0.85 * NOMINAL.fckp.stroke))
    config = {**BENCH.configure(), "plant": truth}
    prepared = BENCH.prepare("single-sine", "nmpc", config)
    BENCH.run("single-sine", "nmpc", config, duration=12.0, prepared=prepared)
    offset, gain = prepared.controller.observer.estimate(15).d
    assert abs(gain + 0.15) < 0.03, gain
    assert abs(offset) < 0.05, offset
    without = BENCH.configure(["estimator.gain=0"])
    assert len(BENCH.build_controller("nmpc", without).observer.estimate(15).d) == 1  # the offset alone
    with pytest.raises(ValueError, match="initial=0.1 applies to the learned gain error, but gain is 0"):
        BENCH.configure(["estimator.gain=0", "estimator.initial=0.1"])


def test_the_inverse_warm_start_corrects_for_the_learned_offset_and_gain():
    """With ``d = [offset, e]`` the static inverse aims at (W − offset) / (1 + e): with e = 0
    it is the offset-only model's inverse, and NumPy and CasADi give the same inputs."""
    import casadi as ca

    from hystmpc.mpc.observer import Estimate, memory_inverse
    learned = prediction_model(NOMINAL, 1e-4, 3e-5, learn_gain=True)
    offset_only = prediction_model(NOMINAL, 1e-4, 3e-5)
    fckp = Fckp(NOMINAL.fckp)
    state = fckp.step(fckp.step(fckp.initial_state(), 6.0)[0], 4.5)[0]  # a memory with a reversal
    refs = 1.0 + 0.1 * np.sin(np.arange(15) / 3)
    history = np.full(15, 0.02)

    def inverse(model, d):
        est = Estimate(np.array([1.0, 0.0]), np.asarray(d, float), state, history)
        return memory_inverse(model.memory, NOMINAL.sample_period)(est, refs)
    assert np.allclose(inverse(learned, [0.03, 0.0]), inverse(offset_only, [0.03]), atol=1e-9)
    corrected, plain = inverse(learned, [0.03, 0.2]), inverse(learned, [0.03, 0.0])
    assert np.all(np.isfinite(corrected)) and np.max(np.abs(corrected - plain)) > 0.1  # a 20 % gain moves it
    sym = [ca.MX.sym(n, k) for n, k in (("x", 2), ("d", 2), ("h", len(state)), ("hist", 15))]
    inverse_fn = memory_inverse(learned.memory, NOMINAL.sample_period)
    out = inverse_fn(Estimate(*sym), ca.DM(refs))
    value = ca.Function("inv", sym, [out])([1.0, 0.0], [0.03, 0.2], state, history)
    assert np.allclose(np.asarray(value).ravel(), corrected, atol=1e-9)
