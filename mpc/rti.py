"""Real-time iteration: one Gauss–Newton SQP step per sample, as a single CasADi Function.

The tracking cost of :mod:`hystmpc.mpc.problem` is a sum of squares, ``Σ ‖r(w, p)‖²``, so the
Gauss–Newton Hessian ``JᵀJ`` is positive semidefinite and needs no convexification. One
step linearises the shooting and rate constraints at the warm start ``w``, solves the QP
(DAQP, qrqp or the interior-point QP of :mod:`hystmpc.mpc.qp`), and returns ``w + Δw``.
Wrapped as one Function ``rti_step(w, p) -> w_next``, the whole step can be code-generated
and compiled (:func:`hystmpc.mpc.codegen.compile_function`), which is the ``rti-c`` variant.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from hystmpc.mpc.settings import LINE_SEARCHES

QP_SOLVERS = ("qrqp", "daqp", "ipm")
"""QP solvers of the Gauss–Newton step (:func:`gauss_newton_step`)."""

REGULARISATION = 1e-8
"""Added to the diagonal of JᵀJ: states enter the cost only through constraints."""


def rti_function(residual: ca.Function, constraints: ca.Function, lbg, ubg, lbx, ubx,
                 name: str = "rti_step", step_lengths: tuple[float, ...] = (), qp: str = "qrqp",
                 qp_iterations: int = 30, line_search: str = "best") -> ca.Function:
    """Build ``rti_step(w, p) -> (w_next, qp_error)`` from the NLP's residual and constraints.

    Parameters
    ----------
    residual : casadi.Function
        ``(w, p) -> r`` with cost ``Σ r²`` (SX).
    constraints : casadi.Function
        ``(w, p) -> g`` with ``lbg <= g <= ubg`` (SX).
    lbg, ubg, lbx, ubx : array_like
        Constraint and variable bounds (constants baked into the function).
    name : str, optional
        Name of the Function (and prefix of its QP solver's).
    step_lengths : tuple of float, optional
        If given, the step taken is the one of ``1`` and these fractions with the lowest cost
        (a fixed backtracking, code-generatable). Only sound where every constraint is
        convex in ``w``, so that a shortened QP step stays feasible: single shooting with
        linear constraints, not multiple shooting.
    line_search : {"best", "descent"}
        With ``step_lengths``: ``best`` evaluates the cost at every step length; ``descent``
        takes the full step without trying the others when it does not raise the cost (a
        converged plan's zero step included); generated code computes the shorter steps'
        costs only when it does.
    qp : {"qrqp", "daqp", "ipm"}
        ``qrqp``: CasADi's active-set solver (any bounds; wrong on some problems with
        inequality rows, see :mod:`hystmpc.mpc.qp`). ``daqp``: DAQP, a dual active-set
        solver for small dense QPs (through CasADi; the generated C calls the DAQP library
        that CasADi ships). ``ipm``: :func:`hystmpc.mpc.qp.interior_point_qp` with
        ``qp_iterations`` iterations (all bounds finite).
    qp_iterations : int, optional
        Iterations of the ``ipm`` QP.

    Returns
    -------
    casadi.Function
        ``rti_step(w, p) -> (w_next, qp_error)``. The second output, ``qp_error``, says how far
        the QP answer is from trustworthy: for ``ipm`` its final residual, for ``qrqp`` the
        largest constraint violation of its answer, each row's divided by the larger of its
        half width and 1, for ``daqp`` the larger of that violation and the relative
        stationarity residual. Callers count a step above :data:`QP_TOLERANCE` as a failed
        solve.
    """
    lower = np.concatenate((np.ravel(lbx), np.ravel(lbg))).astype(float)
    upper = np.concatenate((np.ravel(ubx), np.ravel(ubg))).astype(float)
    w_sx = ca.SX.sym("w", residual.size1_in(0))
    p_sx = ca.SX.sym("p", residual.size1_in(1))
    n = w_sx.numel()
    r = residual(w_sx, p_sx)
    g = constraints(w_sx, p_sx)
    J = ca.jacobian(r, w_sx)
    H = ca.mtimes(J.T, J) + REGULARISATION * ca.SX.eye(n)
    linearise = ca.Function("rti_linearise", [w_sx, p_sx],
                            [H, ca.mtimes(J.T, r), ca.jacobian(g, w_sx), g, ca.sumsqr(r)])
    cost = ca.Function("rti_cost", [w_sx, p_sx], [ca.sumsqr(r)])
    return gauss_newton_step(linearise, cost, lower, upper, name, step_lengths, qp, qp_iterations, line_search)


def gauss_newton_step(linearise: ca.Function, cost: ca.Function, lower, upper, name: str = "rti_step",
                      step_lengths: tuple[float, ...] = (), qp: str = "qrqp", qp_iterations: int = 30,
                      line_search: str = "best") -> ca.Function:
    """``rti_step(w, p) -> (w_next, qp_error)`` from a linearisation and a cost.

    Parameters
    ----------
    linearise : casadi.Function
        ``linearise(w, p) -> (H, Jᵀr, A, g[, Σ r²])``: the Gauss–Newton Hessian (regularised),
        the gradient, the constraints ``g`` with their Jacobian ``A``, and the cost at ``w``
        (read by ``line_search='descent'`` only).
    cost : casadi.Function
        ``cost(w, p)``, ``Σ r²`` (used by ``step_lengths`` only).
    lower, upper : array_like
        Bounds of ``[w; g]``.
    name : str, optional
        As in :func:`rti_function`.
    step_lengths : tuple of float, optional
        As in :func:`rti_function`.
    qp : {"qrqp", "daqp", "ipm"}
        As in :func:`rti_function`.
    qp_iterations : int, optional
        As in :func:`rti_function`.
    line_search : {"best", "descent"}
        As in :func:`rti_function`.

    Returns
    -------
    casadi.Function
        ``rti_step(w, p) -> (w_next, qp_error)``, as :func:`rti_function` returns.

    Raises
    ------
    ValueError
        For an unknown ``line_search`` or ``qp``, ``descent`` without the cost output of
        ``linearise``, or ``ipm`` without finite bounds ``lower < upper``.
    """
    if line_search not in LINE_SEARCHES:
        raise ValueError(f"line_search {line_search!r} is unknown; allowed: {', '.join(LINE_SEARCHES)}")
    if step_lengths and line_search == "descent" and linearise.n_out() < 5:
        raise ValueError("line_search 'descent' needs the cost at w as linearise's fifth output")
    if qp not in QP_SOLVERS:
        raise ValueError(f"qp {qp!r} is unknown; allowed: {', '.join(QP_SOLVERS)}")
    n = linearise.size1_in(0)
    w = ca.MX.sym("w", n)
    p = ca.MX.sym("p", linearise.size1_in(1))
    H_mx, grad, A_mx, g_mx, *current_cost = linearise(w, p)
    C = ca.vertcat(ca.MX(ca.DM.eye(n)), A_mx)
    l_mx = ca.DM(lower) - ca.vertcat(w, g_mx)
    u_mx = ca.DM(upper) - ca.vertcat(w, g_mx)
    if qp == "ipm":
        if not (np.all(np.isfinite(lower)) and np.all(np.isfinite(upper)) and np.all(lower < upper)):
            raise ValueError("qp 'ipm' needs finite bounds with lower < upper on every variable and constraint")
        from hystmpc.mpc.qp import interior_point_qp
        solver = interior_point_qp(linearise.sparsity_out(0), C.sparsity(), qp_iterations)
        step, qp_error, _ = solver(H_mx, grad, C, l_mx, u_mx)
    elif qp == "daqp":
        solver = ca.conic(f"{name}_qp", "daqp", {"h": linearise.sparsity_out(0), "a": linearise.sparsity_out(2)},
                          {"error_on_fail": False})
        solution = solver(h=H_mx, g=grad, a=A_mx, lba=l_mx[n:], uba=u_mx[n:], lbx=l_mx[:n], ubx=u_mx[:n])
        step = solution["x"]
        # DAQP's iterates are dual feasible: one that stopped short violates a constraint
        qp_error = ca.fmax(_constraint_violation(C @ step, l_mx, u_mx, lower, upper),
                           _stationarity(H_mx, grad, A_mx, step, solution["lam_x"], solution["lam_a"]))
        # false for a NaN or infinite entry, which fmax and mmax would hide
        finite = ca.sum1(ca.fabs(ca.vertcat(step, solution["lam_x"], solution["lam_a"]))) < ca.inf
        qp_error = ca.if_else(finite, qp_error, ca.inf)
    else:
        solver = ca.conic(f"{name}_qp", "qrqp", {"h": linearise.sparsity_out(0), "a": linearise.sparsity_out(2)},
                          {"print_iter": False, "print_header": False, "error_on_fail": False})
        step = solver(h=H_mx, g=grad, a=A_mx, lba=l_mx[n:], uba=u_mx[n:], lbx=l_mx[:n], ubx=u_mx[:n])["x"]
        qp_error = _constraint_violation(C @ step, l_mx, u_mx, lower, upper)
    w_next = w + step
    if step_lengths:
        full_cost = cost(w_next, p)
        if line_search == "best":
            w_next = _lowest_cost_step(cost, w, step, p, w_next, full_cost, step_lengths)
        else:  # a switch, not an if_else: the shorter steps' costs are computed only when needed
            ws, steps, ps, costs = ca.MX.sym("w", n), ca.MX.sym("step", n), ca.MX.sym("p", p.numel()), ca.MX.sym("c")
            args = [ws, steps, ps, costs]
            switch = ca.Function.if_else(
                f"{name}_line_search", ca.Function("full_step", args, [ws + steps]),
                ca.Function("backtracking", args,
                            [_lowest_cost_step(cost, ws, steps, ps, ws + steps, costs, step_lengths)]))
            keep = ca.logic_and(full_cost <= current_cost[0], full_cost < ca.inf)  # inf <= inf: backtrack
            w_next = switch(keep, w, step, p, full_cost)
    return ca.Function(name, [w, p], [w_next, qp_error], ["w", "p"], ["w_next", "qp_error"])


def _lowest_cost_step(cost: ca.Function, w, step, p, full, full_cost, step_lengths: tuple[float, ...]):
    """The lowest-cost one of ``full = w + step`` and ``w + t step`` for each step length ``t``.

    The cost of ``full`` is ``full_cost``; any cost beats a NaN or infinite one.
    """
    w_next, best_cost = full, full_cost
    for t in step_lengths:
        trial = w + t * step
        trial_cost = cost(trial, p)
        better = ca.logic_or(trial_cost < best_cost, ca.logic_not(best_cost < ca.inf))  # x != x would fold away
        w_next = ca.if_else(better, trial, w_next)
        best_cost = ca.if_else(better, trial_cost, best_cost)
    return w_next


def _stationarity(H, g, A, x, lam_x, lam_a):
    """Largest entry of ``Hx + g + λx + Aᵀλa``, relative to the largest of the terms and 1.

    The expression is zero at a KKT point (CasADi's sign convention).
    """
    Hx, A_lam = H @ x, A.T @ lam_a
    size = ca.fmax(1.0, ca.mmax(ca.fabs(ca.vertcat(Hx, g, lam_x, A_lam))))
    return ca.mmax(ca.fabs(Hx + g + lam_x + A_lam)) / size


def _constraint_violation(Cx, l_mx, u_mx, lower, upper):
    """Largest violation of ``l <= Cx <= u`` over the finite bounds.

    Each row's is divided by the larger of its half width and 1.
    """
    parts = [ca.MX(0)]
    width = np.where(np.isfinite(upper - lower), np.maximum((upper - lower) / 2, 1.0), 1.0)
    low, up = np.flatnonzero(np.isfinite(lower)), np.flatnonzero(np.isfinite(upper))
    if len(low):
        parts.append((l_mx[low.tolist()] - Cx[low.tolist()]) / ca.DM(width[low]))
    if len(up):
        parts.append((Cx[up.tolist()] - u_mx[up.tolist()]) / ca.DM(width[up]))
    return ca.mmax(ca.vertcat(*parts))


QP_TOLERANCE = 1e-6
"""A step whose ``qp_error`` exceeds this counts as a failed solve."""


def feasible_guess(u_guess, u_prev: float, u_min: float, u_max: float, du_max: float) -> np.ndarray:
    """The guess moved into ``u_min <= u <= u_max``, ``|u_k − u_{k−1}| <= du_max``.

    Each input is clipped in turn to what its predecessor allows.

    The backtracking RTI step takes fractions of the QP step; they stay feasible only when
    the step starts from a feasible point (a convex combination of two feasible points).
    An inverse-model guess after a reference jump is often not rate-feasible.

    Parameters
    ----------
    u_guess : array_like
        The guessed inputs ``u_0..u_{N−1}``.
    u_prev : float
        The input sent last (clipped to the bounds first), the predecessor of ``u_0``.
    u_min, u_max : float
        Input bounds.
    du_max : float
        Largest change per sample (``inf``: none).

    Returns
    -------
    ndarray
        The feasible inputs.
    """
    u = np.clip(np.asarray(u_guess, float).ravel(), u_min, u_max)
    if np.isfinite(du_max):
        last = float(np.clip(u_prev, u_min, u_max))
        for k in range(len(u)):
            u[k] = last = min(max(u[k], last - du_max, u_min), last + du_max, u_max)
    return u


def rti_steps(rti: ca.Function, w0, p, iterations: int,
              extra_step_tolerance: float = np.inf) -> tuple[np.ndarray, float, int]:
    """``iterations`` RTI steps from ``w0``, and one more when the last moved the iterate enough.

    Parameters
    ----------
    rti : casadi.Function
        ``rti_step(w, p) -> (w_next, qp_error)``.
    w0 : array_like
        The first iterate.
    p : array_like
        The step's parameters.
    iterations : int
        Steps to take.
    extra_step_tolerance : float, optional
        One more step when the last moved an entry of the iterate by more than this
        (``inf``: never).

    Returns
    -------
    w : ndarray
        The last iterate.
    worst : float
        The worst ``qp_error`` (NaN if any was; infinite when an iterate is not finite, which
        ends the steps: an in-process QP refuses NaN bounds).
    taken : int
        The steps taken.
    """
    w, worst = np.asarray(w0, float), 0.0
    taken, moved = 0, np.inf
    while taken < iterations or (taken == iterations and moved > extra_step_tolerance):
        w_next, qp_error = rti(w, p)
        w_next, qp_error = np.asarray(w_next).ravel(), float(qp_error)
        moved = float(np.max(np.abs(w_next - w), initial=0.0))
        w, taken = w_next, taken + 1
        if not (qp_error <= worst or np.isnan(worst)):  # larger, or NaN; a NaN stays
            worst = qp_error
        if not np.all(np.isfinite(w)):
            return w, np.inf, taken
    return w, worst, taken
