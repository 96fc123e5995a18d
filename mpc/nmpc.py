"""Multiple-shooting tracking NMPC built on a :class:`mpc.model.PredictionModel`."""

from __future__ import annotations

import time
from dataclasses import dataclass

import casadi as ca
import numpy as np

from mpc.model import PredictionModel
from mpc.rti import QP_TOLERANCE, feasible_guess, rti_steps

SOLVERS = ("ipopt", "sqp", "rti", "rti-c", "gn")
"""Solver variants: IPOPT (robust default); CasADi sqpmethod + qrqp; ``rti``, one Gauss–Newton
SQP step per sample as one CasADi Function (:mod:`mpc.rti`; condensed onto the inputs, with
the interior-point QP of :mod:`mpc.qp`); ``rti-c``, the same generated as C, compiled and
loaded; ``gn``, Gauss–Newton SQP to convergence (single-shooting problems only,
:mod:`mpc.shooting`)."""
WARM_STARTS = ("inverse", "shift", "cold")


@dataclass(frozen=True)
class NmpcSettings:
    """Settings of the NMPC (``--set nmpc.KEY=VALUE``)."""

    horizon: int = 20
    """Prediction horizon N in samples."""
    q_output: float = 1.0
    """Weight on the squared tracking error of each predicted output."""
    r_rate: float = 0.3
    """Weight on the squared input change per sample (damps valve chatter from sensor noise)."""
    r_input: float = 0.0
    """Weight on the squared deviation of the input from the inverse-model input."""
    solver: str = "ipopt"
    """Solver variant, one of :data:`SOLVERS`."""
    preview: bool = True
    """Use the known future reference over the horizon; false holds the current one."""
    warm_start: str = "inverse"
    """Initial guess at start-up, after a reference jump and after a failure: 'inverse',
    'shift' (previous plan only, zeros at start) or 'cold' (zeros every step)."""
    max_iter: int = 100
    """Iteration limit of the solver per sample."""
    tol: float = 1e-6
    """Solver tolerance."""
    eps: float = 1e-3
    """Smoothing width of the hysteresis switching in the prediction model."""
    direction_eps: float = 0.0
    """Width of the direction detection (sign of the input change) in models that have one;
    0: same as ``eps``. Must be well below the input change per sample."""
    warm_multipliers: bool = False
    """IPOPT only: also start from the previous solve's multipliers (warm_start_init_point)."""
    rti_iterations: int = 1
    """rti/rti-c only: Gauss–Newton steps per sample (1 is the classic real-time iteration)."""
    rti_condensed: bool = True
    """rti/rti-c on multiple-shooting problems: eliminate the states by a rollout inside the
    step, so the QP has the N inputs only and the step backtracks on the cost; false: the
    QP over states and inputs with the shooting gaps as constraints, full step."""
    rti_qp_iterations: int = 30
    """Interior-point iterations of the condensed RTI step's QP (fixed: real time)."""

    def __post_init__(self):
        if self.horizon < 2:
            raise ValueError(f"horizon must be >= 2, got {self.horizon}")
        if self.rti_iterations < 1:
            raise ValueError(f"rti_iterations must be >= 1, got {self.rti_iterations}")
        if self.rti_qp_iterations < 10:
            raise ValueError(f"rti_qp_iterations must be >= 10, got {self.rti_qp_iterations}")
        if self.solver not in SOLVERS:
            raise ValueError(f"solver {self.solver!r} is unknown; allowed: {', '.join(SOLVERS)}")
        if self.warm_start not in WARM_STARTS:
            raise ValueError(f"warm_start {self.warm_start!r} is unknown; allowed: {', '.join(WARM_STARTS)}")
        for name in ("q_output", "r_rate", "r_input"):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {getattr(self, name)}")
        if self.q_output <= 0:
            raise ValueError(f"q_output must be > 0, got {self.q_output}")
        if self.max_iter < 1 or not self.tol > 0 or not self.eps > 0:
            raise ValueError("max_iter must be >= 1, tol and eps > 0")
        if not (np.isfinite(self.direction_eps) and self.direction_eps >= 0):
            raise ValueError(f"direction_eps must be finite and >= 0, got {self.direction_eps}")


