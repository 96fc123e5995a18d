"""The interior-point QP of mpc.qp and DAQP against OSQP, and the qrqp failure they replace."""

import casadi as ca
import numpy as np
import osqp
import pytest
import scipy.sparse as sp

from hystmpc.mpc.codegen import CompilerNotFound, c_compiler, compile_function
from hystmpc.mpc.qp import interior_point_qp
from hystmpc.mpc.rti import gauss_newton_step, rti_steps

N = 10
RATES = np.eye(N) - np.eye(N, k=-1)
C = np.vstack((np.eye(N), RATES))
C_SPARSITY = ca.sparsify(ca.DM(C)).sparsity()


def _osqp(H, g, l, u):
    solver = osqp.OSQP()
    solver.setup(sp.csc_matrix(np.triu(H)), g, sp.csc_matrix(C), l, u, eps_abs=1e-11, eps_rel=1e-11,
                 max_iter=200000, polishing=True, verbose=False)
    return solver.solve(raise_error=True).x


def _random_problem(rng):
    """A dense, badly scaled convex QP with shifted input bounds and rate bounds."""
    M = rng.normal(size=(N + 5, N)) * 10 ** rng.uniform(-2, 3)
    H = M.T @ M + 1e-8 * np.eye(N)
    g = rng.normal(size=N) * 5 * 10 ** rng.uniform(-2, 3)
    du, shift = 0.15 * 10 ** rng.uniform(-2, 1), rng.uniform(-0.5, 0.5, N)
    return H, g, np.r_[-1 - shift, -du * np.ones(N)], np.r_[1 - shift, du * np.ones(N)], du


def test_interior_point_qp_matches_osqp_on_random_badly_scaled_problems():
    qp = interior_point_qp(ca.Sparsity.dense(N, N), C_SPARSITY)
    rng = np.random.default_rng(0)
    for _ in range(100):
        H, g, l, u, du = _random_problem(rng)
        x, residual, _ = qp(H, g, C, l, u)
        assert float(residual) <= 1e-6
        assert np.max(np.abs(np.asarray(x).ravel() - _osqp(H, g, l, u))) <= 1e-5 * du


def test_a_small_residual_means_a_near_optimal_cost_even_with_few_iterations():
    """The residual is what the RTI step uses to count a failed solve: below the tolerance the
    cost must be near the optimum (here with 10 iterations, where many solves are not)."""
    qp = interior_point_qp(ca.Sparsity.dense(N, N), C_SPARSITY, iterations=10)
    rng = np.random.default_rng(0)
    flagged = 0
    for _ in range(50):
        H, g, l, u, _ = _random_problem(rng)
        x, residual, _ = qp(H, g, C, l, u)
        x, best = np.asarray(x).ravel(), _osqp(H, g, l, u)
        cost, best_cost = 0.5 * x @ H @ x + g @ x, 0.5 * best @ H @ best + g @ best
        if float(residual) <= 1e-6:
            assert np.all(C @ x >= l - 1e-9) and np.all(C @ x <= u + 1e-9)
            assert cost - best_cost <= 1e-4 * abs(best_cost)
        else:
            flagged += 1
    assert flagged > 0  # 10 iterations are too few for some of these problems, and it shows


def test_early_exit_gives_the_fixed_iteration_answer():
    """Skipping the iterations after convergence must not move the answer."""
    early = interior_point_qp(ca.Sparsity.dense(N, N), C_SPARSITY)
    fixed = interior_point_qp(ca.Sparsity.dense(N, N), C_SPARSITY, early_exit=False)
    rng = np.random.default_rng(1)
    for _ in range(100):
        H, g, l, u, du = _random_problem(rng)
        x_early, residual, _ = early(H, g, C, l, u)
        assert float(residual) <= 1e-6
        assert np.max(np.abs(np.asarray(x_early) - np.asarray(fixed(H, g, C, l, u)[0]))) <= 1e-7 * du


def test_compiled_interior_point_qp_equals_the_in_process_one(tmp_path):
    qp = interior_point_qp(ca.Sparsity.dense(N, N), C_SPARSITY)
    compiled = compile_function(qp, tmp_path)
    H, g, l, u, _ = _random_problem(np.random.default_rng(3))
    assert np.max(np.abs(np.asarray(compiled(H, g, C, l, u)[0]) - np.asarray(qp(H, g, C, l, u)[0]))) <= 1e-12


def test_cc_may_carry_a_launcher_and_is_part_of_the_cache_key(tmp_path, monkeypatch):
    x = ca.SX.sym("x")
    fun = ca.Function("twice", [x], [2 * x])
    monkeypatch.setenv("CC", "env cc")  # as "ccache gcc" would: a launcher, then the compiler
    assert c_compiler()[1:] == ["cc"]
    assert float(compile_function(fun, tmp_path)(1.5)) == 3.0
    monkeypatch.setenv("CC", "cc")
    compile_function(fun, tmp_path)
    assert len(list(tmp_path.glob("twice_*"))) == 2
    monkeypatch.setenv("CC", "no-such-compiler-here")
    assert c_compiler() is None
    with pytest.raises(CompilerNotFound, match="no-such-compiler-here"):
        compile_function(ca.Function("thrice", [x], [3 * x]), tmp_path)


