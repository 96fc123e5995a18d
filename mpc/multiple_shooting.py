"""Multiple-shooting tracking problem built on a :class:`hystmpc.models.prediction.PredictionModel`."""

from __future__ import annotations

import casadi as ca
import numpy as np

from hystmpc.models.prediction import PredictionModel
from hystmpc.mpc.problem import Solution, TrackingProblem
from hystmpc.mpc.rti import REGULARISATION, gauss_newton_step, rti_function
from hystmpc.mpc.settings import InputBounds, NmpcSettings, SolverSettings

STRAIGHT_LINE_CONDENSING_LIMIT = 40_000
"""Most operations of the straight-line condensing (:func:`condensing_function`): beyond, the
C and its compile grow too long (pam's 17,461 operations: 575 kB of C, 11 s to compile; they grow
as N² × the nonzeros of ``A`` for the propagation plus N³/6 for ``JᵀJ``), and the sensitivities
are propagated as matrix products."""


class MultipleShootingProblem(TrackingProblem):
    """Minimise Σ q (y_k − r_k)² + r_rate Δu² + r_input (u − u_ff)² over states and inputs.

    Subject to ``x_{k+1} = F(x_k, u_k, d)``, the input bounds and ``|u_k − u_{k−1}| <= rate``
    (with ``u_{−1}`` the input applied last sample). The condition is ``[x0; d]``.

    Parameters
    ----------
    model : PredictionModel
        Nominal discrete-time model.
    settings : NmpcSettings
        Horizon, weights, solver.
    bounds : InputBounds
        Input bounds and largest input change per sample (scalar input).
    solvers : SolverSettings
        Settings of every solver (``solver.gn`` does not apply: single shooting only).
    """

    multiple_shooting = True

    def __init__(self, model: PredictionModel, settings: NmpcSettings, bounds: InputBounds,
                 solvers: SolverSettings | None = None):
        if model.nu != 1:
            raise ValueError(f"only scalar inputs are supported, model has nu={model.nu}")
        if settings.solver == "gn":
            raise ValueError("solver 'gn' is only available for single-shooting problems; "
                             "allowed here: ipopt, sqp, rti, rti-c")
        super().__init__(settings, bounds, solvers or SolverSettings(), model.nx + model.nd)
        self.model = model
        self.condensed = settings.solver in ("rti", "rti-c") and self.solvers.rti.condensed
        if settings.solver in ("rti", "rti-c"):
            self.solvers.rti.check_step(self.condensed)
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
        w = ca.vertcat(ca.vec(X), ca.vec(U))
        g = ca.vertcat(*shooting, *rates)
        p = ca.vertcat(x0, d, u_prev, ref, u_ff)
        self.residual = ca.Function("nmpc_residual", [w, p], [residual], ["w", "p"], ["r"])
        self.constraints = ca.Function("nmpc_constraints", [w, p], [g], ["w", "p"], ["g"])
        n_shoot = nx * (N + 1)
        self._lbg = np.concatenate((np.zeros(n_shoot), -self.du_max * np.ones(N)))
        self._ubg = np.concatenate((np.zeros(n_shoot), self.du_max * np.ones(N)))
        self._lbx = np.concatenate((-np.inf * np.ones(n_shoot), self.u_min * np.ones(N)))
        self._ubx = np.concatenate((np.inf * np.ones(n_shoot), self.u_max * np.ones(N)))
        self._n_shoot = n_shoot
        if s.solver in ("ipopt", "sqp"):
            self._uses_nlp_solver({"x": w, "f": ca.sumsqr(residual), "g": g, "p": p})
            return
        if self.condensed:
            self.rti = self._condensed_rti(p)
        else:  # the shooting gaps are equalities and the states unbounded: qrqp
            self.rti = rti_function(self.residual, self.constraints, self._lbg, self._ubg, self._lbx, self._ubx)
        self._compile_rti()

    def _condensed_rti(self, p: ca.SX) -> ca.Function:
        """The RTI step over the inputs only: the states come from a rollout from x0.

        With no state constraints in this problem, eliminating the states leaves only the
        input bounds and the rate bounds, which are linear in U. A shortened Gauss–Newton
        step then stays feasible, so the step can backtrack on the cost (``step_lengths``).
        The QP goes to ``solver.rti.qp``: DAQP (the default) or the interior-point solver of
        :mod:`hystmpc.mpc.qp` (qrqp gets some of these QPs wrong).
        """
        m, s = self.model, self.settings
        N, nx, nd = s.horizon, m.nx, m.nd
        U = ca.SX.sym("U", N)
        x0, d = p[:nx], p[nx: nx + nd]
        x, states = x0, [x0]
        for k in range(N):
            x = m.step(x, U[k], d)
            states.append(x)
        self.rollout = ca.Function("nmpc_rollout", [U, p], [ca.horzcat(*states).T])
        n_rates = N if np.isfinite(self.du_max) else 0  # no rate rows for an unbounded rate
        lower = np.concatenate((self.u_min * np.ones(N), -self.du_max * np.ones(n_rates)))
        upper = np.concatenate((self.u_max * np.ones(N), self.du_max * np.ones(n_rates)))
        linearise, self.rti_cost, self.rti_outcome = self._condensed_linearisation(p.numel(), n_rates)
        rti = self.solvers.rti
        return gauss_newton_step(linearise, self.rti_cost, lower, upper, step_lengths=(0.5, 0.25, 0.125), qp=rti.qp,
                                 qp_iterations=rti.qp_iterations, line_search=rti.line_search)

    def _condensed_linearisation(self, n_p: int, n_rates: int) -> tuple[ca.Function, ca.Function, ca.Function]:
        """The condensed problem's ``linearise``, ``cost`` and ``outcome`` Functions.

        ``linearise(U, p) -> (H, Jᵀr, A, g, Σ r²)``, ``cost(U, p)`` and ``outcome(U, p) -> (cost,
        y_N − r_N)``.

        Built from one model step and its Jacobians, called once per predicted sample, with
        the output sensitivities to the inputs propagated forward (``S_{k+1} = A_k S_k``,
        plus ``B_k`` as the newest column). By default the propagation and ``JᵀJ`` are one
        straight-line function of the Jacobians (:func:`condensing_function`), whose products
        skip the structural zeros of ``A_k``, ``B_k`` and ``C_k`` with no index loops. Beyond
        :data:`STRAIGHT_LINE_CONDENSING_LIMIT` operations, or with ``solver.rti.sensitivity_block``
        > 0 (padded to a few sizes, for less RAM), they are CasADi's sparse matrix products
        instead. All give the same numbers. Differentiating the unrolled
        rollout instead gives them too but one expression of the model per entry of J: far
        more C and a far longer compile (docs/realtime.md).
        """
        m, s = self.model, self.settings
        N, nx, nd = s.horizon, m.nx, m.nd
        x_s, u_s, d_s = ca.SX.sym("x", nx), ca.SX.sym("u"), ca.SX.sym("d", nd)
        x_next = m.step(x_s, u_s, d_s)
        y_next = m.output(x_next, d_s)
        step = ca.Function("model_step", [x_s, u_s, d_s], [x_next, y_next])
        output_jacobian = ca.Function("output_jacobian", [x_s, d_s], [ca.jacobian(m.output(x_s, d_s), x_s)])
        step_linear = ca.Function("model_step_linear", [x_s, u_s, d_s],
                                  [x_next, y_next, ca.jacobian(x_next, x_s), ca.jacobian(x_next, u_s),
                                   output_jacobian(x_next, d_s)])
        U, p = ca.MX.sym("U", N), ca.MX.sym("p", n_p)
        x0, d, u_prev = p[:nx], p[nx: nx + nd], p[nx + nd]
        ref, u_ff = p[nx + nd + 1: nx + nd + 1 + N], p[nx + nd + 1 + N:]
        # constant parts: the rate and input residuals are linear in U
        D = ca.sparsify(ca.DM(np.eye(N) - np.eye(N, k=-1)))
        du = D @ U - ca.vertcat(u_prev, ca.DM.zeros(N - 1))
        H_const = s.r_rate * (D.T @ D) + (s.r_input + REGULARISATION) * ca.DM.eye(N)
        grad = s.r_rate * (D.T @ du) + s.r_input * (U - u_ff)
        x, errors, jacobians = x0, [], []
        for k in range(N):
            x, y, A, B, Cy = step_linear(x, U[k], d)
            errors.append(y - ref[k])
            jacobians.append((A, B, Cy))
        e = ca.vertcat(*errors)
        sparsities = [step_linear.sparsity_out(i) for i in (2, 3, 4)]
        # a rough count first (it overestimates): a far larger function is not worth building to count it
        rough = N * N * sparsities[0].nnz() + N ** 3 / 3
        straight = not self.solvers.rti.sensitivity_block and rough <= 3 * STRAIGHT_LINE_CONDENSING_LIMIT
        condense = condensing_function(*sparsities, N) if straight else None
        if condense is not None and condense.n_instructions() <= STRAIGHT_LINE_CONDENSING_LIMIT:
            JtJ, Jte = condense(*(J for stage in jacobians for J in stage), e)
        else:
            Jy = _propagated_sensitivities(jacobians, self.solvers.rti.sensitivity_block)
            JtJ, Jte = Jy.T @ Jy, Jy.T @ e
        H = s.q_output * JtJ + H_const
        grad = grad + s.q_output * Jte
        rates = du[:n_rates]
        A_rates = D[:n_rates, :]
        x, cost = x0, s.r_rate * ca.sumsqr(du) + s.r_input * ca.sumsqr(U - u_ff)
        linearise = ca.Function("rti_linearise", [U, p], [H, grad, ca.MX(A_rates), rates,
                                                          cost + s.q_output * ca.sumsqr(e)])
        for k in range(N):
            x, y = step(x, U[k], d)
            cost += s.q_output * (y - ref[k]) ** 2
        return (linearise, ca.Function("rti_cost", [U, p], [cost]),
                ca.Function("rti_outcome", [U, p], [cost, y - ref[N - 1]]))

    def solve(self, condition, u_prev: float, ref, u_guess, x_guess=None, u_ff=None) -> Solution:
        """Solve the NLP from ``condition = [x0; d]`` for the references ``ref[0..N-1]`` = r_{k+1..k+N}.

        Parameters
        ----------
        condition : array_like, shape (nx + nd,)
            Current state estimate and disturbance estimate (held over the horizon).
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

        Returns
        -------
        Solution
            The plan, with the predicted states (a condensed RTI step rolls them out from the
            planned inputs; NaN when they are not finite).
        """
        N, nx = self.horizon, self.model.nx
        condition = np.asarray(condition, float).ravel()
        x0, d = condition[:nx], condition[nx:]
        u_guess = np.clip(np.asarray(u_guess, float).ravel(), self.u_min, self.u_max)
        u_ff = u_guess if u_ff is None else np.asarray(u_ff, float).ravel()
        p = self._parameters(condition, u_prev, ref, u_ff)
        if self.condensed:  # backtracking keeps feasibility only from a feasible start
            w0 = self.feasible_start(u_guess, u_prev)
        else:
            x_start = self.model.rollout(x0, u_guess, d) if x_guess is None else x_guess
            w0 = np.concatenate((np.asarray(x_start, float).ravel(), u_guess))
        if self.rti is not None:
            def finish(w, finite):
                if self.condensed:
                    x_plan = np.asarray(self.rollout(w, p)) if finite else np.full((N + 1, nx), np.nan)
                    return w.reshape(N, 1), x_plan
                return w[self._n_shoot:].reshape(N, 1), w[: self._n_shoot].reshape(N + 1, nx)
            return self._solve_rti(w0, p, finish)
        args = {"x0": w0, "p": p, "lbx": self._lbx, "ubx": self._ubx, "lbg": self._lbg, "ubg": self._ubg}
        w, success, status, iterations, elapsed = self._solve_nlp(args, warm=x_guess is not None)
        return Solution(u_plan=w[self._n_shoot:].reshape(N, 1), x_plan=w[: self._n_shoot].reshape(N + 1, nx),
                        success=success, status=status, iterations=iterations, solve_time=elapsed)