@dataclass
class NmpcStep:
    """Result of one NLP solve."""

    u_plan: np.ndarray
    """Optimal inputs over the horizon, shape (N, nu)."""
    x_plan: np.ndarray
    """Predicted states, shape (N+1, nx)."""
    success: bool
    """Whether the solver reported convergence."""
    status: str
    """Solver's return status."""
    iterations: int
    """Solver iterations."""
    solve_time: float
    """Wall-clock time of the solve (s)."""


class Nmpc:
    """Tracking NMPC: minimise Σ q (y_k − r_k)² + r_rate Δu² + r_input (u − u_ff)².

    Subject to ``x_{k+1} = F(x_k, u_k, d)``, ``u_min <= u <= u_max`` and
    ``|u_k − u_{k−1}| <= du_max`` (with ``u_{−1}`` the input applied last sample).

    Parameters
    ----------
    model : PredictionModel
        Nominal discrete-time model.
    settings : NmpcSettings
        Horizon, weights, solver.
    u_min, u_max, du_max : float
        Input bounds and largest input change per sample (scalar input).
    """

    def __init__(self, model: PredictionModel, settings: NmpcSettings,
                 u_min: float, u_max: float, du_max: float):
        if model.nu != 1:
            raise ValueError(f"only scalar inputs are supported, model has nu={model.nu}")
        if not (u_min < u_max and du_max > 0):
            raise ValueError(f"need u_min < u_max and du_max > 0, got {u_min}, {u_max}, {du_max}")
        if settings.solver == "gn":
            raise ValueError("solver 'gn' is only available for single-shooting problems; "
                             "allowed here: ipopt, sqp, rti, rti-c")
        self.model = model
        self.settings = settings
        self.u_min, self.u_max, self.du_max = float(u_min), float(u_max), float(du_max)
        self._build()

    def _build(self) -> None:
        m, s = self.model, self.settings
        N, nx, nd = s.horizon, m.nx, m.nd
        X = ca.SX.sym("X", nx, N + 1)
        U = ca.SX.sym("U", 1, N)
        x0 = ca.SX.sym("x0", nx)
        d = ca.SX.sym("d", nd)
        u_prev = ca.SX.sym("u_prev")
        ref = ca.SX.sym("ref", N)
        u_ff = ca.SX.sym("u_ff", N)
        shooting = [X[:, 0] - x0]
        rates, residuals = [], []
        for k in range(N):
            shooting.append(X[:, k + 1] - m.step(X[:, k], U[0, k], d))
            e = m.output(X[:, k + 1], d) - ref[k]
            du = U[0, k] - (u_prev if k == 0 else U[0, k - 1])
            rates.append(du)
            residuals += [np.sqrt(s.q_output) * e, np.sqrt(s.r_rate) * du,
                          np.sqrt(s.r_input) * (U[0, k] - u_ff[k])]
        residual = ca.vertcat(*residuals)
        cost = ca.sumsqr(residual)
        w = ca.vertcat(ca.vec(X), ca.vec(U))
        g = ca.vertcat(*shooting, *rates)
        p = ca.vertcat(x0, d, u_prev, ref, u_ff)
        nlp = {"x": w, "f": cost, "g": g, "p": p}
        self.residual = ca.Function("nmpc_residual", [w, p], [residual], ["w", "p"], ["r"])
        self.constraints = ca.Function("nmpc_constraints", [w, p], [g], ["w", "p"], ["g"])
        if s.solver == "ipopt":
            opts = {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes",
                    "ipopt.max_iter": s.max_iter, "ipopt.tol": s.tol,
                    "ipopt.acceptable_tol": 1e3 * s.tol, "record_time": True}
            if s.warm_multipliers:
                opts.update({"ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-4,
                             "ipopt.warm_start_bound_push": 1e-6, "ipopt.warm_start_mult_bound_push": 1e-6})
            self._solver = ca.nlpsol("nmpc", "ipopt", nlp, opts)
        elif s.solver in ("rti", "rti-c"):
            self._solver = None
        else:
            opts = {"qpsol": "qrqp", "qpsol_options": {"print_iter": False, "print_header": False,
                                                       "error_on_fail": False},
                    "max_iter": s.max_iter, "tol_du": s.tol, "tol_pr": s.tol, "print_header": False,
                    "print_iteration": False, "print_status": False, "print_time": False,
                    "record_time": True, "error_on_fail": False}
            self._solver = ca.nlpsol("nmpc", "sqpmethod", nlp, opts)
        n_shoot = nx * (N + 1)
        self._lbg = np.concatenate((np.zeros(n_shoot), -self.du_max * np.ones(N)))
        self._ubg = np.concatenate((np.zeros(n_shoot), self.du_max * np.ones(N)))
        self._lbx = np.concatenate((-np.inf * np.ones(n_shoot), self.u_min * np.ones(N)))
        self._ubx = np.concatenate((np.inf * np.ones(n_shoot), self.u_max * np.ones(N)))
        self._n_shoot = n_shoot
        self._lam = None
        self.condensed = s.solver in ("rti", "rti-c") and s.rti_condensed
        if s.solver in ("rti", "rti-c"):
            from mpc.rti import compile_function, rti_function
            if self.condensed:
                self.rti = self._condensed_rti(p)
            else:  # the shooting gaps are equalities and the states unbounded: qrqp
                self.rti = rti_function(self.residual, self.constraints, self._lbg, self._ubg, self._lbx, self._ubx)
            if s.solver == "rti-c":
                self.rti = compile_function(self.rti)

    def _condensed_rti(self, p: ca.SX) -> ca.Function:
        """The RTI step over the inputs only: the states come from a rollout from x0.

        With no state constraints in this problem, eliminating the states leaves only the
        input bounds and the rate bounds, which are linear in U. A shortened Gauss–Newton
        step then stays feasible, so the step can backtrack on the cost (``step_lengths``).
        The QP goes to the interior-point solver of :mod:`mpc.qp` (qrqp gets some of these
        QPs wrong).
        """
        from mpc.rti import rti_function
        m, s = self.model, self.settings
        N, nx, nd = s.horizon, m.nx, m.nd
        U = ca.SX.sym("U", N)
        x0, d, u_prev = p[:nx], p[nx: nx + nd], p[nx + nd]
        ref, u_ff = p[nx + nd + 1: nx + nd + 1 + N], p[nx + nd + 1 + N:]
        x, states, residuals = x0, [x0], []
        for k in range(N):
            x = m.step(x, U[k], d)
            states.append(x)
            du = U[k] - (u_prev if k == 0 else U[k - 1])
            residuals += [np.sqrt(s.q_output) * (m.output(x, d) - ref[k]), np.sqrt(s.r_rate) * du,
                          np.sqrt(s.r_input) * (U[k] - u_ff[k])]
        n_rates = N if np.isfinite(self.du_max) else 0  # no rate rows for an unbounded rate
        rates = (U - ca.vertcat(u_prev, U[:-1]))[:n_rates]
        self.rollout = ca.Function("nmpc_rollout", [U, p], [ca.horzcat(*states).T])
        return rti_function(ca.Function("residual", [U, p], [ca.vertcat(*residuals)]),
                            ca.Function("constraints", [U, p], [rates]),
                            -self.du_max * np.ones(n_rates), self.du_max * np.ones(n_rates),
                            self.u_min * np.ones(N), self.u_max * np.ones(N),
                            step_lengths=(0.5, 0.25, 0.125), qp="ipm", qp_iterations=s.rti_qp_iterations)

    def solve(self, x0, d, u_prev: float, ref, u_guess, x_guess=None, u_ff=None) -> NmpcStep:
        """Solve the NLP from state ``x0`` for the references ``ref[0..N-1]`` = r_{k+1..k+N}.

        Parameters
        ----------
        x0 : array_like, shape (nx,)
            Current state estimate.
        d : array_like, shape (nd,)
            Current disturbance estimate, held over the horizon.
        u_prev : float
            Input applied in the previous sample (for the rate bound).
        ref : array_like, shape (N,)
            Output references for the predicted samples 1..N.
        u_guess : array_like, shape (N,)
            Initial input guess.
        x_guess : array_like, shape (N+1, nx), optional
            Initial state guess; default: roll the model out under ``u_guess``. Unused by
            the condensed RTI step, which rolls out itself.
        u_ff : array_like, shape (N,), optional
            Feed-forward inputs that ``r_input`` pulls towards (default ``u_guess``).
        """
        N, nx = self.settings.horizon, self.model.nx
        u_guess = np.clip(np.asarray(u_guess, float).ravel(), self.u_min, self.u_max)
        u_ff = u_guess if u_ff is None else np.asarray(u_ff, float).ravel()
        p = np.concatenate((np.asarray(x0, float).ravel(), np.asarray(d, float).ravel(), [u_prev],
                            np.asarray(ref, float).ravel(), u_ff))
        if self.condensed:  # backtracking keeps feasibility only from a feasible start
            w0 = feasible_guess(u_guess, u_prev, self.u_min, self.u_max, self.du_max)
        else:
            if x_guess is None:
                x_guess = self.model.rollout(x0, u_guess, d)
            w0 = np.concatenate((np.asarray(x_guess, float).ravel(), u_guess))
        if self._solver is None:  # RTI: rti_iterations Gauss–Newton steps from the warm start
            start = time.perf_counter()
            w, qp_error = rti_steps(self.rti, w0, p, self.settings.rti_iterations)
            elapsed = time.perf_counter() - start
            finite = bool(np.all(np.isfinite(w)))
            ok = finite and qp_error <= QP_TOLERANCE
            if self.condensed:
                x_plan = np.asarray(self.rollout(w, p)) if finite else np.full((N + 1, nx), np.nan)
                w = np.concatenate((x_plan.ravel(), w))
            status = "RTI_Step" if ok else ("RTI_Non_Finite" if not finite else "RTI_QP_Failed")
            return NmpcStep(u_plan=w[self._n_shoot:].reshape(N, 1), x_plan=w[: self._n_shoot].reshape(N + 1, nx),
                            success=ok, status=status,
                            iterations=self.settings.rti_iterations,
                            solve_time=elapsed)
        args = {"x0": w0, "p": p, "lbx": self._lbx, "ubx": self._ubx, "lbg": self._lbg, "ubg": self._ubg}
        if self.settings.warm_multipliers and self._lam is not None and x_guess is not None:
            args["lam_x0"], args["lam_g0"] = self._lam
        start = time.perf_counter()
        sol = self._solver(**args)
        elapsed = time.perf_counter() - start
        stats = self._solver.stats()
        w = np.asarray(sol["x"]).ravel()
        x_plan = w[: self._n_shoot].reshape(N + 1, nx)
        u_plan = w[self._n_shoot:].reshape(N, 1)
        success = bool(stats.get("success", False)) and bool(np.all(np.isfinite(w)))
        self._lam = (np.asarray(sol["lam_x"]).ravel(), np.asarray(sol["lam_g"]).ravel()) if success else None
        return NmpcStep(u_plan=u_plan, x_plan=x_plan, success=success,
                        status=str(stats.get("return_status", "")),
                        iterations=int(stats.get("iter_count", -1)), solve_time=elapsed)