def test_qrqp_still_gets_a_small_rate_bounded_qp_wrong():
    """Why mpc.qp exists (CasADi 3.8): qrqp reports success on this feasible QP while violating
    its rate bounds. If this starts failing, qrqp was fixed and the choice can be revisited."""
    H, g = np.eye(8) + 0.5, -np.arange(1.0, 9.0)
    A = np.eye(8) - np.eye(8, k=-1)
    qrqp = ca.conic("q", "qrqp", {"h": ca.DM(H).sparsity(), "a": ca.DM(A).sparsity()},
                    {"print_iter": False, "print_header": False, "error_on_fail": False})
    x = np.asarray(qrqp(h=H, g=g, a=A, lba=-0.15, uba=0.15, lbx=-2, ubx=2)["x"]).ravel()
    assert qrqp.stats()["success"]
    assert np.max(np.abs(A @ x)) > 0.15 + 1e-3
    ipm = interior_point_qp(ca.DM(H).sparsity(), ca.sparsify(ca.DM(np.vstack((np.eye(8), A)))).sparsity())
    x_ipm = np.asarray(ipm(H, g, np.vstack((np.eye(8), A)), np.r_[-2 * np.ones(8), -0.15 * np.ones(8)],
                           np.r_[2 * np.ones(8), 0.15 * np.ones(8)])[0]).ravel()
    assert x_ipm == pytest.approx(0.15 * np.arange(1, 9), abs=1e-8)


def _qp_as_gauss_newton_step(qp: str):
    """``step(w=0, p=[vec(H); g]) -> (x, qp_error)``: the Gauss–Newton step on a quadratic cost
    solves ``min ½ xᵀHx + gᵀx, l <= x <= u, |Dx| <= du`` exactly (bounds of the random problems
    are baked in per call, so they come back with the step)."""
    w, p = ca.SX.sym("w", N), ca.SX.sym("p", N * N + N)
    H, g = ca.reshape(p[: N * N], N, N), p[N * N:]
    linearise = ca.Function("lin", [w, p], [H, H @ w + g, ca.DM(RATES), RATES @ w])
    cost = ca.Function("cost", [w, p], [0.5 * w.T @ H @ w + g.T @ w])
    return lambda l, u: gauss_newton_step(linearise, cost, l, u, qp=qp)


def test_daqp_step_matches_osqp_and_the_interior_point_step_on_random_badly_scaled_problems():
    make_daqp, make_ipm = _qp_as_gauss_newton_step("daqp"), _qp_as_gauss_newton_step("ipm")
    rng = np.random.default_rng(0)
    for _ in range(30):
        H, g, l, u, du = _random_problem(rng)
        p = np.r_[H.ravel(order="F"), g]
        x, qp_error = make_daqp(l, u)(np.zeros(N), p)
        assert float(qp_error) <= 1e-9
        assert np.max(np.abs(np.asarray(x).ravel() - _osqp(H, g, l, u))) <= 1e-6 * du
        x_ipm, _ = make_ipm(l, u)(np.zeros(N), p)
        assert np.max(np.abs(np.asarray(x).ravel() - np.asarray(x_ipm).ravel())) <= 1e-5 * du


def test_daqp_step_reports_a_qp_it_could_not_solve():
    H, g, l, u, _ = _random_problem(np.random.default_rng(5))
    step = _qp_as_gauss_newton_step("daqp")(l, u)
    _, qp_error = step(np.zeros(N), np.r_[H.ravel(order="F"), g * np.nan])
    assert float(qp_error) == np.inf
    _, qp_error = step(np.zeros(N), np.r_[(-H).ravel(order="F"), g])  # not convex: DAQP's setup fails
    assert float(qp_error) > 1e-6
    w, worst, _ = rti_steps(step, np.zeros(N), np.r_[H.ravel(order="F"), g * np.nan], iterations=3)
    assert worst == np.inf and not np.all(np.isfinite(w))  # ends at the first NaN: no NaN bounds for the QP


def test_an_unsettled_last_step_is_followed_by_one_more():
    """``extra_step_tolerance``: a third step when the second still moved the iterate by
    more than the tolerance, never a fourth; none when it settled."""
    w = ca.MX.sym("w", 2)
    halve = ca.Function("halve", [w, ca.MX.sym("p")], [w + (1.0 - w) / 2, ca.MX(0)])  # halves the distance to 1
    steps = [(w_out, taken) for w_out, _, taken in
             (rti_steps(halve, np.zeros(2), 0.0, 2, tol) for tol in (np.inf, 0.3, 0.2, 1e-9))]
    assert [taken for _, taken in steps] == [2, 2, 3, 3]  # the second step moved by 0.25
    assert np.allclose(steps[0][0], 0.75) and np.allclose(steps[2][0], 0.875) and np.allclose(steps[3][0], 0.875)


