"""The acados twin's problems (without acados): the cost they encode is the RTI step's."""

import numpy as np
import pytest

from hystmpc.experiments.peer_acados import _rti_bench, _write_problems, twin_least_squares
from hystmpc.mpc.codegen import RecordingStep
from hystmpc.mpc.rti import REGULARISATION


def test_the_twin_problems_encode_the_steps_cost_on_the_states(tmp_path):
    """At the recorded start, the twin's least-squares cost (stage k: y(x_k) against its
    reference, the rate against the last input in the state, the input against its target;
    y(x_N) at the end) is the step's cost, with the regularisation folded into the target."""
    bench, _, prepared = _rti_bench("pam")
    problem = prepared.controller.problem
    problem.rti = RecordingStep(problem.rti)
    bench.run(bench.default_scenario, "nmpc", duration=6.0, prepared=prepared)  # a step of the square
    calls = np.asarray(problem.rti.calls)
    _write_problems(problem, calls, tmp_path / "problems.txt")
    header = (tmp_path / "problems.txt").read_text().split("\n", 1)[0]
    nx_aug, nu, n_p, ny, ny_e, N, count = (int(v) for v in header.split())
    assert (nu, ny, ny_e, N, count) == (1, 3, 1, problem.settings.horizon, len(calls))
    rows = np.loadtxt(tmp_path / "problems.txt", skiprows=1, ndmin=2)
    s, output = problem.settings, problem.model.output
    for call, row in zip(calls, rows, strict=True):
        states = row[nx_aug: nx_aug * (N + 2)].reshape(N + 1, nx_aug)
        u = row[nx_aug * (N + 2): nx_aug * (N + 2) + N]
        d = row[nx_aug * (N + 2) + N: nx_aug * (N + 2) + N + n_p]
        yref = row[nx_aug * (N + 2) + N + (N + 1) * n_p:].reshape(-1)
        stage_refs, terminal = yref[:-1].reshape(N, ny), yref[-1]
        y = np.array([float(output(x[:-1], d)) for x in states])
        cost = s.q_output * (np.sum((y[1:N] - stage_refs[1:, 0]) ** 2) + (y[N] - terminal) ** 2)
        cost += s.r_rate * np.sum((u - states[:N, -1] - stage_refs[:, 1]) ** 2)
        cost += (s.r_input + REGULARISATION) * np.sum((u - stage_refs[:, 2]) ** 2)
        w0, p = call[:N], call[N:]
        u_ff = p[-N:]
        # r_input (u - u_ff)² + ε (u - w0)² = (r_input + ε) (u - target)² + r_input ε / (r_input + ε) (w0 - u_ff)²
        expected = float(problem.rti_cost(w0, p)) - s.r_input * REGULARISATION / (s.r_input + REGULARISATION) * np.sum(
            (w0 - u_ff) ** 2)
        assert np.array_equal(u, w0)
        assert cost == pytest.approx(expected, rel=1e-9, abs=1e-12)
    assert np.ptp([row[0] for row in rows]) > 1.0  # the angle moved: the references are not all alike


def test_the_twins_gauss_newton_qp_is_the_steps(tmp_path):
    """With an input weight (so the regularisation's folding into the target matters), the
    twin's least squares (its Vx, Vu, W from the problem file's references, linearised at the
    recorded start) give the step's Hessian and gradient."""
    import casadi as ca

    from hystmpc.experiments.benches import get_bench
    bench = get_bench("pam")
    prepared = bench.prepare(bench.default_scenario, "nmpc",
                             bench.configure(["nmpc.solver=rti", "nmpc.runtime=python", "nmpc.r_input=0.1"]))
    problem = prepared.controller.problem
    problem.rti = RecordingStep(problem.rti)
    bench.run(bench.default_scenario, "nmpc", duration=6.0, prepared=prepared)
    calls = np.asarray(problem.rti.calls)[[0, 240, 250, 260]]  # around the square's step at 5 s
    _write_problems(problem, calls, tmp_path / "problems.txt")
    rows = np.loadtxt(tmp_path / "problems.txt", skiprows=1, ndmin=2)
    cost = twin_least_squares(problem)
    assert cost is not None  # pam's output is its angle: linear least squares
    N, nx = problem.settings.horizon, problem.model.nx
    linearise = problem._condensed_linearisation(calls.shape[1] - N, N)[0]
    U = ca.MX.sym("U", N)
    for call, row in zip(calls, rows, strict=True):
        w0, p = call[:N], call[N:]
        u_prev = row[nx]
        yref = row[(nx + 1) * (N + 2) + N + (N + 1) * problem.model.nd:]
        stage_refs, terminal = yref[:-1].reshape(N, 3), yref[-1]
        states = problem.rollout(U, p)
        lasts = ca.vertcat(u_prev, U)
        residuals = [cost["Vx"] @ ca.vertcat(states[k, :].T, lasts[k]) + cost["Vu"] * U[k] - stage_refs[k]
                     for k in range(N)]
        terminal_residual = cost["Vx_e"] @ ca.vertcat(states[N, :].T, lasts[N]) - terminal
        weighted = ca.vertcat(*[np.sqrt(cost["W"]) @ r for r in residuals], np.sqrt(cost["W_e"]) @ terminal_residual)
        J = ca.Function("J", [U], [ca.jacobian(weighted, U), weighted])
        jacobian, value = (np.asarray(v) for v in J(w0))
        H, gradient = (np.asarray(ca.DM(v)) for v in linearise(w0, p)[:2])
        assert jacobian.T @ jacobian == pytest.approx(H, rel=1e-10, abs=1e-10)
        assert (jacobian.T @ value).ravel() == pytest.approx(gradient.ravel(), rel=1e-10, abs=1e-10)
    assert np.abs(gradient).max() > 1e-3
