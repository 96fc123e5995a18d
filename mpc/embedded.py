"""The whole NMPC controller as two CasADi Functions, for C: estimator, warm start, solver, fallback.

:func:`controller_functions` turns an :class:`~hystmpc.mpc.controller.NmpcController` into

* ``feedback(mem, z, ref_preview) -> (mem_next, u, status, predicted)``: the measurement
  update, the restart of a non-finite estimate, the jump test, the warm start (shifted plan,
  or the inverse model), the rate-feasible guess, the RTI steps, the success test, the
  fallback and the bound and rate clip; and
* ``prepare(mem) -> mem_next``: what does not need the next measurement: the EKF's time
  update with the input just sent and, for an input-driven model, the exact hysteresis and
  dead-time queue (and the creep memory) moved by it,

over one flat memory vector (:class:`MemoryLayout`). They repeat
:meth:`NmpcController.step <hystmpc.mpc.controller.NmpcController.step>` operation by
operation (``feedback`` after ``prepare`` is one Python step), so generated C does what the
Python controller does. Supported: a :class:`StateObserver` (EKF on ``[x; d]``) or a
:class:`MemoryObserver` (the exact hysteresis, dead time and creep over a fixed window, with
or without an EKF), with the condensed multiple-shooting or the single-shooting RTI step;
the inverse model and the observer's ``initial_state`` must accept CasADi expressions (the
bench writes them so). What cannot be generated raises :class:`NotGeneratable`, saying why.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from hystmpc.models.fractional import window_functions
from hystmpc.mpc.codegen.controller import ControllerCode
from hystmpc.mpc.embedded_planner import PlannerExpressions
from hystmpc.mpc.expressions import NotGeneratable, all_finite, clip, is_nan, rows, symbolic
from hystmpc.mpc.observer import Estimate, MemoryObserver, StateObserver
from hystmpc.mpc.rti import QP_TOLERANCE
from hystmpc.mpc.settings import second_start_cost


@dataclass(frozen=True)
class MemoryLayout:
    """Where each part of the controller's memory vector sits, and its value before the first step.

    The estimator's parts first (a state observer: ``x``, ``d``, ``P``, the EKF covariance
    of ``[x; d]`` column-major; the exact-memory observer: ``hysteresis``, ``queue``, and
    ``x``, ``d``, ``P`` of its EKF if it has one; with a linear MPC's plan, its ``planner_*``
    parts, :class:`~hystmpc.mpc.embedded_planner.PlannerExpressions`), then ``u_last`` (input sent last),
    ``started`` (1 after the first step), ``plan`` (the last successful input plan),
    ``has_plan``, ``ref_end`` (the last preview's final reference, for the jump test),
    ``has_ref_end``, ``failures`` and ``estimator_resets`` (counters since the start), and
    ``paused`` (samples left without a second start, ``nmpc.second_start_pause``).
    """

    estimator: tuple[tuple[str, int], ...]
    horizon: int
    initial_values: tuple[tuple[str, tuple[float, ...]], ...] = ()
    """Parts that do not start at zero (the exact memory's rest state)."""

    @property
    def parts(self) -> dict[str, int]:
        """Name -> length, in memory order."""
        return {**dict(self.estimator), "u_last": 1, "started": 1, "plan": self.horizon, "has_plan": 1,
                "ref_end": 1, "has_ref_end": 1, "failures": 1, "estimator_resets": 1, "paused": 1}

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

    def initial(self) -> np.ndarray:
        """The memory before the first step.

        Returns
        -------
        ndarray
            Zeros, but for the parts of ``initial_values``.
        """
        mem = np.zeros(self.size)
        for name, values in self.initial_values:
            mem[self.slices[name]] = values
        return mem

    def pack(self, mem: ca.MX, **parts) -> ca.MX:
        """``mem`` with the named parts replaced.

        Parameters
        ----------
        mem : casadi.MX
            A memory vector.
        **parts
            New values by part name (each flattened column-major).

        Returns
        -------
        casadi.MX
            The new memory vector.

        Raises
        ------
        ValueError
            For a name that is not a part.
        """
        unknown = set(parts) - set(self.parts)
        if unknown:
            raise ValueError(f"unknown memory parts {sorted(unknown)}")
        return ca.vertcat(*[ca.vec(parts[name]) if name in parts else mem[sl]
                            for name, sl in self.slices.items()])


def feasible_guess_expr(u, u_prev, u_min: float, u_max: float, du_max: float) -> ca.MX:
    """:func:`hystmpc.mpc.rti.feasible_guess` on CasADi expressions (the same operations).

    Parameters
    ----------
    u : casadi.MX
        The guessed inputs.
    u_prev : casadi.MX
        The input sent last.
    u_min, u_max : float
        Input bounds.
    du_max : float
        Largest change per sample (``inf``: none).

    Returns
    -------
    casadi.MX
        The feasible inputs.
    """
    u = clip(u, u_min, u_max)
    if not np.isfinite(du_max):
        return u
    last = clip(u_prev, u_min, u_max)
    out = []
    for k in range(u.shape[0]):
        last = ca.fmin(ca.fmin(ca.fmax(ca.fmax(u[k], last - du_max), u_min), last + du_max), u_max)
        out.append(last)
    return ca.vertcat(*out)


class _StateEstimator:
    """A :class:`StateObserver` as expressions: an EKF on the whole model's ``[x; d]``."""

    def __init__(self, controller):
        self.observer, self.model = controller.observer, controller.model
        self.ekf = self.observer.ekf
        nx, nd = self.model.nx, self.model.nd
        self.parts = (("x", nx), ("d", nd), ("P", (nx + nd) ** 2))
        self.initial_values = ()

    def prepare(self, part, u_last) -> dict:
        """The parts after the time update with the input sent last."""
        ekf, nx = self.ekf, self.model.nx
        n = nx + self.model.nd
        xd, P = ekf.time_update(part("x"), u_last, part("d"), ca.reshape(part("P"), n, n), ca.DM(ekf.Q))
        return {"x": rows(xd, 0, nx), "d": rows(xd, nx, n), "P": P}

    def feedback(self, part, z, started):
        """``(parts, estimate, condition, lost, predicted)`` after the measurement ``z``."""
        ekf, model = self.ekf, self.model
        nx, nd = model.nx, model.nd
        n = nx + nd
        x0 = symbolic(self.observer.initial_state, "the observer's initial_state", z, nx)
        x_rest = ca.vertcat(x0, ca.DM.zeros(nd))
        P_rest = ca.DM(np.diag(self.observer.initial_covariance))
        xd = ca.if_else(started, ca.vertcat(part("x"), part("d")), x_rest)
        P = ca.if_else(started, ca.reshape(part("P"), n, n), P_rest)
        predicted = model.output(rows(xd, 0, nx), rows(xd, nx, n))
        xd_update, P_update = ekf.measurement_update(rows(xd, 0, nx), rows(xd, nx, n), P, z, ca.DM(ekf.R))
        lost = ca.logic_not(all_finite(xd_update))
        xd = ca.if_else(lost, x_rest, xd_update)
        P = ca.if_else(lost, P_rest, P_update)
        x, d = rows(xd, 0, nx), rows(xd, nx, n)
        return {"x": x, "d": d, "P": P}, Estimate(x, d), ca.vertcat(x, d), lost, predicted


class _MemoryEstimator:
    """A :class:`MemoryObserver` as expressions.

    The exact hysteresis and dead time on the inputs sent, and the EKF (on the dynamics, or on
    the whole model with the exact states held) if there is one; the creep memory as the last
    ``window + 1`` hysteresis outputs.
    """

    def __init__(self, controller):
        obs, model = controller.observer, controller.model
        self.observer, self.model, self.memory, self.ekf = obs, model, obs.memory, obs.ekf
        hysteresis = self.memory.hysteresis
        n_h, D = len(hysteresis.initial_state(obs.rest_input)), self.memory.delay_samples
        parts = [("hysteresis", n_h), ("queue", D)]
        self.creep = None
        if obs.creeping:
            if obs.creep_window is None:
                raise NotGeneratable("a generated controller keeps a fixed creep memory: the whole history grows "
                                     "without bound; give the creep sums a window (dea: memory.window=200)")
            self.creep = window_functions(-self.memory.creep_order, model.sample_period, obs.creep_window,
                                          controller.horizon)
            parts.append(("creep", obs.creep_window + 1))
        if self.ekf is not None:
            n_e, nd = self.ekf.model.nx, model.nd
            parts += [("x", n_e), ("d", nd), ("P", (n_e + nd) ** 2)]
        self.parts = tuple(parts)
        values = [("hysteresis", tuple(float(v) for v in hysteresis.initial_state(obs.rest_input))),
                  ("queue", (obs.rest_input,) * D)]
        if self.ekf is not None and not obs.split:  # the whole-model EKF's exact states, held
            values.append(("x", tuple(np.concatenate((np.zeros(self.memory.n_dynamic), values[0][1], values[1][1])))))
        self.initial_values = tuple(values)

    def _held(self, x_e, hysteresis, queue):
        """The whole-model EKF's state with its exact part set to the exact memory."""
        if self.observer.split:
            return x_e
        return ca.vertcat(rows(x_e, 0, self.memory.n_dynamic), hysteresis, queue)

    def prepare(self, part, u_last) -> dict:
        """The exact memory moved by the input sent last, and the EKF's time update."""
        queue = part("queue")
        D = self.memory.delay_samples
        u_in = queue[0] if D else u_last
        queue_next = ca.vertcat(rows(queue, 1, D), u_last) if D else queue
        try:
            hysteresis, h = self.memory.hysteresis.step(part("hysteresis"), u_in)
        except Exception as exc:  # noqa: BLE001 - a NumPy-only step fails in many ways
            raise NotGeneratable(f"the exact step of {type(self.memory.hysteresis).__name__} does not accept CasADi "
                                 f"expressions ({type(exc).__name__}: {exc})") from None
        out = {"hysteresis": hysteresis, "queue": queue_next}
        if self.creep is not None:
            out["creep"], h = self.creep[0](part("creep"), h)
        if self.ekf is not None:
            ekf, n_e = self.ekf, self.ekf.model.nx
            n = n_e + self.model.nd
            xd, P = ekf.time_update(part("x"), h if self.observer.split else u_last, part("d"),
                                    ca.reshape(part("P"), n, n), ca.DM(ekf.Q))
            out.update({"x": self._held(rows(xd, 0, n_e), hysteresis, queue_next), "d": rows(xd, n_e, n), "P": P})
        return out

    def feedback(self, part, z, started):
        """``(parts, estimate, condition, lost, predicted)`` after the measurement ``z``."""
        obs, model, nd = self.observer, self.model, self.model.nd
        hysteresis, queue = part("hysteresis"), part("queue")
        n_dyn = self.memory.n_dynamic
        if self.ekf is None:
            x_dyn, d = ca.DM.zeros(n_dyn), ca.DM.zeros(nd)
            x = ca.vertcat(x_dyn, hysteresis, queue)
            return {}, Estimate(x, d, hysteresis, None, queue), ca.vertcat(x, d), ca.MX(0), model.output(x, d)
        ekf, n_e = self.ekf, self.ekf.model.nx
        n = n_e + nd
        x0 = symbolic(obs.initial_state, "the observer's initial_state", z, n_dyn)
        x_rest = ca.vertcat(self._held(ca.vertcat(x0, ca.DM.zeros(n_e - n_dyn)), hysteresis, queue), ca.DM.zeros(nd))
        P_rest = ca.DM(np.diag(obs.initial_covariance))
        xd = ca.if_else(started, ca.vertcat(part("x"), part("d")), x_rest)
        P = ca.if_else(started, ca.reshape(part("P"), n, n), P_rest)
        output = self.memory.dynamics.output if obs.split else model.output
        predicted = output(rows(xd, 0, n_e), rows(xd, n_e, n))
        xd_update, P_update = ekf.measurement_update(rows(xd, 0, n_e), rows(xd, n_e, n), P, z, ca.DM(ekf.R))
        xd_update = ca.vertcat(self._held(rows(xd_update, 0, n_e), hysteresis, queue), rows(xd_update, n_e, n))
        lost = ca.logic_not(all_finite(xd_update))
        xd = ca.if_else(lost, x_rest, xd_update)
        P = ca.if_else(lost, P_rest, P_update)
        x_e, d = rows(xd, 0, n_e), rows(xd, n_e, n)
        if self.creep is not None:  # the creep model's condition: [hysteresis, x_dyn, d, history]
            history = self.creep[1](part("creep"))
            return ({"x": x_e, "d": d, "P": P}, Estimate(x_e, d, hysteresis, history, queue),
                    ca.vertcat(hysteresis, x_e, d, history), lost, predicted)
        x = ca.vertcat(rows(x_e, 0, n_dyn), hysteresis, queue)
        return ({"x": x_e, "d": d, "P": P}, Estimate(x, d, hysteresis, None, queue), ca.vertcat(x, d), lost,
                predicted)


def _estimator(controller):
    observer = controller.observer
    if isinstance(observer, StateObserver):
        return _StateEstimator(controller)
    if isinstance(observer, MemoryObserver):
        return _MemoryEstimator(controller)
    raise NotGeneratable(f"a generated controller needs a StateObserver or a MemoryObserver; this one has "
                     f"{type(observer).__name__}")


def _check(controller) -> None:
    if controller.settings.inverse_plan == "linear-mpc" and controller.planner is None:
        raise NotGeneratable("nmpc.inverse_plan=linear-mpc takes its inputs from a linear MPC's plan, and this "
                             "controller has none (give it planner=InverseLinearMpc(...))")
    problem = controller.problem
    if getattr(problem, "multiple_shooting", False) and not getattr(problem, "condensed", False):
        raise NotGeneratable("a generated controller needs the condensed RTI step "
                             "(nmpc.solver=rti with solver.rti.condensed=true)")
    if getattr(problem, "rti", None) is None or problem.rti.is_a("External"):
        raise NotGeneratable("build the controller with nmpc.solver=rti: its RTI step goes into the generated code")


def controller_functions(controller, name: str = "nmpc") -> tuple[ca.Function, ca.Function, MemoryLayout]:
    """``(feedback, prepare, layout)`` of ``controller`` (see the module docstring).

    Parameters
    ----------
    controller : NmpcController
        Built with ``nmpc.solver=rti``, a :class:`StateObserver` or a :class:`MemoryObserver`
        (a creep memory with a window) and, for ``warm_start='inverse'`` or ``r_input > 0``, an inverse
        model that accepts CasADi expressions (as the observer's ``initial_state`` must).
    name : str
        Prefix of the Functions' names (``<name>_feedback``, ``<name>_prepare``).

    Returns
    -------
    feedback : casadi.Function
        ``feedback(mem, z, ref_preview) -> (mem_next, u, status, predicted)``; ``status`` 0: the
        RTI steps succeeded, 1: they failed, 2: the estimate was not finite and restarted.
    prepare : casadi.Function
        ``prepare(mem) -> mem_next``.
    layout : MemoryLayout
        Their memory layout.

    Raises
    ------
    NotGeneratable
        When the controller cannot be generated.
    """
    estimator = _estimator(controller)
    _check(controller)
    problem, s, bounds = controller.problem, controller.settings, controller.bounds
    N = controller.horizon
    planner = None
    if s.inverse_plan == "linear-mpc":
        planner = PlannerExpressions(controller.planner, controller.sensor_names, N)
    layout = MemoryLayout(estimator.parts + (planner.parts if planner else ()), N,
                          estimator.initial_values + (planner.initial_values if planner else ()))
    sl = layout.slices
    mem = ca.MX.sym("mem", layout.size)

    def part(key):
        return mem[sl[key]]

    started = part("started") > 0.5
    u_last = part("u_last")

    # prepare: what the input just sent moves (the EKF's time update, the exact memory)
    moved = estimator.prepare(part, u_last)
    if planner is not None:
        moved.update(planner.prepare(part, u_last))
    prepare = ca.Function(f"{name}_prepare", [mem], [layout.pack(
        mem, **{key: ca.if_else(started, ca.vec(value), part(key)) for key, value in moved.items()})], ["mem"],
        ["mem_next"])

    # feedback
    z = ca.MX.sym("z", len(controller.sensor_names))
    window = ca.MX.sym("ref_preview", N + 1)
    estimated, est, condition, lost, predicted = estimator.feedback(part, z, started)

    refs = window[1:] if s.preview else ca.repmat(window[0], N, 1)
    u_min, u_max, rate = float(bounds.lower), float(bounds.upper), float(bounds.rate)
    if planner is not None:  # the linear MPC's plan every sample (its filter and plan follow the loop)
        planned, inverse_plan = planner.feedback(part, z, started, refs, u_last)
        estimated.update(planned)
    else:
        inverse_plan = None if controller.inverse is None else _inverse_plan(controller, est, refs, u_last, N)
    jump = ca.MX(0)
    if np.isfinite(controller.jump_threshold):
        jump = ca.logic_and(part("has_ref_end") > 0.5, ca.fabs(refs[-1] - part("ref_end")) > controller.jump_threshold)
    has_plan = ca.logic_and(part("has_plan") > 0.5, ca.logic_not(lost))  # a restarted estimate drops the plan
    plan = part("plan")
    shifted = ca.vertcat(plan[1:], plan[-1])
    # the inverse is a large share of a step: computed only on the samples that use it
    restart = ca.logic_or(ca.logic_not(has_plan), jump)  # the inverse warm start's samples
    needs_inverse = ca.MX(1) if s.r_input > 0 else restart if s.warm_start == "inverse" else ca.MX(0)
    u_inv = None
    if inverse_plan is not None and (s.r_input > 0 or s.warm_start == "inverse"):
        u_inv = inverse_plan(needs_inverse)
    if s.warm_start == "cold":
        u_guess = ca.DM.zeros(N)
    elif s.warm_start == "inverse":
        u_guess = ca.if_else(restart, u_inv, shifted)
    else:
        u_guess = ca.if_else(has_plan, shifted, ca.repmat(u_last, N, 1))
    u_ff = u_inv if s.r_input > 0 else ca.DM.zeros(N)
    p = ca.vertcat(condition, u_last, refs, u_ff)

    settings = controller.solvers.rti
    extra_step = _extra_rti_step(problem.rti, N, p.numel())  # one Function for both starts: one name in C

    def rti_steps(guess):
        """The RTI steps from ``guess`` made feasible: the last iterate, and whether they succeeded."""
        w = feasible_guess_expr(guess, u_last, u_min, u_max, rate)
        w, worst, broken = rti_steps_expr(problem.rti, w, p, settings.iterations, settings.extra_step_tolerance,
                                          extra_step)
        return w, ca.logic_and(ca.logic_and(ca.logic_not(lost), ca.logic_not(broken)), worst <= QP_TOLERANCE)

    w, success = rti_steps(u_guess)
    pause_next = part("paused")
    if s.multistart:  # also from the inverse where the first plan tracks badly (and did not start there)
        if inverse_plan is None or problem.rti_outcome is None:
            raise NotGeneratable("nmpc.multistart needs an inverse model and an RTI step over the inputs (its cost)")
        cost, end_error = problem.rti_outcome(w, p)
        limit = second_start_cost(s)
        paused = part("paused") > 0.5
        tracks = ca.MX(0) if limit is None else ca.logic_or(  # a NaN cost or end error does not track
            ca.logic_or(cost <= limit, ca.fabs(end_error) <= s.second_start_error), paused)
        from_inverse = restart if s.warm_start == "inverse" else ca.MX(0)
        second = ca.logic_and(ca.logic_not(ca.logic_and(success, tracks)),
                              ca.logic_not(ca.logic_or(from_inverse, lost)))  # Python solves on neither
        u_second = u_inv if s.r_input > 0 else inverse_plan(second)
        w_inv, worst_inv, broken_inv, cost_inv = _second_start(problem, settings, extra_step, N, p.numel(),
                                                               u_min, u_max, rate)(second, u_second, p, u_last)
        success_inv = ca.logic_and(ca.logic_and(second, ca.logic_not(lost)),
                                   ca.logic_and(ca.logic_not(broken_inv), worst_inv <= QP_TOLERANCE))
        take = ca.logic_and(success_inv, ca.logic_or(ca.logic_not(success), cost_inv < cost))
        w, success = ca.if_else(take, w_inv, w), ca.logic_or(take, success)
        pause_next = ca.if_else(ca.logic_and(second, ca.logic_not(take)), s.second_start_pause,
                                ca.fmax(part("paused") - 1, 0))

    planned = ca.if_else(success, w[0], plan[min(1, N - 1)])
    # the fallback when neither the step nor the last plan gives a finite input: never a NaN to the actuator
    falls_back = ca.logic_not(ca.logic_and(ca.logic_or(success, has_plan), ca.fabs(planned) < ca.inf))
    fallback = u_last
    if inverse_plan is not None:  # the inverse's first input, computed again only if not at hand
        at_hand, held = (needs_inverse, u_inv) if u_inv is not None else (ca.MX(0), None)
        if u_inv is None and s.multistart:
            at_hand, held = second, u_second
        again = inverse_plan(ca.logic_and(falls_back, ca.logic_not(at_hand)))
        fallback = again[0] if held is None else ca.if_else(at_hand, held[0], again[0])
    u = ca.if_else(falls_back, fallback, planned)
    if np.isfinite(rate):
        u = clip(u, u_last - rate, u_last + rate)
    u = clip(u, u_min, u_max)
    status = ca.if_else(lost, 2, ca.if_else(success, 0, 1))
    mem_next = layout.pack(
        mem, **estimated, u_last=u, started=1, plan=ca.if_else(success, w, plan), has_plan=success,
        ref_end=refs[-1], has_ref_end=1, failures=part("failures") + ca.logic_not(success),
        estimator_resets=part("estimator_resets") + lost, paused=pause_next)
    feedback = ca.Function(f"{name}_feedback", [mem, z, window], [mem_next, u, status, predicted],
                           ["mem", "z", "ref_preview"], ["mem_next", "u", "status", "predicted"])
    return feedback, prepare, layout


def controller_code(controller, name: str) -> ControllerCode:
    """What :func:`hystmpc.mpc.codegen.write_controller` writes for ``controller``.

    Parameters
    ----------
    controller : NmpcController
        As in :func:`controller_functions`.
    name : str
        Prefix of the Functions' names.

    Returns
    -------
    ControllerCode
        Its Functions (:func:`controller_functions`, prefixed ``name``) and the facts its C
        header states.

    Raises
    ------
    NotGeneratable
        When the controller cannot be generated.
    """
    feedback, prepare, layout = controller_functions(controller, name)
    sl, rti = layout.slices, controller.solvers.rti
    bounds = controller.bounds
    return ControllerCode(
        feedback=feedback, prepare=prepare, initial_memory=tuple(float(v) for v in layout.initial()),
        offsets={key: sl[key].start for key in ("failures", "u_last", "estimator_resets", "planner_failures")
                 if key in sl},
        horizon=controller.horizon, sensor_names=tuple(controller.sensor_names),
        bounds=(float(bounds.lower), float(bounds.upper), float(bounds.rate)), iterations=rti.iterations,
        extra_step_tolerance=rti.extra_step_tolerance, warm_start=controller.settings.warm_start, qp=rti.qp,
        sensitivity_block=rti.sensitivity_block, estimator_docs=_estimator_docs(controller),
        qp_dimensions=_daqp_dimensions(controller))


def _estimator_docs(controller) -> dict[str, str]:
    """What ``_step``, ``_prepare`` and ``_init`` do with the estimate, in the header's words."""
    observer = controller.observer
    if isinstance(observer, MemoryObserver):
        memory = "the exact hysteresis memory" + (" and dead time" if observer.memory.delay_samples else "")
        if observer.creeping:
            memory += f" and the creep memory (the last {observer.creep_window + 1} hysteresis outputs)"
        if observer.ekf is None:
            return {"feedback_doc": f"no estimation (the actuator has no sensors: {memory} follows the inputs sent)",
                    "prepare_doc": f"moves {memory} with the input just sent",
                    "init_doc": f"{memory} at rest"}
        on = "the dynamics" if observer.split else "the whole model, the exact states held"
        return {"feedback_doc": f"the EKF's measurement update on {on} (restarting from the sensors when the "
                                "estimate is not finite)",
                "prepare_doc": f"moves {memory} with the input just sent, and the EKF's time update",
                "init_doc": f"{memory} at rest, no estimate yet (the first step starts it from the sensors)"}
    return {"feedback_doc": "the EKF's measurement update (restarting from the sensors when the estimate is "
                            "not finite)",
            "prepare_doc": "the EKF's time update with the input just sent",
            "init_doc": "no estimate yet (the first step starts it from the sensors)"}


def _daqp_dimensions(controller) -> tuple[int, int, int] | None:
    """``(n, m, ms)`` of the DAQP QP in the controller's RTI step (None: it calls no DAQP)."""
    for fun in controller.problem.rti.find_functions():
        if fun.class_name() == "DaqpInterface":
            n, na = fun.sparsity_in("h").size1(), fun.sparsity_in("a").size1()
            return n, n + na, n
    return None


def rti_steps_expr(rti: ca.Function, w, p, iterations: int, extra_step_tolerance: float = np.inf,
                   extra_step: ca.Function | None = None):
    """:func:`hystmpc.mpc.rti.rti_steps` as expressions: ``(w, worst, broken)``.

    A non-finite step keeps the iterate before it, so that the next QP gets finite data.

    Parameters
    ----------
    rti : casadi.Function
        ``rti_step(w, p) -> (w_next, qp_error)``.
    w : casadi.MX
        The first iterate.
    p : casadi.MX
        The step's parameters.
    iterations : int
        Steps to take.
    extra_step_tolerance : float, optional
        One more step when the last moved an entry of the iterate by more than this, and no
        step was non-finite (``inf``: never).
    extra_step : casadi.Function, optional
        :func:`_extra_rti_step` of ``rti``, made once per generated controller (None: made
        here when needed).

    Returns
    -------
    w : casadi.MX
        The last finite iterate.
    worst : casadi.MX
        The worst ``qp_error`` (a NaN stays).
    broken : casadi.MX
        Whether a step was not finite.
    """
    worst, broken, moved = ca.MX(0), ca.MX(0), ca.MX(0)

    def take(w, step, taken=None):
        """The iterate after ``step``, counted only where ``taken`` (when given)."""
        nonlocal worst, broken, moved
        w_next, qp_error = step
        new_worst = ca.if_else(ca.logic_or(qp_error <= worst, is_nan(worst)), worst, qp_error)
        finite = all_finite(w_next)
        new_broken = ca.logic_or(broken, ca.logic_not(finite))
        if taken is not None:
            new_worst, new_broken = ca.if_else(taken, new_worst, worst), ca.if_else(taken, new_broken, broken)
        worst, broken = new_worst, new_broken
        moved = ca.mmax(ca.fabs(w_next - w))
        return ca.if_else(finite, w_next, w)

    for _ in range(iterations):
        w = take(w, rti(w, p))
    if np.isfinite(extra_step_tolerance):
        needed = ca.logic_and(ca.logic_not(broken), moved > extra_step_tolerance)
        extra_step = extra_step or _extra_rti_step(rti, w.numel(), p.numel())
        w = take(w, extra_step(needed, w, p), needed)
    return w, worst, broken


def _second_start(problem, settings, extra_step: ca.Function, N: int, n_p: int, u_min: float, u_max: float,
                  rate: float) -> ca.Function:
    """``start(needed, u_start, p, u_last) -> (w, worst, broken, cost)``: a second start.

    The RTI steps from ``u_start`` made feasible, and the cost there, where ``needed``; else
    a broken result. Through a switch, so that generated code solves from the second start only on the samples
    that need it.
    """
    u_start, p, u_last = ca.MX.sym("u_start", N), ca.MX.sym("p", n_p), ca.MX.sym("u_last")
    w = feasible_guess_expr(u_start, u_last, u_min, u_max, rate)
    w, worst, broken = rti_steps_expr(problem.rti, w, p, settings.iterations, settings.extra_step_tolerance,
                                      extra_step)
    solve = ca.Function("second_start", [u_start, p, u_last], [w, worst, broken, problem.rti_cost(w, p)])
    skip = ca.Function("no_second_start", [u_start, p, u_last], [u_start, ca.MX(0), ca.MX(1), ca.MX(np.inf)])
    return ca.Function.if_else("second_start_if_needed", solve, skip)


def _extra_rti_step(rti: ca.Function, N: int, n_p: int) -> ca.Function:
    """``step(needed, w, p)``: ``rti(w, p)`` where ``needed``, else ``(w, 0)``, through a switch.

    The switch lets generated code take the step only on the samples that need it.
    """
    w, p = ca.MX.sym("w", N), ca.MX.sym("p", n_p)
    skip = ca.Function("no_extra_rti_step", [w, p], [w, ca.MX(0)])
    return ca.Function.if_else("extra_rti_step_if_needed", ca.Function("extra_rti_step", [w, p], list(rti(w, p))), skip)


def _inverse_plan(controller, est: Estimate, refs, u_last, N: int):
    """``plan(needed)``: the inverse model's inputs for ``refs`` from the estimate ``est``.

    The inputs (bounded; a non-finite one replaced by ``u_last``) where ``needed`` is true,
    zeros where it is false, through a switch, so that generated code computes the inverse only
    when needed.
    """
    fields = {k: v for k, v in vars(est).items() if v is not None}
    symbols = {k: ca.MX.sym(k, ca.MX(v).sparsity()) for k, v in fields.items()}
    refs_s, u_last_s = ca.MX.sym("refs", N), ca.MX.sym("u_last")
    model = getattr(controller.inverse, "hysteresis", None)  # the default inverse: hystmpc's own model
    if model is None:
        what, advice = "the inverse model", "write it with casadi operations for a generated controller"
    else:
        what = f"{type(model).__name__}.inverse_step"
        advice = ("this model has no symbolic inverse yet, so its whole controller is not generated (from Python, "
                  "one with nmpc.warm_start=shift and its inverse set to None can be)")
    raw = symbolic(lambda r: controller.inverse(Estimate(**symbols), r), what, refs_s, N, advice)
    bounds = controller.bounds
    plan = clip(ca.if_else(ca.fabs(raw) < ca.inf, raw, u_last_s), float(bounds.lower), float(bounds.upper))
    inputs = [*symbols.values(), refs_s, u_last_s]
    switch = ca.Function.if_else("inverse_plan_if_needed", ca.Function("inverse_plan", inputs, [plan]),
                                 ca.Function("no_inverse_plan", inputs, [ca.DM.zeros(N)]))
    return lambda needed: switch(needed, *fields.values(), refs, u_last)


class FunctionController:
    """``feedback`` and ``prepare`` run in Python as a controller of :mod:`hystmpc.experiments.runner`.

    This is to check them, and the generated C built from them, against the Python controller.

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
        self.mem = self.layout.initial()
        self.statuses: dict[int, int] = {}
        self.predicted_output = float("nan")

    def step(self, measurement, ref_window) -> float:
        """One feedback call, then the prepare call for the next sample.

        Parameters
        ----------
        measurement : Measurement
            This sample's measurement.
        ref_window : array_like
            References ``r_k..r_{k+N}``.

        Returns
        -------
        float
            The input ``u``.
        """
        mem, u, status, predicted = self.feedback(self.mem, self.controller.sensors(measurement),
                                                  np.asarray(ref_window, float))
        self.mem = np.asarray(self.prepare(mem)).ravel()
        self.predicted_output = float(predicted)
        self.statuses[int(status)] = self.statuses.get(int(status), 0) + 1
        return float(u)

    def stats(self) -> dict:
        """Failures and restarts counted by the memory, and the status codes seen.

        Returns
        -------
        dict
            ``name`` (``generated``), ``failures``, ``estimator_resets``, ``statuses``
            (status code -> samples) and, with a linear MPC's plan, ``planner_failures``.
        """
        sl = self.layout.slices
        planner = {"planner_failures": int(self.mem[sl["planner_failures"]][0])} if "planner_failures" in sl else {}
        return {"name": "generated", "failures": int(self.mem[sl["failures"]][0]),
                "estimator_resets": int(self.mem[sl["estimator_resets"]][0]), "statuses": dict(self.statuses),
                **planner}
