"""What the multiple- and single-shooting tracking problems share: solvers, solves, results.

Both minimise ``Σ q (y_k − r_k)² + r_rate Δu_k² + r_input (u_k − u_ff,k)²`` subject to the
input bounds and the rate bound. Their parameter vector is laid out the same way:
``p = [condition, u_prev, ref_1..ref_N, u_ff_1..u_ff_N]``, where ``condition`` is what the
estimator hands over (the multiple-shooting problem's ``[x0; d]``, the single-shooting
problem's prediction parameters) — :meth:`TrackingProblem.parameter_layout` names the parts.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import casadi as ca
import numpy as np

from hystmpc.mpc.codegen.toolchain import compiled_or_in_process
from hystmpc.mpc.rti import QP_TOLERANCE, feasible_guess, rti_steps
from hystmpc.mpc.settings import InputBounds, NlpSettings, NmpcSettings, SolverSettings


@dataclass
class Solution:
    """Result of one solve of a tracking problem."""

    u_plan: np.ndarray
    """Optimal inputs over the horizon, shape (N, 1)."""
    x_plan: np.ndarray | None
    """Predicted states, shape (N+1, nx), for multiple-shooting problems; None otherwise."""
    success: bool
    """Whether the solver reported convergence (and every value is finite)."""
    status: str
    """Solver's return status."""
    iterations: int
    """Solver iterations."""
    solve_time: float
    """Wall-clock time of the solve (s)."""
    cost: float = float("nan")
    """The objective at ``u_plan``, where the solver reports it (``gn``; the RTI step with ``multistart``)."""
    end_error: float = float("nan")
    """The planned output's error at the horizon's end, ``y_N − r_N``, where the solver reports
    the cost."""


def nlp_solver(name: str, nlp: dict, solver: str, settings: NlpSettings) -> ca.Function:
    """IPOPT or sqpmethod + qrqp for ``nlp``, quiet, with the settings and pass-through options.

    Parameters
    ----------
    name : str
        Name of the solver Function.
    nlp : dict
        The NLP as ``casadi.nlpsol`` takes it (``x``, ``f``, ``g``, ``p``).
    solver : str
        ``ipopt`` for IPOPT, anything else for sqpmethod + qrqp.
    settings : NlpSettings
        Iteration limit, tolerance, warm multipliers (IPOPT) and pass-through options.

    Returns
    -------
    casadi.Function
        The solver.

    Raises
    ------
    ValueError
        Naming an option the solver does not know.
    """
    s = settings
    if solver == "ipopt":
        opts = {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes", "ipopt.max_iter": s.max_iter,
                "ipopt.tol": s.tol, "ipopt.acceptable_tol": 1e3 * s.tol, "record_time": True}
        if s.warm_multipliers:
            opts.update({"ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-4,
                         "ipopt.warm_start_bound_push": 1e-6, "ipopt.warm_start_mult_bound_push": 1e-6})
        opts.update({f"ipopt.{k}": v for k, v in s.options.items()})
    else:
        opts = {"qpsol": "qrqp", "qpsol_options": {"print_iter": False, "print_header": False,
                                                   "error_on_fail": False},
                "max_iter": s.max_iter, "tol_du": s.tol, "tol_pr": s.tol, "print_header": False,
                "print_iteration": False, "print_status": False, "print_time": False,
                "record_time": True, "error_on_fail": False}
        opts.update(s.options)
    try:
        return ca.nlpsol(name, "ipopt" if solver == "ipopt" else "sqpmethod", nlp, opts)
    except RuntimeError as exc:  # keep the line that names the option, without CasADi's source location
        lines = [line for line in str(exc).splitlines() if "option" in line.lower()] or str(exc).splitlines()
        raise ValueError(f"solver.{solver}.options: {lines[0].split(': ', 1)[-1].strip()}") from None


