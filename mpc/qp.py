"""A small dense QP solver as a CasADi expression graph, so it code-generates with the rest.

Why not qrqp: on dense QPs with box and rate (bidiagonal) inequality constraints, CasADi
3.8's qrqp often reports success while violating the constraints (compared on random
problems against ``ipqp`` and OSQP: docs/realtime.md, ``tests/test_qp.py``). ``ipqp``
is right but cannot be code-generated. The RTI step needs a QP that is both.

:func:`interior_point_qp` is a Mehrotra predictor–corrector interior-point method with a
fixed number of iterations, for ``min ½ xᵀHx + gᵀx  s.t.  l <= C x <= u`` with every bound
finite. Each iteration factorises ``H + Cᵀ Σ C`` once (an unrolled Cholesky) and solves with it
twice; one iteration is one function, called ``iterations`` times, which keeps the
generated C small.
"""

from __future__ import annotations

import casadi as ca

FRACTION_TO_BOUNDARY = 0.99
"""Largest share of the distance to the boundary a step may take."""
INITIAL_SLACK = 0.5
"""Initial slacks as a share of each (normalised) constraint's width."""
MU_FLOOR = 1e-13
"""Smallest complementarity the centring aims at: below it, z/s overflows the Newton matrix
and the dual residual deteriorates although x is exact."""
MIN_ITERATIONS = 10
"""Iterations always run: before them a small residual can hide a poor x on badly scaled
problems."""
EXIT_TOLERANCE = 2 * MU_FLOOR
"""After :data:`MIN_ITERATIONS`, the remaining iterations are skipped once the residual is
below this, i.e. once the complementarity has reached its floor. A residual of 1e-10 is not
enough: with complementarity left, a constraint can sit 1e-4 of its width from where it
belongs (seen on ``tests/test_qp.py``'s problems)."""

SMALLEST_WIDTH = 1e-9
"""A linear MPC's rate row (``lmpc.qp=ipm``) is at least this share of its box's width on
each side of 0: the method needs ``l < u``, and a hysteresis flat near the last input (a dead
zone) leaves no virtual change within the input rate."""


def interior_point_qp(h_sparsity: ca.Sparsity, c_sparsity: ca.Sparsity, iterations: int = 30,
                      early_exit: bool = True) -> ca.Function:
    """``qp(h, g, c, l, u) -> (x, residual, parts)`` for ``min ½ xᵀHx + gᵀx, l <= Cx <= u``.

    Parameters
    ----------
    h_sparsity, c_sparsity : casadi.Sparsity
        Patterns of H (n × n) and C (m × n); bounds on x are rows of C too. A sparse C
        (identity and rate rows) keeps ``Cᵀ Σ C`` cheap.
    iterations : int
        Most predictor–corrector iterations, so the cost per call is bounded (real time).
        The default, 30, brings random badly scaled problems close to OSQP's solution,
        relative to the rate bound (``tests/test_qp.py`` checks 100 of them to 1e-5).
    early_exit : bool
        Skip the iterations after the first :data:`MIN_ITERATIONS` once the residual is
        below :data:`EXIT_TOLERANCE` (a conditional in the generated C, so a converged
        QP costs only what it needed); false: always ``iterations``.

    Returns
    -------
    casadi.Function
        Outputs the solution ``x``; ``residual``, the largest of the scaled dual residual,
        primal infeasibility and complementarity at the end, which the caller compares with
        a tolerance to count a failed solve; and those three ``parts``. All bounds must be
        finite with ``l < u``.
    """
    if iterations < MIN_ITERATIONS:
        raise ValueError(f"iterations must be >= {MIN_ITERATIONS} (fewer leave the residual unreliable), "
                         f"got {iterations}")
    n, m = c_sparsity.size2(), c_sparsity.size1()
    H, g = ca.MX.sym("h", h_sparsity), ca.MX.sym("g", n)
    C, l, u = ca.MX.sym("c", c_sparsity), ca.MX.sym("l", m), ca.MX.sym("u", m)
    # normalise: every constraint row to width 2, the objective to a unit largest curvature
    half_width = (u - l) / 2
    C_s = ca.diag(1 / half_width) @ C
    l_s, u_s = l / half_width, u / half_width
    scale = 1.0 / ca.fmax(ca.mmax(ca.diag(H)), 1e-12)
    H_s, g_s = H * scale, g * scale
    x = ca.MX.zeros(n)
    s_l = ca.fmax(-l_s, INITIAL_SLACK * 2)
    s_u = ca.fmax(u_s, INITIAL_SLACK * 2)
    z_l, z_u = ca.MX.ones(m), ca.MX.ones(m)
    iterate = _iteration(H_s.sparsity(), C_s.sparsity())  # one function, called up to `iterations` times
    measure = _residual(H_s.sparsity(), C_s.sparsity())
    data = (H_s, g_s, C_s, l_s, u_s)
    state = (x, s_l, s_u, z_l, z_u)
    unless_done = ca.Function.if_else("ipm_iteration_unless_done", _unchanged(iterate), iterate)
    for k in range(iterations):
        if early_exit and k >= MIN_ITERATIONS:  # a branch in C: converged QPs skip the work
            state = unless_done(measure(*state, *data)[0] <= EXIT_TOLERANCE, *state, *data)
        else:
            state = iterate(*state, *data)
    residual, parts = measure(*state, *data)
    x = state[0]
    return ca.Function("interior_point_qp", [H, g, C, l, u], [x, residual, parts],
                       ["h", "g", "c", "l", "u"], ["x", "residual", "parts"])