def condensing_function(A_sparsity: ca.Sparsity, B_sparsity: ca.Sparsity, C_sparsity: ca.Sparsity,
                        horizon: int) -> ca.Function:
    """``condense(A_0, B_0, C_0, …, A_{N−1}, B_{N−1}, C_{N−1}, e) -> (JᵀJ, Jᵀe)`` as straight-line SX.

    ``J`` holds the outputs' sensitivities to the inputs, row ``k`` being ``C_k S_k`` with
    ``S_0 = B_0`` and ``S_k = [A_k S_{k−1}, B_k]``: ``A_k``, ``B_k`` are the model step's
    Jacobians to the state and the input at sample ``k``, ``C_k`` the output's Jacobian at the
    state it reaches. The products are expanded entry by entry at build time, so only the
    structural nonzeros of the given sparsities cost operations; ``JᵀJ`` is computed on its
    lower triangle and mirrored.

    Parameters
    ----------
    A_sparsity, B_sparsity, C_sparsity : casadi.Sparsity
        Sparsities of ``A_k`` (nx × nx), ``B_k`` (nx × 1) and ``C_k`` (1 × nx).
    horizon : int
        ``N``.

    Returns
    -------
    casadi.Function
        ``condense``; ``e`` has ``N`` entries.
    """
    N = horizon
    inputs, S, rows = [], None, []
    for k in range(N):
        A, B, C = (ca.SX.sym(f"{name}_{k}", sparsity)
                   for name, sparsity in (("A", A_sparsity), ("B", B_sparsity), ("C", C_sparsity)))
        inputs += [A, B, C]
        S = B if S is None else ca.horzcat(A @ S, B)
        rows.append(ca.horzcat(C @ S, ca.SX(1, N - S.size2())))
    e = ca.SX.sym("e", N)
    J = ca.vertcat(*rows)
    names = [f"{name}_{k}" for k in range(N) for name in "ABC"]
    return ca.Function("condense", [*inputs, e], [ca.tril2symm(ca.tril(J.T @ J)), J.T @ e], [*names, "e"],
                       ["JtJ", "Jte"])


def _propagated_sensitivities(jacobians, block: int) -> ca.MX:
    """``J`` (N × N) from the stages' ``(A_k, B_k, C_k)`` as matrix products (see :func:`condensing_function`).

    With ``block`` > 0 the sensitivities are padded with exact zeros to a multiple of ``block``
    columns: CasADi reuses a work slot only for a value of the same size.
    """
    N = len(jacobians)
    S, rows = None, []
    for k, (A, B, C) in enumerate(jacobians):
        if block:
            width = min(N, -(-(k + 1) // block) * block)
            if S is not None and S.size2() < width:
                S = ca.horzcat(S, ca.DM.zeros(S.size1(), width - S.size2()))
            newest = B @ ca.DM(ca.Sparsity.triplet(1, width, [0], [k]), 1.0)  # B in column k
            S = ca.densify(newest if S is None else A @ S + newest)
        else:
            S = B if S is None else ca.horzcat(A @ S, B)
        rows.append(ca.horzcat(C @ S, ca.MX(1, N - S.size2())))
    return ca.vertcat(*rows)
