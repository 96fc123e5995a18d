"""The whole NMPC controller as two CasADi Functions, for C: estimator, warm start, solver, fallback.

:func:`controller_functions` turns an :class:`~hystmpc.mpc.controller.NmpcController` into

* ``feedback(mem, z, ref_preview) -> (mem_next, u, status, predicted)``: the measurement
  update, the restart of a non-finite estimate, the jump test, the warm start (shifted plan,
  or the inverse model), the rate-feasible guess, the RTI steps, the success test, the
  fallback and the bound and rate clip; and
* ``prepare(mem) -> mem_next``: what does not need the next measurement, the EKF's time
  update with the input just sent,

over one flat memory vector (:class:`MemoryLayout`). They repeat
:meth:`NmpcController.step <hystmpc.mpc.controller.NmpcController.step>` operation by
operation (``feedback`` after ``prepare`` is one Python step), so generated C does what the
Python controller does. Supported: a state observer (EKF on ``[x; d]``) with the condensed
multiple-shooting RTI step; the inverse model and the observer's ``initial_state`` must
accept CasADi expressions (the bench writes them so).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import casadi as ca
import numpy as np

from hystmpc.mpc.observer import Estimate, StateObserver
from hystmpc.mpc.rti import QP_TOLERANCE

STATUS_CODES = {0: "solved", 1: "solver failed: fallback input sent",
                2: "estimate not finite: restarted from the sensors, fallback input sent"}
"""The ``status`` output of ``feedback`` (and of the generated ``<name>_step``)."""


@dataclass(frozen=True)
class MemoryLayout:
    """Where each part of the controller's memory vector sits.

    ``x`` (model state estimate), ``d`` (disturbance estimate), ``P`` (EKF covariance of
    ``[x; d]``, column-major), ``u_last`` (input sent last), ``started`` (1 after the first
    step), ``plan`` (the last successful input plan), ``has_plan``, ``ref_end`` (the last
    preview's final reference, for the jump test), ``has_ref_end``, ``failures`` and
    ``estimator_resets`` (counters since the start).
    """

    nx: int
    nd: int
    horizon: int

    @property
    def parts(self) -> dict[str, int]:
        """Name -> length, in memory order."""
        n = self.nx + self.nd
        return {"x": self.nx, "d": self.nd, "P": n * n, "u_last": 1, "started": 1, "plan": self.horizon,
                "has_plan": 1, "ref_end": 1, "has_ref_end": 1, "failures": 1, "estimator_resets": 1}

    @property
    def slices(self) -> dict[str, slice]:
        """Name -> slice of the memory vector."""
        out, start = {}, 0
        for name, length in self.parts.items():
            out[name] = slice(start, start + length)
            start += length
        return out

    @property
    def size(self) -> int:
        """Length of the memory vector."""
        return sum(self.parts.values())

    def pack(self, mem: ca.MX, **parts) -> ca.MX:
        """``mem`` with the named parts replaced."""
        unknown = set(parts) - set(self.parts)
        if unknown:
            raise ValueError(f"unknown memory parts {sorted(unknown)}")
        return ca.vertcat(*[ca.vec(parts[name]) if name in parts else mem[sl]
                            for name, sl in self.slices.items()])


def _finite(v) -> ca.MX:
    """1 when every entry of ``v`` is finite (NaN and ±inf give 0)."""
    return ca.sum1(ca.fabs(ca.vec(v))) < ca.inf


def _clip(v, lower, upper):
    return ca.fmin(ca.fmax(v, lower), upper)


def feasible_guess_expr(u, u_prev, u_min: float, u_max: float, du_max: float) -> ca.MX:
    """:func:`hystmpc.mpc.rti.feasible_guess` on CasADi expressions (the same operations)."""
    u = _clip(u, u_min, u_max)
    if not np.isfinite(du_max):
        return u
    last = _clip(u_prev, u_min, u_max)
    out = []
    for k in range(u.shape[0]):
        last = ca.fmin(ca.fmin(ca.fmax(ca.fmax(u[k], last - du_max), u_min), last + du_max), u_max)
        out.append(last)
    return ca.vertcat(*out)


def _check(controller) -> None:
    problem, observer = controller.problem, controller.observer
    if not isinstance(observer, StateObserver):
        raise ValueError(f"a generated controller needs a StateObserver (an EKF on [x; d]); this one has "
                         f"{type(observer).__name__}")
    if not (getattr(problem, "multiple_shooting", False) and getattr(problem, "condensed", False)):
        raise ValueError("a generated controller needs the condensed multiple-shooting RTI step "
                         "(nmpc.solver=rti with solver.rti.condensed=true)")
    if problem.rti is None or problem.rti.is_a("External"):
        raise ValueError("build the controller with nmpc.solver=rti: its RTI step goes into the generated code")


def controller_functions(controller, name: str = "nmpc") -> tuple[ca.Function, ca.Function, MemoryLayout]:
    """``(feedback, prepare, layout)`` of ``controller`` (see the module docstring).

    Parameters
    ----------
    controller : NmpcController
        Built with ``nmpc.solver=rti``, a :class:`StateObserver` and, for
        ``warm_start='inverse'`` or ``r_input > 0``, an inverse model that accepts CasADi
        expressions (as the observer's ``initial_state`` must).
    name : str
        Prefix of the Functions' names (``<name>_feedback``, ``<name>_prepare``).
    """
    _check(controller)
    model, observer, problem, s = controller.model, controller.observer, controller.problem, controller.settings
    ekf, bounds = observer.ekf, controller.bounds
    nx, nd, N, nz = model.nx, model.nd, controller.horizon, model.nz
    n = nx + nd
    layout = MemoryLayout(nx, nd, N)
    sl = layout.slices
    mem = ca.MX.sym("mem", layout.size)

    def part(key):
        return mem[sl[key]]

    P_mem = ca.reshape(part("P"), n, n)
    started = part("started") > 0.5
    u_last = part("u_last")

    # prepare: the time update with the input just sent
    xd_next, P_next = ekf.time_update(part("x"), u_last, part("d"), P_mem, ca.DM(ekf.Q))
    prepare = ca.Function(f"{name}_prepare", [mem], [layout.pack(
        mem, x=ca.if_else(started, xd_next[:nx], part("x")), d=ca.if_else(started, xd_next[nx:], part("d")),
        P=ca.if_else(started, P_next, P_mem))], ["mem"], ["mem_next"])

    # feedback
    z = ca.MX.sym("z", nz)
    window = ca.MX.sym("ref_preview", N + 1)
    x_rest = ca.vertcat(_symbolic(observer.initial_state, "the observer's initial_state", z), ca.DM.zeros(nd))
    P_rest = ca.DM(np.diag(observer.initial_covariance))
    xd = ca.if_else(started, ca.vertcat(part("x"), part("d")), x_rest)
    P = ca.if_else(started, P_mem, P_rest)
    predicted = model.output(xd[:nx], xd[nx:])
    xd_update, P_update = ekf.measurement_update(xd[:nx], xd[nx:], P, z)
    lost = ca.logic_not(_finite(xd_update))
    xd = ca.if_else(lost, x_rest, xd_update)
    P = ca.if_else(lost, P_rest, P_update)
    x, d = xd[:nx], xd[nx:]

    refs = window[1:] if s.preview else ca.repmat(window[0], N, 1)
    u_min, u_max, rate = float(bounds.lower), float(bounds.upper), float(bounds.rate)
    u_inv = None
    if controller.inverse is not None:
        raw = _symbolic(lambda r: controller.inverse(Estimate(x, d), r), "the inverse model", refs)
        u_inv = _clip(ca.if_else(ca.fabs(raw) < ca.inf, raw, u_last), u_min, u_max)
    jump = ca.MX(0)
    if np.isfinite(controller.jump_threshold):
        jump = ca.logic_and(part("has_ref_end") > 0.5, ca.fabs(refs[-1] - part("ref_end")) > controller.jump_threshold)
    has_plan = ca.logic_and(part("has_plan") > 0.5, ca.logic_not(lost))  # a restarted estimate drops the plan
    plan = part("plan")
    shifted = ca.vertcat(plan[1:], plan[-1])
    if s.warm_start == "cold":
        u_guess = ca.DM.zeros(N)
    elif s.warm_start == "inverse":
        u_guess = ca.if_else(ca.logic_or(ca.logic_not(has_plan), jump), u_inv, shifted)
    else:
        u_guess = ca.if_else(has_plan, shifted, ca.repmat(u_last, N, 1))
    u_ff = u_inv if s.r_input > 0 else ca.DM.zeros(N)
    w = feasible_guess_expr(u_guess, u_last, u_min, u_max, rate)
    p = ca.vertcat(x, d, u_last, refs, u_ff)
    worst, broken = ca.MX(0), ca.MX(0)
    for _ in range(controller.solvers.rti.iterations):
        w_next, qp_error = problem.rti(w, p)
        worst = ca.if_else(qp_error <= worst, worst, qp_error)  # a NaN error is kept, as rti_steps does
        finite = _finite(w_next)
        broken = ca.logic_or(broken, ca.logic_not(finite))
        w = ca.if_else(finite, w_next, w)  # a non-finite step is a failure; the next QP gets finite data
    success = ca.logic_and(ca.logic_and(ca.logic_not(lost), ca.logic_not(broken)), worst <= QP_TOLERANCE)

    fallback = u_inv[0] if u_inv is not None else u_last
    u = ca.if_else(success, w[0], ca.if_else(has_plan, plan[min(1, N - 1)], fallback))
    u = ca.if_else(ca.fabs(u) < ca.inf, u, fallback)  # never a NaN to the actuator
    if np.isfinite(rate):
        u = _clip(u, u_last - rate, u_last + rate)
    u = _clip(u, u_min, u_max)
    status = ca.if_else(lost, 2, ca.if_else(success, 0, 1))
    mem_next = layout.pack(
        mem, x=x, d=d, P=P, u_last=u, started=1, plan=ca.if_else(success, w, plan), has_plan=success,
        ref_end=refs[-1], has_ref_end=1, failures=part("failures") + ca.logic_not(success),
        estimator_resets=part("estimator_resets") + lost)
    feedback = ca.Function(f"{name}_feedback", [mem, z, window], [mem_next, u, status, predicted],
                           ["mem", "z", "ref_preview"], ["mem_next", "u", "status", "predicted"])
    return feedback, prepare, layout


def _symbolic(fun, what: str, arg):
    """``fun(arg)`` on a CasADi symbol as a column, or a ValueError saying ``what`` has no CasADi form."""
    try:
        with warnings.catch_warnings():  # a NumPy-only function on a CasADi symbol warns before it fails
            warnings.simplefilter("ignore")
            out = fun(arg)
        if not isinstance(out, (ca.MX, ca.SX, ca.DM)):
            raise TypeError(f"returned {type(out).__name__}")
    except Exception as exc:  # noqa: BLE001 - any failure means the same thing here
        raise ValueError(f"{what} does not accept CasADi expressions ({type(exc).__name__}: {exc}); "
                         "write it with casadi operations for a generated controller") from None
    return ca.vec(out)


def initial_memory(layout: MemoryLayout) -> np.ndarray:
    """The memory before the first step: nothing started (every entry zero)."""
    return np.zeros(layout.size)


class FunctionController:
    """``feedback`` and ``prepare`` run in Python as a controller of :mod:`hystmpc.experiments.runner`
    (to check them, and the generated C built from them, against the Python controller).

    Parameters
    ----------
    controller : NmpcController
        The Python controller the Functions were built from (for ``horizon`` and ``sensors``).
    feedback, prepare : casadi.Function
        From :func:`controller_functions`, in-process or compiled.
    layout : MemoryLayout
        Their memory layout.
    """

    def __init__(self, controller, feedback: ca.Function, prepare: ca.Function, layout: MemoryLayout):
        self.controller, self.feedback, self.prepare, self.layout = controller, feedback, prepare, layout
        self.horizon = controller.horizon
        self.sensor_names = controller.sensor_names
        self.reset()

    def reset(self) -> None:
        """Back to the memory before the first step."""
        self.mem = initial_memory(self.layout)
        self.statuses: dict[int, int] = {}
        self.predicted_output = float("nan")

    def step(self, measurement, ref_window) -> float:
        """One feedback call, then the prepare call for the next sample."""
        mem, u, status, predicted = self.feedback(self.mem, self.controller.sensors(measurement),
                                                  np.asarray(ref_window, float))
        self.mem = np.asarray(self.prepare(mem)).ravel()
        self.predicted_output = float(predicted)
        self.statuses[int(status)] = self.statuses.get(int(status), 0) + 1
        return float(u)

    def stats(self) -> dict:
        """Failures and restarts counted by the memory, and the status codes seen."""
        sl = self.layout.slices
        return {"name": "generated", "failures": int(self.mem[sl["failures"]][0]),
                "estimator_resets": int(self.mem[sl["estimator_resets"]][0]), "statuses": dict(self.statuses)}
