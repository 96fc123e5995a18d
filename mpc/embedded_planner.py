"""The linear MPC planner of ``nmpc.inverse_plan=linear-mpc`` as CasADi Functions, for the generated controller.

:class:`PlannerFunctions` is an :class:`~hystmpc.mpc.linear_mpc.InverseLinearMpc`'s sample with
``lmpc.qp=ipm``: ``applied`` (the compensation's memory moved by the input sent, the Kalman
filter's time update with the virtual input it gave), ``plan`` (the measurement update, the
virtual bounds through the compensation, the box QP solved by the interior-point method,
:func:`hystmpc.mpc.qp.interior_point_qp`, and the fallback after a failed QP) and
``inputs_along`` (the virtual plan through the compensation's inverse). The Python linear MPC
runs these same Functions with ``lmpc.qp=ipm``, so that the generated controller repeats it to
the last bit; :class:`PlannerExpressions` places them in the generated controller's memory.

The compensation must offer ``memory_at_rest``, ``step_expression``, ``inputs_along_function``
and ``sensor_names`` (:class:`hystmpc.experiments.baselines.InverseCompensation` does, for a
memory that follows the inputs sent and sensors named by the measured signals).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from hystmpc.mpc.expressions import NotGeneratable, all_finite, clip, symbolic
from hystmpc.mpc.qp import SMALLEST_WIDTH, interior_point_qp
from hystmpc.mpc.rti import QP_TOLERANCE

STATIC_INSTEAD = "; or set nmpc.inverse_plan=static"
"""How every refusal of a planner ends: the static inverse needs no planner."""
COMPENSATION_METHODS = ("memory_at_rest", "step_expression", "inputs_along_function")
"""What a compensation needs beyond the :class:`~hystmpc.mpc.linear_mpc.Compensation` protocol
to be generated."""


class PlannerFunctions:
    """An :class:`~hystmpc.mpc.linear_mpc.InverseLinearMpc`'s sample as CasADi Functions.

    Parameters
    ----------
    planner : InverseLinearMpc
        The linear MPC, with ``lmpc.qp=ipm``.

    Attributes
    ----------
    memory_at_rest : ndarray
        The compensation's memory before the first sample.
    applied : casadi.Function
        ``(memory, state, covariance, u) -> (memory_next, state_next, covariance_next)``: after
        the input ``u`` is sent (the covariance column-major).
    plan : casadi.Function
        ``(memory, state, covariance, plan, has_plan, z, started, refs, u_last) -> (state_next,
        covariance_next, plan_next, has_plan_next, virtual_plan)``: one sample's plan after the
        sensors ``z`` (``started`` 0: the filter starts from them).
    inputs_along : casadi.Function
        ``(memory, virtual_plan) -> inputs``, NaN where out of reach.

    Raises
    ------
    NotGeneratable
        When a part has no CasADi form, saying which.
    """

    def __init__(self, planner):
        comp, model = planner.compensation, planner.model
        missing = [m for m in COMPENSATION_METHODS if not hasattr(comp, m)]
        if missing:
            raise NotGeneratable(f"the linear MPC's compensation ({type(comp).__name__}) has no {', '.join(missing)}, "
                                 f"which its generated form needs (an InverseCompensation has them){STATIC_INSTEAD}")
        if planner.settings.qp != "ipm":
            raise NotGeneratable(f"the generated linear MPC solves its QP by the interior-point method; lmpc.qp is "
                                 f"{planner.settings.qp!r}: set lmpc.qp=ipm{STATIC_INSTEAD}")
        if model.nz and getattr(comp, "sensor_names", None) is None:
            raise NotGeneratable("the linear MPC's compensation computes its sensors with a function; give it the "
                                 "measured signals' names instead (InverseCompensation(..., sensors=('y',)))"
                                 + STATIC_INSTEAD)
        try:
            self.memory_at_rest = np.asarray(comp.memory_at_rest(), float)
        except ValueError as exc:
            raise NotGeneratable(f"the linear MPC's compensation cannot be generated: {exc}{STATIC_INSTEAD}") from None
        self.planner, self.compensation, self.matrices = planner, comp, planner.matrices
        self.horizon, self.n = planner.horizon, model.nx + model.nd
        qp_rows = ca.sparsify(ca.DM(planner.qp_rows()))
        self._qp_rows = qp_rows
        self._qp = interior_point_qp(ca.Sparsity.dense(self.horizon, self.horizon), qp_rows.sparsity())
        self.inputs_along = self._symbolic_compensation(lambda: comp.inputs_along_function(self.horizon))
        N, n = self.horizon, self.n
        memory = ca.MX.sym("memory", len(self.memory_at_rest))
        state, covariance, u = ca.MX.sym("state", n), ca.MX.sym("covariance", n * n), ca.MX.sym("u")
        self.applied = ca.Function("linear_mpc_applied", [memory, state, covariance, u],
                                   list(self._applied(memory, state, covariance, u)),
                                   ["memory", "state", "covariance", "u"],
                                   ["memory_next", "state_next", "covariance_next"])
        inputs = [memory, state, covariance, ca.MX.sym("plan", N), ca.MX.sym("has_plan"), ca.MX.sym("z", model.nz),
                  ca.MX.sym("started"), ca.MX.sym("refs", N), ca.MX.sym("u_last")]
        self.plan = ca.Function("linear_mpc_plan", inputs, list(self._plan(*inputs)), [v.name() for v in inputs],
                                ["state_next", "covariance_next", "plan_next", "has_plan_next", "virtual_plan"])

    def _symbolic_compensation(self, make):
        try:
            return make()
        except Exception as exc:  # noqa: BLE001 - a NumPy-only model or map fails in many ways
            raise NotGeneratable(f"the linear MPC's compensation ({type(self.compensation).__name__}) does not "
                                 f"accept CasADi expressions ({type(exc).__name__}: {str(exc)[:200]})"
                                 + STATIC_INSTEAD) from None

    def _moved(self, memory, u):
        """``(memory_next, v)``: the compensation's memory moved by ``u``, and the virtual input ``u`` gives."""
        return self._symbolic_compensation(lambda: self.compensation.step_expression(memory, u))

    def _applied(self, memory, state, covariance, u):
        kf = self.matrices
        memory, v = self._moved(memory, u)
        x = ca.mtimes(ca.DM(kf.A), state) + ca.DM(kf.B) * v + ca.DM(kf.f)
        P = ca.mtimes(ca.mtimes(ca.DM(kf.A), ca.reshape(covariance, self.n, self.n)), ca.DM(kf.A.T)) + ca.DM(kf.Q)
        return memory, x, ca.vec(P)

    def _plan(self, memory, state, covariance, plan, has_plan, z, started, refs, u_last):
        """The planner's sample on symbols: ``(state, covariance, plan, has_plan, virtual_plan)``."""
        kf, planner, N, n = self.matrices, self.planner, self.horizon, self.n
        bounds, s = planner.bounds, planner.settings
        nx = planner.model.nx
        x_rest = ca.vertcat(symbolic(planner.initial_state, "the linear MPC's initial_state", z, nx),
                            ca.DM.zeros(n - nx))
        P_rest = ca.DM(kf.initial_covariance)
        x = ca.if_else(started, state, x_rest)
        P = ca.if_else(started, ca.reshape(covariance, n, n), P_rest)
        if planner.model.nz:
            C, R = ca.DM(kf.C), ca.DM(kf.R)
            gain = ca.solve(ca.mtimes(ca.mtimes(C, P), C.T) + R, ca.mtimes(C, P)).T
            x = x + ca.mtimes(gain, z - ca.mtimes(C, x) - ca.DM(kf.z0))
            joseph = ca.DM.eye(n) - ca.mtimes(gain, C)
            P = ca.mtimes(ca.mtimes(joseph, P), joseph.T) + ca.mtimes(ca.mtimes(gain, R), gain.T)
        lost = ca.logic_not(all_finite(x))
        x, P = ca.if_else(lost, x_rest, x), ca.if_else(lost, P_rest, P)

        def virtual(u):
            return self._moved(memory, u)[1]
        u_min, u_max, rate = float(bounds.lower), float(bounds.upper), float(bounds.rate)
        v_prev = virtual(u_last)  # u_last is 0 before the first sample, as the Python planner's u_prev
        v_a, v_b = virtual(u_min), virtual(u_max)
        e0 = ca.vertcat(v_prev, ca.DM.zeros(N - 1))
        lower, upper = [ca.repmat(ca.fmin(v_a, v_b), N, 1)], [ca.repmat(ca.fmax(v_a, v_b), N, 1)]
        if np.isfinite(rate):
            down = virtual(ca.fmax(u_last - rate, u_min)) - v_prev
            up = virtual(ca.fmin(u_last + rate, u_max)) - v_prev
            least = SMALLEST_WIDTH * (ca.fmax(v_a, v_b) - ca.fmin(v_a, v_b))  # the method needs l < u
            lower.append(-ca.fmax(-ca.fmin(down, up), least) + e0)
            upper.append(ca.fmax(ca.fmax(down, up), least) + e0)
        free = ca.mtimes(ca.DM(kf.Phi), x) + ca.DM(kf.offset)
        grad = 2 * (s.q_output * ca.mtimes(ca.DM(kf.G.T), free - refs) - s.r_rate * ca.mtimes(ca.DM(kf.D.T), e0))
        solution, residual, _ = self._qp(ca.DM(kf.hessian), grad, self._qp_rows, ca.vertcat(*lower),
                                         ca.vertcat(*upper))
        solved = ca.logic_and(residual <= QP_TOLERANCE, all_finite(solution))
        fallback = ca.if_else(has_plan > 0.5, plan[1], v_prev)
        virtual_plan = ca.if_else(solved, solution, ca.repmat(fallback, N, 1))
        return x, ca.vec(P), ca.if_else(solved, solution, plan), solved, virtual_plan