class TrackingProblem:
    """Base of :class:`MultipleShootingProblem` and :class:`SingleShootingProblem`.

    Parameters
    ----------
    settings : NmpcSettings
        Horizon, weights, solver variant.
    bounds : InputBounds
        Input bounds and rate bound (scalar input).
    solvers : SolverSettings
        Settings of every solver; the one ``settings.solver`` names is used.
    n_condition : int
        Length of the condition part of ``p``.
    """

    multiple_shooting = False

    def __init__(self, settings: NmpcSettings, bounds: InputBounds, solvers: SolverSettings, n_condition: int):
        self.settings, self.bounds, self.solvers = settings, bounds, solvers
        self.u_min, self.u_max, self.du_max = float(bounds.lower), float(bounds.upper), float(bounds.rate)
        self.n_condition = n_condition
        self.rti: ca.Function | None = None
        self.rti_cost: ca.Function | None = None
        """``(w, p) -> Σ r²`` of the RTI step's problem, where it has one (single shooting, condensed
        multiple shooting)."""
        self.rti_outcome: ca.Function | None = None
        """``(w, p) -> (Σ r², y_N − r_N)``: the cost and the error where the plan ends, with
        ``rti_cost`` (``multistart`` tests both)."""
        self._solver: ca.Function | None = None
        self._lam = None

    @property
    def horizon(self) -> int:
        """Prediction horizon N."""
        return self.settings.horizon

    def parameter_layout(self) -> dict[str, slice]:
        """Where each part of the parameter vector ``p`` sits.

        Returns
        -------
        dict
            ``condition``, ``u_prev``, ``ref`` and ``u_ff``, each a slice of ``p``.
        """
        n, N = self.n_condition, self.horizon
        return {"condition": slice(0, n), "u_prev": slice(n, n + 1), "ref": slice(n + 1, n + 1 + N),
                "u_ff": slice(n + 1 + N, n + 1 + 2 * N)}

    def _parameters(self, condition, u_prev: float, ref, u_ff) -> np.ndarray:
        return np.concatenate((np.asarray(condition, float).ravel(), [u_prev], np.asarray(ref, float).ravel(),
                               np.asarray(u_ff, float).ravel()))

    def _uses_nlp_solver(self, nlp: dict) -> None:
        solver = self.settings.solver
        self._solver = nlp_solver("nmpc", nlp, solver, getattr(self.solvers, solver))

    def _compile_rti(self) -> None:
        """``rti-c``: the RTI step compiled (and, with ``multistart``, the cost it compares)."""
        if self.settings.solver != "rti-c":
            return
        self.rti, self.compiled = compiled_or_in_process(self.rti)
        if self.settings.multistart and self.rti_cost is not None:
            self.rti_cost = compiled_or_in_process(self.rti_cost)[0]
            self.rti_outcome = compiled_or_in_process(self.rti_outcome)[0]

    def _solve_rti(self, w0, p, finish) -> Solution:
        """``rti.iterations`` RTI steps from ``w0`` (one more if the last did not settle).

        ``finish(w, finite)`` -> (u_plan, x_plan).
        """
        rti = self.solvers.rti
        start = time.perf_counter()
        w, qp_error, iterations = rti_steps(self.rti, w0, p, rti.iterations, rti.extra_step_tolerance)
        finite = bool(np.all(np.isfinite(w)))
        cost = end_error = float("nan")
        if self.settings.multistart and self.rti_outcome is not None and finite:  # the cost picks between two plans
            cost, end_error = (float(value) for value in self.rti_outcome(w, p))
        elapsed = time.perf_counter() - start
        ok = finite and qp_error <= QP_TOLERANCE
        u_plan, x_plan = finish(w, finite)
        status = "RTI_Step" if ok else ("RTI_Non_Finite" if not finite else "RTI_QP_Failed")
        return Solution(u_plan=u_plan, x_plan=x_plan, success=ok, status=status, iterations=iterations,
                        solve_time=elapsed, cost=cost, end_error=end_error)

    def _solve_nlp(self, args: dict, warm: bool) -> tuple[np.ndarray, bool, str, int, float]:
        """One IPOPT/sqpmethod solve; returns the solution vector, success, status, iterations, time."""
        nlp_settings: NlpSettings = getattr(self.solvers, self.settings.solver)
        if nlp_settings.warm_multipliers and self._lam is not None and warm:
            args["lam_x0"], args["lam_g0"] = self._lam
        start = time.perf_counter()
        sol = self._solver(**args)
        elapsed = time.perf_counter() - start
        stats = self._solver.stats()
        w = np.asarray(sol["x"]).ravel()
        success = bool(stats.get("success", False)) and bool(np.all(np.isfinite(w)))
        self._lam = (np.asarray(sol["lam_x"]).ravel(), np.asarray(sol["lam_g"]).ravel()) if success else None
        return w, success, str(stats.get("return_status", "")), int(stats.get("iter_count", -1)), elapsed

    def feasible_start(self, u_guess, u_prev: float) -> np.ndarray:
        """The guess made input- and rate-feasible (backtracking RTI steps need that).

        Parameters
        ----------
        u_guess : array_like
            The guessed inputs.
        u_prev : float
            Input applied in the previous sample.

        Returns
        -------
        ndarray
            The feasible inputs (:func:`hystmpc.mpc.rti.feasible_guess`).
        """
        return feasible_guess(u_guess, u_prev, self.u_min, self.u_max, self.du_max)

    def solve(self, condition, u_prev: float, ref, u_guess, x_guess=None, u_ff=None) -> Solution:
        """Solve for the references ``ref`` (r_{k+1..k+N}) from ``condition``.

        Parameters
        ----------
        condition : array_like
            What the estimator hands over (the part ``condition`` of ``p``).
        u_prev : float
            Input applied in the previous sample (for the rate bound).
        ref : array_like, shape (N,)
            Output references for the predicted samples 1..N.
        u_guess : array_like, shape (N,)
            Initial input guess.
        x_guess : array_like, optional
            Initial state guess, for problems with states as unknowns.
        u_ff : array_like, shape (N,), optional
            Feed-forward inputs that ``r_input`` pulls towards (default ``u_guess``).

        Returns
        -------
        Solution
            The plan and the solver's report.
        """
        raise NotImplementedError