def _symbols(h_sparsity: ca.Sparsity, c_sparsity: ca.Sparsity) -> tuple[ca.SX, ...]:
    """SX symbols of an iterate ``(x, s_l, s_u, z_l, z_u)`` and of the data ``(H, g, C, l, u)``."""
    n, m = c_sparsity.size2(), c_sparsity.size1()
    return (ca.SX.sym("x", n), ca.SX.sym("s_l", m), ca.SX.sym("s_u", m), ca.SX.sym("z_l", m),
            ca.SX.sym("z_u", m), ca.SX.sym("h", h_sparsity), ca.SX.sym("g", n),
            ca.SX.sym("c", c_sparsity), ca.SX.sym("l", m), ca.SX.sym("u", m))


def _residual(h_sparsity: ca.Sparsity, c_sparsity: ca.Sparsity) -> ca.Function:
    """``(x, s_l, s_u, z_l, z_u, H, g, C, l, u) -> (residual, parts)`` on the normalised problem.

    The largest of the scaled dual residual, primal infeasibility and mean complementarity, and
    those three.
    """
    m = c_sparsity.size1()
    x, s_l, s_u, z_l, z_u, H, g, C, l, u = _symbols(h_sparsity, c_sparsity)
    Cx = C @ x
    dual = ca.mmax(ca.fabs(H @ x + g - C.T @ (z_l - z_u))) / (1 + ca.mmax(ca.fabs(g)))
    primal = ca.mmax(ca.vertcat(l - Cx, Cx - u, 0))
    gap = (ca.dot(s_l, z_l) + ca.dot(s_u, z_u)) / (2 * m)
    return ca.Function("ipm_residual", [x, s_l, s_u, z_l, z_u, H, g, C, l, u],
                       [ca.mmax(ca.vertcat(dual, primal, gap)), ca.vertcat(dual, primal, gap)])


def _unchanged(iterate: ca.Function) -> ca.Function:
    """``iterate``'s signature, returning the iterate it is given."""
    args = [ca.SX.sym(iterate.name_in(i), iterate.sparsity_in(i)) for i in range(iterate.n_in())]
    return ca.Function("ipm_done", args, args[:iterate.n_out()])


def _step_to_boundary(v, dv):
    """Largest step α with v + α dv >= 0."""
    return ca.mmin(ca.if_else(dv < 0, -v / ca.fmin(dv, -1e-300), 1e300))


def _cholesky(K: list[list[ca.SX]]) -> list[list[ca.SX]]:
    """Lower Cholesky factor of a symmetric positive definite K (rows of entries), unrolled.

    Straight-line SX, cheap to code-generate for the small matrices here.
    """
    n = len(K)
    L = [[ca.SX(0)] * n for _ in range(n)]
    for j in range(n):
        d = K[j][j] - sum((L[j][k] * L[j][k] for k in range(j)), ca.SX(0))
        L[j][j] = ca.sqrt(ca.fmax(d, 1e-300))
        for i in range(j + 1, n):
            L[i][j] = (K[i][j] - sum((L[i][k] * L[j][k] for k in range(j)), ca.SX(0))) / L[j][j]
    return L


