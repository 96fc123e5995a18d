"""Single-shooting tracking NMPC for models whose prediction is not a Markov step.

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

from mpc.nmpc import NmpcSettings, NmpcStep
from mpc.rti import QP_TOLERANCE, feasible_guess, rti_steps


class SingleShootingNmpc:
    """Minimise Σ q (y_k − r_k)² + r_rate Δu² + r_input (u − u_ff)² over the inputs only.

    Subject to ``u_min <= u <= u_max`` and ``|u_k − u_{k−1}| <= du_max``.

    Parameters
    ----------
    predict : casadi.Function
        ``(p, U) -> Y`` with ``U`` and ``Y`` of length ``settings.horizon``.
    settings : NmpcSettings
        Horizon, weights, solver (``ipopt``, ``sqp``, ``gn``, ``rti``, ``rti-c``), iterations, tolerance.
    u_min, u_max, du_max : float
        Input bounds and largest change per sample (``inf`` for none).
    """

    def __init__(self, predict: ca.Function, settings: NmpcSettings, u_min: float, u_max: float,
                 du_max: float = np.inf):
        N = settings.horizon
        if predict.size1_in(1) != N or predict.size1_out(0) != N:
            raise ValueError(f"predict must map {N} inputs to {N} outputs, "
                             f"got {predict.size1_in(1)} → {predict.size1_out(0)}")
        if not (u_min < u_max and du_max > 0):
            raise ValueError(f"need u_min < u_max and du_max > 0, got {u_min}, {u_max}, {du_max}")
        self.settings, self.predict = settings, predict
        self.u_min, self.u_max, self.du_max = float(u_min), float(u_max), float(du_max)
        self.n_params = predict.size1_in(0)
        U = ca.SX.sym("U", N)
        p = ca.SX.sym("p", self.n_params)
        u_prev = ca.SX.sym("u_prev")
        ref = ca.SX.sym("ref", N)
        u_ff = ca.SX.sym("u_ff", N)
        y = predict(p, U)
        du = U - ca.vertcat(u_prev, U[:-1])
        cost = (settings.q_output * ca.sumsqr(y - ref) + settings.r_rate * ca.sumsqr(du)
                + settings.r_input * ca.sumsqr(U - u_ff))
        rate_bounded = np.isfinite(self.du_max)
        self._rate_bounded = rate_bounded
        n_g = N if rate_bounded else 0
        self._bounds = {"lbx": np.full(N, self.u_min), "ubx": np.full(N, self.u_max),
                        "lbg": np.full(n_g, -self.du_max), "ubg": np.full(n_g, self.du_max)}
        self._lam = None
        self.rti = None
        if settings.solver in ("gn", "rti", "rti-c"):  # Gauss–Newton: the cost as a sum of squares
            params = ca.vertcat(p, u_prev, ref, u_ff)
            residual = ca.vertcat(np.sqrt(settings.q_output) * (y - ref), np.sqrt(settings.r_rate) * du,
                                  np.sqrt(settings.r_input) * (U - u_ff))
            if settings.solver == "gn":
                self._build_gauss_newton(U, params, residual)
            else:
                self._build_rti(U, params, residual, du)
            return
        nlp = {"x": U, "f": cost, "g": du if rate_bounded else ca.SX(0, 1),
               "p": ca.vertcat(p, u_prev, ref, u_ff)}
        if settings.solver == "ipopt":
            opts = {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes",
                    "ipopt.max_iter": settings.max_iter, "ipopt.tol": settings.tol,
                    "ipopt.acceptable_tol": 1e3 * settings.tol, "record_time": True}
            if settings.warm_multipliers:
                opts.update({"ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-4,
                             "ipopt.warm_start_bound_push": 1e-6, "ipopt.warm_start_mult_bound_push": 1e-6})
            self._solver = ca.nlpsol("nmpc_ss", "ipopt", nlp, opts)
        else:
            opts = {"qpsol": "qrqp", "qpsol_options": {"print_iter": False, "print_header": False,
                                                       "error_on_fail": False},
                    "max_iter": settings.max_iter, "tol_du": settings.tol, "tol_pr": settings.tol,
                    "print_header": False, "print_iteration": False, "print_status": False,
                    "print_time": False, "record_time": True, "error_on_fail": False}
            self._solver = ca.nlpsol("nmpc_ss", "sqpmethod", nlp, opts)

    def _build_gauss_newton(self, U, params, residual) -> None:
        N = self.settings.horizon
        J = ca.jacobian(residual, U)
        self._gn_eval = ca.Function("gn_eval", [U, params], [residual, J])
        H = ca.Sparsity.dense(N, N)
        A = ca.DM(np.eye(N) - np.eye(N, k=-1)) if self._rate_bounded else ca.DM(0, N)
        self._A = np.asarray(A)
        self._qp = ca.conic("gn_qp", "qrqp", {"h": H, "a": ca.DM(A).sparsity()},
                            {"print_iter": False, "print_header": False, "error_on_fail": False})

    def _build_rti(self, U, params, residual, du) -> None:
        """One Gauss–Newton step per sample as one Function (``rti``), compiled for ``rti-c``."""
        from mpc.rti import compile_function, rti_function
        residual = ca.Function("residual", [U, params], [residual])
        constraints = ca.Function("constraints", [U, params], [du if self._rate_bounded else ca.SX(0, 1)])
        b = self._bounds
        # the constraints are linear in U, so a shortened step stays feasible: backtrack as gn does
        self.rti = rti_function(residual, constraints, b["lbg"], b["ubg"], b["lbx"], b["ubx"],
                                step_lengths=(0.5, 0.25, 0.125))
        if self.settings.solver == "rti-c":
            self.rti = compile_function(self.rti)

    def _solve_gauss_newton(self, u, p):
        """Gauss–Newton SQP: QP on JᵀJ, backtracking on the cost; returns (u, ok, status, iters)."""
        s, N = self.settings, self.settings.horizon
        u_prev = p[self.n_params]
        res, J = (np.asarray(v) for v in self._gn_eval(u, p))
        res = res.ravel()
        cost = float(res @ res)
        for it in range(1, s.max_iter + 1):
            H = J.T @ J + 1e-10 * np.eye(N)
            g = J.T @ res
            args = {"h": H, "g": g, "lbx": self._bounds["lbx"] - u, "ubx": self._bounds["ubx"] - u}
            if self._rate_bounded:
                du = u - np.concatenate(([u_prev], u[:-1]))
                args.update(a=self._A, lba=self._bounds["lbg"] - du, uba=self._bounds["ubg"] - du)
            sol = self._qp(**args)
            step = np.asarray(sol["x"]).ravel()
            if not np.all(np.isfinite(step)):
                return u, False, "QP_Failed", it
            t = 1.0
            while t > 1e-3:
                trial = u + t * step
                res_t, J_t = (np.asarray(v) for v in self._gn_eval(trial, p))
                cost_t = float(res_t.ravel() @ res_t.ravel())
                if cost_t <= cost:
                    break
                t *= 0.5
            else:
                return u, True, "Solve_Succeeded", it  # no descent left: stationary
            u, res, J, cost = trial, res_t.ravel(), J_t, cost_t
            if np.max(np.abs(t * step)) <= s.tol * (1.0 + np.max(np.abs(u))):
                return u, True, "Solve_Succeeded", it
        return u, False, "Maximum_Iterations_Exceeded", s.max_iter

    def solve(self, params, u_prev: float, ref, u_guess, u_ff=None) -> NmpcStep:
        """Solve for the references ``ref`` (r_{k+1..k+N}) from ``params`` (see ``predict``)."""
        N = self.settings.horizon
        u_guess = np.clip(np.asarray(u_guess, float).ravel(), self.u_min, self.u_max)
        u_ff = u_guess if u_ff is None else np.asarray(u_ff, float).ravel()
        p = np.concatenate((np.asarray(params, float).ravel(), [u_prev], np.asarray(ref, float).ravel(), u_ff))
        if self.rti is not None:  # RTI: one Gauss–Newton step from the (shifted) warm start
            # backtracking keeps feasibility only from a feasible start
            u_start = feasible_guess(u_guess, u_prev, self.u_min, self.u_max, self.du_max)
            start = time.perf_counter()
            u, qp_error = rti_steps(self.rti, u_start, p, self.settings.rti_iterations)
            elapsed = time.perf_counter() - start
            finite = bool(np.all(np.isfinite(u)))
            success, iterations = finite and qp_error <= QP_TOLERANCE, self.settings.rti_iterations
            status = "RTI_Step" if success else ("RTI_Non_Finite" if not finite else "RTI_QP_Failed")
            y = np.asarray(self.predict(params, u)).ravel() if finite else np.full(N, np.nan)
            return NmpcStep(u_plan=u.reshape(N, 1), x_plan=y.reshape(N, 1), success=success, status=status,
                            iterations=iterations, solve_time=elapsed)
        if self.settings.solver == "gn":
            start = time.perf_counter()
            u, success, status, iterations = self._solve_gauss_newton(u_guess, p)
            elapsed = time.perf_counter() - start
            success = success and bool(np.all(np.isfinite(u)))
            y = np.asarray(self.predict(params, u)).ravel()
            return NmpcStep(u_plan=u.reshape(N, 1), x_plan=y.reshape(N, 1), success=success, status=status,
                            iterations=iterations, solve_time=elapsed)
        args = {"x0": u_guess, "p": p, **self._bounds}
        if self.settings.warm_multipliers and self._lam is not None:
            args["lam_x0"], args["lam_g0"] = self._lam
        start = time.perf_counter()
        sol = self._solver(**args)
        elapsed = time.perf_counter() - start
        stats = self._solver.stats()
        u = np.asarray(sol["x"]).ravel()
        success = bool(stats.get("success", False)) and bool(np.all(np.isfinite(u)))
        self._lam = (np.asarray(sol["lam_x"]).ravel(), np.asarray(sol["lam_g"]).ravel()) if success else None
        y = np.asarray(self.predict(params, u)).ravel()
        return NmpcStep(u_plan=u.reshape(N, 1), x_plan=y.reshape(N, 1), success=success,
                        status=str(stats.get("return_status", "")),
                        iterations=int(stats.get("iter_count", -1)), solve_time=elapsed)