class PlannerExpressions:
    """:class:`PlannerFunctions` over parts of the generated controller's memory.

    Parts: ``planner_memory`` (the compensation's hysteresis state), ``planner_state`` and
    ``planner_covariance`` (the Kalman filter's ``[x; d]`` and its covariance, column-major),
    ``planner_plan`` (the last virtual plan), ``planner_has_plan`` and ``planner_failures``
    (its failed QPs since the start).

    Parameters
    ----------
    planner : InverseLinearMpc
        The linear MPC, with ``lmpc.qp=ipm``.
    sensor_names : sequence of str
        The NMPC's sensors, in the order of its measurement vector ``z``.
    horizon : int
        The NMPC's horizon (the planner's must be the same).

    Raises
    ------
    NotGeneratable
        When a part has no CasADi form, saying which.
    """

    def __init__(self, planner, sensor_names, horizon: int):
        functions = planner.functions if getattr(planner, "functions", None) is not None else PlannerFunctions(planner)
        names = getattr(planner.compensation, "sensor_names", None) or ()
        unmeasured = [n for n in names if n not in sensor_names]
        if unmeasured:
            raise NotGeneratable(f"the linear MPC reads {', '.join(unmeasured)}, which the NMPC does not measure "
                                 f"(it reads {', '.join(sensor_names)}){STATIC_INSTEAD}")
        if horizon != functions.horizon:
            raise NotGeneratable(f"the linear MPC plans over {functions.horizon} samples and the NMPC over {horizon}: "
                                 f"give both the same horizon{STATIC_INSTEAD}")
        self.functions, self.bounds = functions, planner.bounds
        self.sensor_index = [list(sensor_names).index(n) for n in names]
        n, N = functions.n, functions.horizon
        self.parts = (("planner_memory", len(functions.memory_at_rest)), ("planner_state", n),
                      ("planner_covariance", n * n), ("planner_plan", N), ("planner_has_plan", 1),
                      ("planner_failures", 1))
        self.initial_values = (("planner_memory", tuple(float(v) for v in functions.memory_at_rest)),)

    def prepare(self, part, u_last) -> dict:
        """The parts after the input sent last: the compensation's memory and the filter's time update.

        Parameters
        ----------
        part : callable
            ``name -> casadi.MX``: a part of the memory.
        u_last : casadi.MX
            The input sent last.

        Returns
        -------
        dict
            ``planner_memory``, ``planner_state``, ``planner_covariance``.
        """
        memory, state, covariance = self.functions.applied(part("planner_memory"), part("planner_state"),
                                                           part("planner_covariance"), u_last)
        return {"planner_memory": memory, "planner_state": state, "planner_covariance": covariance}

    def feedback(self, part, z, started, refs, u_last):
        """``(parts, plan)`` after the measurement ``z``.

        Parameters
        ----------
        part : callable
            ``name -> casadi.MX``: a part of the memory.
        z : casadi.MX
            The NMPC's sensor vector.
        started : casadi.MX
            1 after the first sample.
        refs : casadi.MX
            The references ``r_{k+1}..r_{k+N}``.
        u_last : casadi.MX
            The input sent last (0 before the first sample).

        Returns
        -------
        parts : dict
            ``planner_state``, ``planner_covariance``, ``planner_plan``, ``planner_has_plan``,
            ``planner_failures``.
        plan : callable
            ``plan(needed)``: the planned inputs (bounded, a non-finite one replaced by
            ``u_last``) where ``needed`` is true, zeros where it is false, through a switch, so
            that generated code runs the inverse chain only when needed.
        """
        z = ca.vertcat(*[z[i] for i in self.sensor_index]) if self.sensor_index else ca.MX(0, 1)
        memory = part("planner_memory")
        state, covariance, plan, has_plan, virtual_plan = self.functions.plan(
            memory, part("planner_state"), part("planner_covariance"), part("planner_plan"),
            part("planner_has_plan"), z, started, refs, u_last)
        parts = {"planner_state": state, "planner_covariance": covariance, "planner_plan": plan,
                 "planner_has_plan": has_plan, "planner_failures": part("planner_failures") + ca.logic_not(has_plan)}
        return parts, self._plan_switch(memory, virtual_plan, u_last, float(self.bounds.lower),
                                        float(self.bounds.upper))

    def _plan_switch(self, memory, virtual_plan, u_last, u_min: float, u_max: float):
        N = self.functions.horizon
        memory_s, virtual_s = ca.MX.sym("memory", memory.sparsity()), ca.MX.sym("virtual", N)
        u_last_s = ca.MX.sym("u_last")
        raw = self.functions.inputs_along(memory_s, virtual_s)
        planned = clip(ca.if_else(ca.fabs(raw) < ca.inf, raw, u_last_s), u_min, u_max)
        inputs = [memory_s, virtual_s, u_last_s]
        switch = ca.Function.if_else("planned_inputs_if_needed", ca.Function("planned_inputs", inputs, [planned]),
                                     ca.Function("no_planned_inputs", inputs, [ca.DM.zeros(N)]))
        return lambda needed: switch(needed, memory, virtual_plan, u_last)