def _cholesky_solve(L: list[list[ca.SX]], b: ca.SX) -> ca.SX:
    """Solve ``L Lᵀ x = b``."""
    n = len(L)
    y = [ca.SX(0)] * n
    for i in range(n):
        y[i] = (b[i] - sum((L[i][k] * y[k] for k in range(i)), ca.SX(0))) / L[i][i]
    x = [ca.SX(0)] * n
    for i in reversed(range(n)):
        x[i] = (y[i] - sum((L[k][i] * x[k] for k in range(i + 1, n)), ca.SX(0))) / L[i][i]
    return ca.vertcat(*x)


def _newton_matrix(H: ca.SX, C: ca.SX, weights: ca.SX) -> list[list[ca.SX]]:
    """``H + Cᵀ diag(weights) C`` entry by entry over C's nonzeros.

    CasADi's symbolic product would treat the row-scaled C as dense.
    """
    n = C.size2()
    K = [[H[i, j] for j in range(n)] for i in range(n)]
    rows, cols = C.sparsity().get_triplet()
    by_row: dict[int, list[tuple[int, int]]] = {}
    for k, (r, c) in enumerate(zip(rows, cols, strict=True)):
        by_row.setdefault(r, []).append((c, k))
    for r, entries in by_row.items():
        for i, ki in entries:
            for j, kj in entries:
                K[i][j] = K[i][j] + weights[r] * C.nz[ki] * C.nz[kj]
    return K


def _iteration(h_sparsity: ca.Sparsity, c_sparsity: ca.Sparsity) -> ca.Function:
    """One Mehrotra predictor–corrector iteration on the normalised problem.

    In SX; the predictor and the corrector share one factorisation of the Newton matrix.
    """
    m = c_sparsity.size1()
    x, s_l, s_u, z_l, z_u, H, g, C, l, u = _symbols(h_sparsity, c_sparsity)
    Cx = C @ x
    r_d = H @ x + g - C.T @ (z_l - z_u)
    r_l = Cx - s_l - l
    r_u = -Cx - s_u + u
    K = _newton_matrix(H, C, z_l / s_l + z_u / s_u)
    mu = (ca.dot(s_l, z_l) + ca.dot(s_u, z_u)) / (2 * m)
    factor = _cholesky(K)
    def direction(c_l, c_u):
        rhs = -r_d + C.T @ ((c_l - z_l * r_l) / s_l) - C.T @ ((c_u - z_u * r_u) / s_u)
        dx = _cholesky_solve(factor, rhs)
        ds_l = C @ dx + r_l
        ds_u = -(C @ dx) + r_u
        return dx, ds_l, ds_u, (c_l - z_l * ds_l) / s_l, (c_u - z_u * ds_u) / s_u

    def step_length(ds_l, ds_u, dz_l, dz_u):
        return ca.mmin(ca.vertcat(_step_to_boundary(s_l, ds_l), _step_to_boundary(s_u, ds_u),
                                  _step_to_boundary(z_l, dz_l), _step_to_boundary(z_u, dz_u)))

    # predictor (affine scaling), then the centring–corrector step
    dx, ds_l, ds_u, dz_l, dz_u = direction(-s_l * z_l, -s_u * z_u)
    alpha = ca.fmin(1.0, step_length(ds_l, ds_u, dz_l, dz_u))
    mu_aff = (ca.dot(s_l + alpha * ds_l, z_l + alpha * dz_l) + ca.dot(s_u + alpha * ds_u, z_u + alpha * dz_u)) / (2 * m)
    target = ca.fmax((mu_aff / mu) ** 3 * mu, MU_FLOOR)
    dx, ds_l, ds_u, dz_l, dz_u = direction(target - s_l * z_l - ds_l * dz_l, target - s_u * z_u - ds_u * dz_u)
    alpha = ca.fmin(1.0, FRACTION_TO_BOUNDARY * step_length(ds_l, ds_u, dz_l, dz_u))
    return ca.Function("ipm_iteration", [x, s_l, s_u, z_l, z_u, H, g, C, l, u],
                       [x + alpha * dx, s_l + alpha * ds_l, s_u + alpha * ds_u, z_l + alpha * dz_l,
                        z_u + alpha * dz_u])
