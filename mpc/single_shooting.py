"""Single-shooting tracking problem for predictions that are not a Markov step.

Some predictions need more than the current state: the FCKP creep couples every predicted
sample to all earlier ones in the horizon (the Grünwald–Letnikov sum). Such a model is given
as a whole-horizon CasADi function ``predict(p, U) -> Y`` (``p``: state, disturbance, history
terms, anything the caller fixes; ``U``: the N inputs; ``Y``: the N predicted outputs), and the
NLP has only the inputs as unknowns.
"""

from __future__ import annotations

import time

import casadi as ca
import numpy as np

from hystmpc.mpc.codegen.toolchain import compiled_or_slower
from hystmpc.mpc.problem import Solution, TrackingProblem
from hystmpc.mpc.rti import REGULARISATION, gauss_newton_step, rti_function
from hystmpc.mpc.settings import InputBounds, NmpcSettings, SolverSettings

GN_COMPILE_FLAGS = ("-O1", "-ffp-contract=off")
"""Flags of ``gn``'s compiled residual and Jacobian: on dea's unrolled prediction -O1 compiles
more slowly than -O0 but runs faster per call (docs/dea.md, "Solver")."""


class BufferedEvaluation:
    """A CasADi Function called through its zero-copy buffers, on dense NumPy values.

    The same numbers as a call, without its conversions (on dea's Gauss–Newton evaluation and QP
    they cost more than the compiled evaluation itself).

    Parameters
    ----------
    fun : casadi.Function
        The Function to call.
    """

    def __init__(self, fun: ca.Function):
        def layout(shape, sparsity):
            dense = sparsity.is_dense()
            return shape, dense, *(np.asarray(v, int) for v in sparsity.get_triplet())
        self._names = [fun.name_in(i) for i in range(fun.n_in())]
        self._index = {name: i for i, name in enumerate(self._names)}
        self._defaults = [fun.default_in(i) for i in range(fun.n_in())]
        self._inputs = [np.full(fun.nnz_in(i), self._defaults[i]) for i in range(fun.n_in())]
        self._outputs = [np.zeros(fun.nnz_out(i)) for i in range(fun.n_out())]
        self._in_layout = [layout(fun.size_in(i), fun.sparsity_in(i)) for i in range(fun.n_in())]
        self._out_layout = [layout(fun.size_out(i), fun.sparsity_out(i)) for i in range(fun.n_out())]
        self._given: set[int] = set()  # inputs that hold a given value, not their default
        self._buffer, self._evaluate = fun.buffer()
        for i, a in enumerate(self._inputs):
            self._buffer.set_arg(i, memoryview(a))
        for i, a in enumerate(self._outputs):
            self._buffer.set_res(i, memoryview(a))

    def __call__(self, *args, **named) -> list[np.ndarray]:
        """The outputs as new dense arrays (column vectors as 1-D).

        Inputs by position or name, dense, the ones not given at the Function's defaults.
        """
        if len(args) > len(self._names):
            raise ValueError(f"{len(args)} arguments for a Function of {len(self._names)} inputs")
        given = dict(enumerate(args))
        for name, value in named.items():
            if name not in self._index:
                raise ValueError(f"unknown input(s) {sorted(set(named) - set(self._index))}; allowed: "
                                 f"{', '.join(self._names)}")
            given[self._index[name]] = value
        now = {i for i, value in given.items() if value is not None}
        for i in self._given - now:  # given last time, not now: back to the default
            self._inputs[i].fill(self._defaults[i])
        self._given = now
        for i in self._given:
            target, (shape, dense, rows, cols) = self._inputs[i], self._in_layout[i]
            value = np.asarray(given[i], float)
            vector = 1 in shape or value.ndim < 2
            if value.size != shape[0] * shape[1] or not (vector or value.shape == tuple(shape)):
                raise ValueError(f"input {self._names[i]} needs shape {tuple(shape)}, got {value.shape}")
            if dense:
                target[:] = value.ravel(order="F")
            else:
                target[:] = np.reshape(value, shape, order="F")[rows, cols]
        self._evaluate()
        outputs = []
        for values_nz, (shape, dense, rows, cols) in zip(self._outputs, self._out_layout, strict=True):
            if dense:
                outputs.append(values_nz.copy() if shape[1] == 1 else values_nz.reshape(shape, order="F").copy())
                continue
            full = np.zeros(shape)
            full[rows, cols] = values_nz
            outputs.append(full[:, 0] if shape[1] == 1 else full)
        return outputs