def test_compiled_daqp_step_equals_the_in_process_one_and_never_aborts(tmp_path):
    """CasADi's generated DAQP call made the whole function fail on a QP it did not solve to
    optimality; patched, it returns what DAQP gives and leaves the verdict to ``qp_error``."""
    H, g, l, u, du = _random_problem(np.random.default_rng(6))
    step = _qp_as_gauss_newton_step("daqp")(l, u)
    compiled = compile_function(step, tmp_path)
    p = np.r_[H.ravel(order="F"), g]
    assert np.array_equal(np.asarray(compiled(np.zeros(N), p)[0]), np.asarray(step(np.zeros(N), p)[0]))
    for bad in (np.r_[(-H).ravel(order="F"), g], np.r_[H.ravel(order="F"), g * np.nan]):
        _, qp_error = compiled(np.zeros(N), bad)
        assert not float(qp_error) <= 1e-6


def test_rti_settings_refuse_what_the_step_would_not_use():
    from hystmpc.mpc.settings import RtiSettings
    with pytest.raises(ValueError, match="qp_iterations=12 applies to solver.rti.qp=ipm only"):
        RtiSettings(qp_iterations=12).check_step(condensed=True)
    RtiSettings(qp="ipm", qp_iterations=12).check_step(condensed=True)
    with pytest.raises(ValueError, match="qp=ipm needs solver.rti.condensed=true"):
        RtiSettings(qp="ipm").check_step(condensed=False)
    with pytest.raises(ValueError, match="qp must be one of daqp, ipm"):
        RtiSettings(qp="qrqp")


def test_buffered_evaluation_gives_a_calls_numbers():
    """``BufferedEvaluation``: dense NumPy in and out through CasADi's buffers, the same
    numbers as a call; inputs not given take the Function's defaults (a QP's infinite
    bounds), sparse inputs and outputs are scattered by their sparsity."""
    from hystmpc.mpc.single_shooting import BufferedEvaluation
    x, p = ca.SX.sym("x", 4), ca.SX.sym("p", 3)
    r = ca.vertcat(ca.sin(x[:3]) * p, x[1:] - x[:-1], x[0] * x[3])
    fun = ca.Function("f", [x, p], [r, ca.jacobian(r, x)])  # a sparse Jacobian
    rng = np.random.default_rng(1)
    u, q = rng.normal(size=4), rng.normal(size=3)
    res, jac = BufferedEvaluation(fun)(u, q)
    assert np.array_equal(res, np.asarray(fun(u, q)[0]).ravel())
    assert np.array_equal(jac, np.asarray(fun(u, q)[1]))
    A = np.eye(4) - np.eye(4, k=-1)
    qp = ca.conic("q", "qrqp", {"h": ca.Sparsity.dense(4, 4), "a": ca.DM(A).sparsity()},
                  {"print_iter": False, "print_header": False, "error_on_fail": False})
    H, g = np.diag([1.0, 2.0, 3.0, 4.0]) + 0.1, rng.normal(size=4)
    args = {"h": H, "g": g, "a": A, "lba": -0.1 * np.ones(4), "uba": 0.1 * np.ones(4), "ubx": np.ones(4)}
    expected = qp(**args)
    step, cost, _, _ = BufferedEvaluation(qp)(**args)
    assert np.array_equal(step, np.asarray(expected["x"]).ravel()) and cost == float(expected["cost"])
    assert step.min() < 0 < step.max() <= 1  # lbx took its default, -inf; ubx the value given
    buffered = BufferedEvaluation(qp)  # a bound given in one call takes its default in the next without it
    buffered(**{**args, "ubx": np.full(4, 1e-3)})
    again = {k: v for k, v in args.items() if k != "ubx"}
    free = np.asarray(qp(**again)["x"]).ravel()
    assert free.max() > 1e-3 and np.array_equal(buffered(**again)[0], free)
    M, v = ca.SX.sym("M", 3, 2), ca.SX.sym("v", 2)
    product = ca.Function("product", [M, v], [M @ v, 2 * M])  # dense, not symmetric: column-major order
    m = rng.normal(size=(3, 2))
    out, twice = BufferedEvaluation(product)(m, np.array([1.0, -2.0]))
    assert np.array_equal(out, m @ [1.0, -2.0]) and np.array_equal(twice, 2 * m)
    with pytest.raises(ValueError, match="unknown input"):
        BufferedEvaluation(qp)(hh=H)
    with pytest.raises(ValueError, match=r"input h needs shape \(4, 4\), got \(2, 8\)"):
        BufferedEvaluation(qp)(h=np.ones((2, 8)))