class SingleShootingProblem(TrackingProblem):
    """Minimise Σ q (y_k − r_k)² + r_rate Δu² + r_input (u − u_ff)² over the inputs only.

    Subject to the input bounds and ``|u_k − u_{k−1}| <= rate``. The condition is the
    ``p`` of ``predict``.

    Parameters
    ----------
    predict : casadi.Function
        ``(p, U) -> Y`` with ``U`` and ``Y`` of length ``settings.horizon``.
    settings : NmpcSettings
        Horizon, weights, solver (``ipopt``, ``sqp``, ``gn``, ``rti``, ``rti-c``).
    bounds : InputBounds
        Input bounds and largest change per sample.
    solvers : SolverSettings
        Settings of every solver (``solver.rti.condensed=false`` does not apply).
    predict_jacobian, compact_predict : casadi.Function, optional
        ``(p, U) -> (Y, dY/dU)`` and a ``predict`` that generates small C (function calls per
        sample rather than one unrolled graph). Given both, the ``rti`` step is built from
        them; otherwise from ``predict``'s symbolic Jacobian.
    """

    def __init__(self, predict: ca.Function, settings: NmpcSettings, bounds: InputBounds,
                 solvers: SolverSettings | None = None, *, predict_jacobian: ca.Function | None = None,
                 compact_predict: ca.Function | None = None):
        N = settings.horizon
        if predict.size1_in(1) != N or predict.size1_out(0) != N:
            raise ValueError(f"predict must map {N} inputs to {N} outputs, "
                             f"got {predict.size1_in(1)} → {predict.size1_out(0)}")
        solvers = solvers or SolverSettings()
        if not solvers.rti.condensed:
            raise ValueError("solver.rti.condensed=false needs a multiple-shooting problem; a single-shooting "
                             "problem has the inputs as its only unknowns")
        if solvers.rti.sensitivity_block:
            raise ValueError(f"solver.rti.sensitivity_block={solvers.rti.sensitivity_block} needs a multiple-shooting "
                             "problem; a single-shooting problem differentiates its prediction as a whole")
        super().__init__(settings, bounds, solvers, predict.size1_in(0))
        self.predict = predict
        self._predict_jacobian, self._compact_predict = predict_jacobian, compact_predict
        U = ca.SX.sym("U", N)
        p = ca.SX.sym("p", self.n_condition)
        u_prev = ca.SX.sym("u_prev")
        ref = ca.SX.sym("ref", N)
        u_ff = ca.SX.sym("u_ff", N)
        y = predict(p, U)
        du = U - ca.vertcat(u_prev, U[:-1])
        rate_bounded = np.isfinite(self.du_max)
        self._rate_bounded = rate_bounded
        n_g = N if rate_bounded else 0
        self._bounds = {"lbx": np.full(N, self.u_min), "ubx": np.full(N, self.u_max),
                        "lbg": np.full(n_g, -self.du_max), "ubg": np.full(n_g, self.du_max)}
        params = ca.vertcat(p, u_prev, ref, u_ff)
        if settings.solver in ("gn", "rti", "rti-c"):  # Gauss–Newton: the cost as a sum of squares
            residual = ca.vertcat(np.sqrt(settings.q_output) * (y - ref), np.sqrt(settings.r_rate) * du,
                                  np.sqrt(settings.r_input) * (U - u_ff))
            if settings.solver == "gn":
                self._build_gauss_newton(U, params, residual)
            else:
                self._build_rti(U, params, residual, du, y[N - 1] - ref[N - 1])
            return
        cost = (settings.q_output * ca.sumsqr(y - ref) + settings.r_rate * ca.sumsqr(du)
                + settings.r_input * ca.sumsqr(U - u_ff))
        self._uses_nlp_solver({"x": U, "f": cost, "g": du if rate_bounded else ca.SX(0, 1), "p": params})

    def _linearisation(self, n_params: int) -> tuple[ca.Function, ca.Function, ca.Function]:
        """The RTI step's ``linearise``, ``cost`` and ``outcome`` Functions.

        ``linearise(U, params) -> (H, Jᵀr, A, g, Σ r²)``, ``cost(U, params)`` and
        ``outcome(U, params) -> (cost, y_N − r_N)``, all from the model's ``predict_jacobian``
        and ``compact_predict`` (see :func:`hystmpc.mpc.rti.gauss_newton_step`).
        """
        s, N, n = self.settings, self.horizon, self.n_condition
        U, params = ca.MX.sym("U", N), ca.MX.sym("params", n_params)
        p, u_prev, ref, u_ff = params[:n], params[n], params[n + 1: n + 1 + N], params[n + 1 + N:]
        D = ca.DM(np.eye(N) - np.eye(N, k=-1))
        du = U - ca.vertcat(u_prev, U[:-1])
        y, dy = self._predict_jacobian(p, U)

        def residual(outputs):
            return ca.vertcat(np.sqrt(s.q_output) * (outputs - ref), np.sqrt(s.r_rate) * du,
                              np.sqrt(s.r_input) * (U - u_ff))

        r = residual(y)
        J = ca.vertcat(np.sqrt(s.q_output) * dy, np.sqrt(s.r_rate) * D, np.sqrt(s.r_input) * ca.DM.eye(N))
        H = J.T @ J + REGULARISATION * ca.DM.eye(N)
        A, g = (ca.MX(ca.sparsify(D)), du) if self._rate_bounded else (ca.MX(0, N), ca.MX(0, 1))
        linearise = ca.Function("rti_linearise", [U, params], [H, J.T @ r, A, g, ca.sumsqr(r)])
        outputs = self._compact_predict(p, U)
        cost = ca.sumsqr(residual(outputs))
        return (linearise, ca.Function("rti_cost", [U, params], [cost]),
                ca.Function("rti_outcome", [U, params], [cost, outputs[N - 1] - ref[N - 1]]))

    def _build_gauss_newton(self, U, params, residual) -> None:
        N = self.horizon
        evaluate = ca.Function("gn_eval", [U, params], [residual, ca.jacobian(residual, U)])
        # the line search's trials need the residual only; most of them are rejected
        residual_only = ca.Function("gn_residual", [U, params], [residual])
        # compiled: the same numbers to the last bit, in a fraction of the time
        slower = "solver gn evaluates {} in-process, slower"
        self._gn_eval = compiled_or_slower(evaluate, slower.format("its residual and Jacobian"), GN_COMPILE_FLAGS)
        self._gn_residual = compiled_or_slower(residual_only, slower.format("its line search's residual"),
                                               GN_COMPILE_FLAGS)
        self._gn_buffered = BufferedEvaluation(self._gn_eval)
        self._gn_residual_buffered = BufferedEvaluation(self._gn_residual)
        H = ca.Sparsity.dense(N, N)
        A = ca.DM(np.eye(N) - np.eye(N, k=-1)) if self._rate_bounded else ca.DM(0, N)
        self._A = np.asarray(A)
        self._qp = ca.conic("gn_qp", "qrqp", {"h": H, "a": ca.DM(A).sparsity()},
                            {"print_iter": False, "print_header": False, "error_on_fail": False})
        self._qp_buffered = BufferedEvaluation(self._qp)

    def _build_rti(self, U, params, residual, du, end_error) -> None:
        """One Gauss–Newton step per sample as one Function (``rti``), compiled for ``rti-c``."""
        b, rti = self._bounds, self.solvers.rti
        rti.check_step(condensed=True)
        # the constraints are linear in U, so a shortened step stays feasible: backtrack as gn does
        if (self._predict_jacobian is None) != (self._compact_predict is None):
            raise ValueError("give both predict_jacobian and compact_predict, or neither")
        if self._predict_jacobian is not None:
            linearise, self.rti_cost, self.rti_outcome = self._linearisation(params.numel())
            lower = np.concatenate((b["lbx"], b["lbg"]))
            upper = np.concatenate((b["ubx"], b["ubg"]))
            self.rti = gauss_newton_step(linearise, self.rti_cost, lower, upper, step_lengths=(0.5, 0.25, 0.125),
                                         qp=rti.qp, qp_iterations=rti.qp_iterations, line_search=rti.line_search)
        else:
            self.rti_cost = ca.Function("rti_cost", [U, params], [ca.sumsqr(residual)])
            self.rti_outcome = ca.Function("rti_outcome", [U, params], [ca.sumsqr(residual), end_error])
            residual = ca.Function("residual", [U, params], [residual])
            constraints = ca.Function("constraints", [U, params], [du if self._rate_bounded else ca.SX(0, 1)])
            self.rti = rti_function(residual, constraints, b["lbg"], b["ubg"], b["lbx"], b["ubx"],
                                    step_lengths=(0.5, 0.25, 0.125), qp=rti.qp, qp_iterations=rti.qp_iterations,
                                    line_search=rti.line_search)
        self._compile_rti()

    def _solve_gauss_newton(self, u, p):
        """Gauss–Newton SQP: QP on JᵀJ, backtracking on the cost; returns (u, ok, status, iters, residual at u)."""
        gn, N = self.solvers.gn, self.horizon
        u_prev = p[self.n_condition]
        res, J = self._gn_buffered(u, p)
        cost = float(res @ res)
        if not np.isfinite(cost):
            return u, False, "Non_Finite_Cost", 0, res
        for it in range(1, gn.max_iter + 1):
            H = J.T @ J + 1e-10 * np.eye(N)
            g = J.T @ res
            args = {"h": H, "g": g, "lbx": self._bounds["lbx"] - u, "ubx": self._bounds["ubx"] - u}
            if self._rate_bounded:
                du = u - np.concatenate(([u_prev], u[:-1]))
                args.update(a=self._A, lba=self._bounds["lbg"] - du, uba=self._bounds["ubg"] - du)
            step = self._qp_buffered(**args)[0]
            if not np.all(np.isfinite(step)):
                return u, False, "QP_Failed", it, res
            t = 1.0
            while t > 1e-3:
                trial = u + t * step
                res_t = self._gn_residual_buffered(trial, p)[0]
                cost_t = float(res_t @ res_t)
                if cost_t <= cost:
                    break
                t *= 0.5
            else:  # no descent left: stationary, unless the cost stopped being a number
                finite = np.isfinite(cost_t)
                return u, bool(finite), "Solve_Succeeded" if finite else "Non_Finite_Cost", it, res
            stalled = cost - cost_t < gn.ftol * cost
            u, res, cost = trial, res_t, cost_t
            if np.max(np.abs(t * step)) <= gn.tol * (1.0 + np.max(np.abs(u))) or stalled:
                return u, True, "Solve_Succeeded", it, res
            if it < gn.max_iter:  # the Jacobian at the accepted trial, for the next step only
                J = self._gn_buffered(u, p)[1]
        return u, False, "Maximum_Iterations_Exceeded", gn.max_iter, res

    def solve(self, condition, u_prev: float, ref, u_guess, x_guess=None, u_ff=None) -> Solution:
        """Solve for the references ``ref`` (r_{k+1..k+N}) from ``condition`` (the ``p`` of ``predict``).

        Parameters
        ----------
        condition : array_like
            The ``p`` of ``predict``.
        u_prev : float
            Input applied in the previous sample (for the rate bound).
        ref : array_like, shape (N,)
            Output references for the predicted samples 1..N.
        u_guess : array_like, shape (N,)
            Initial input guess.
        x_guess : array_like, optional
            Not used: the inputs are the only unknowns.
        u_ff : array_like, shape (N,), optional
            Feed-forward inputs that ``r_input`` pulls towards (default ``u_guess``).

        Returns
        -------
        Solution
            The plan and the solver's report.
        """
        N = self.horizon
        u_guess = np.clip(np.asarray(u_guess, float).ravel(), self.u_min, self.u_max)
        u_ff = u_guess if u_ff is None else np.asarray(u_ff, float).ravel()
        p = self._parameters(condition, u_prev, ref, u_ff)
        if self.rti is not None:  # backtracking keeps feasibility only from a feasible start
            return self._solve_rti(self.feasible_start(u_guess, u_prev), p,
                                   lambda w, finite: (w.reshape(N, 1), None))
        if self.settings.solver == "gn":
            start = time.perf_counter()
            u, success, status, iterations, residual = self._solve_gauss_newton(u_guess, p)
            elapsed = time.perf_counter() - start
            success = success and bool(np.all(np.isfinite(u)))
            end_error = residual[N - 1] / np.sqrt(self.settings.q_output)  # the residual's first N: √q (y - r)
            return Solution(u_plan=u.reshape(N, 1), x_plan=None, success=success, status=status,
                            iterations=iterations, solve_time=elapsed, cost=float(residual @ residual),
                            end_error=float(end_error))
        u, success, status, iterations, elapsed = self._solve_nlp({"x0": u_guess, "p": p, **self._bounds}, warm=True)
        return Solution(u_plan=u.reshape(N, 1), x_plan=None, success=success, status=status,
                        iterations=iterations, solve_time=elapsed)
