"""Inverse compensation plus linear MPC: the strong conventional alternative to the NMPC.

A :class:`Compensation` (an actuator's inverse hysteresis model) turns a *virtual* input
``v`` into the actuator input ``u``, so that what remains between ``v`` and the output is
nearly linear. :class:`InverseLinearMpc` controls that remainder with a linear MPC: a
condensed QP over the same horizon, input and rate bounds and reference preview as the
NMPC, solved by OSQP, and a Kalman filter with the same integrating disturbance as the
NMPC's estimator (offset-free tracking); ``lmpc.qp=ipm`` solves the QP with the generated
controller's interior-point method instead (:func:`hystmpc.mpc.qp.interior_point_qp`). The
remainder is given as a
:class:`~hystmpc.models.prediction.PredictionModel` with ``v`` as its input; it is
linearised once at the origin (exact when it is linear).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Protocol

import casadi as ca
import numpy as np

from hystmpc.models.prediction import PredictionModel
from hystmpc.mpc.linear_mpc_matrices import condense
from hystmpc.mpc.qp import SMALLEST_WIDTH
from hystmpc.mpc.rti import QP_TOLERANCE
from hystmpc.mpc.settings import InputBounds

LINEAR_MPC_QPS = ("osqp", "ipm")
"""The linear MPC's QP solvers (``lmpc.qp``)."""


class Compensation(Protocol):
    """An inverse model between the linear MPC's virtual input ``v`` and the actuator input ``u``."""

    def reset(self) -> None:
        """Forget the model's memory."""

    def update(self, measurement) -> None:
        """See this sample's measurement (before :meth:`to_input` / :meth:`to_virtual`).

        Parameters
        ----------
        measurement : Measurement
            This sample's measurement.
        """

    def to_input(self, v: float) -> float:
        """The actuator input that gives the virtual input ``v`` now.

        Parameters
        ----------
        v : float
            Virtual input.

        Returns
        -------
        float
            Actuator input.
        """

    def to_virtual(self, u: float) -> float:
        """The virtual input that the actuator input ``u`` gives now (monotone in ``u``).

        Parameters
        ----------
        u : float
            Actuator input.

        Returns
        -------
        float
            Virtual input.
        """

    def applied(self, u: float) -> None:
        """The input actually sent this sample (input-driven memories follow it).

        Parameters
        ----------
        u : float
            Actuator input sent.
        """

    def inputs_along(self, vs) -> np.ndarray:
        """The actuator inputs that give the virtual inputs ``vs`` one after another.

        They start from the present memory, which is left as it is.

        Parameters
        ----------
        vs : array_like
            Virtual inputs, one per sample.

        Returns
        -------
        ndarray
            One actuator input per virtual input (NaN where one is out of reach).
        """

    def sensors(self, measurement) -> np.ndarray:
        """The linear model's sensor vector for this measurement.

        Parameters
        ----------
        measurement : Measurement
            This sample's measurement.

        Returns
        -------
        ndarray
            The sensor vector, in the order of the model's ``sensor_names``.
        """


@dataclass(frozen=True)
class LinearMpcSettings:
    """The linear MPC of ``inverse-lmpc`` (``--set lmpc.KEY=VALUE``)."""

    horizon: int = 20
    """Prediction (and control) horizon N in samples: the NMPC's, for a fair comparison
    (``--set nmpc.horizon=N`` alone sets both)."""
    q_output: float = 1.0
    """Weight on the squared tracking error of each predicted output."""
    r_rate: float = 0.3
    """Weight on the squared change of the virtual input per sample."""
    qp: str = "osqp"
    """QP solver: ``osqp``, or ``ipm``, the interior-point QP the generated controller runs
    (a generated NMPC's planner uses it; ``codegen`` sets it)."""

    def __post_init__(self):
        if self.horizon < 2:
            raise ValueError(f"horizon must be >= 2, got {self.horizon}")
        if not (np.isfinite(self.q_output) and self.q_output > 0):
            raise ValueError(f"q_output must be finite and > 0, got {self.q_output}")
        if not (np.isfinite(self.r_rate) and self.r_rate >= 0):
            raise ValueError(f"r_rate must be finite and >= 0, got {self.r_rate}")
        if self.qp not in LINEAR_MPC_QPS:
            raise ValueError(f"qp {self.qp!r} is unknown; allowed: {', '.join(LINEAR_MPC_QPS)}")


def one_sample_delay(sample_period: float) -> PredictionModel:
    """The remainder of a feed-forward actuator whose inverse is exact and static.

    Parameters
    ----------
    sample_period : float
        Sample period (s).

    Returns
    -------
    PredictionModel
        One state; the output is the virtual input one sample later; no sensors, no disturbance.
    """
    x, v, d = ca.SX.sym("x", 1), ca.SX.sym("v"), ca.SX.sym("d", 0)
    return PredictionModel(
        step=ca.Function("delay_step", [x, v, d], [v], ["x", "u", "d"], ["x_next"]),
        output=ca.Function("delay_output", [x, d], [x], ["x", "d"], ["y"]),
        measure=ca.Function("delay_measure", [x, d], [ca.SX(0, 1)], ["x", "d"], ["z"]),
        sample_period=sample_period, state_names=("output",), sensor_names=())


class InverseLinearMpc:
    """Inverse compensation + offset-free linear MPC (condensed onto the virtual inputs).

    Each sample: the compensation sees the measurement; the Kalman filter's time update
    with the last virtual input and its measurement update; the virtual bounds (the
    actuator's bounds and rate, through the compensation, held over the horizon); the QP
    over ``v_0..v_{N−1}``; ``u = to_input(v_0)``, kept inside the bounds. A failed QP is
    counted, and the previous plan's next virtual input is used (or the last one held).

    The QP is OSQP's, or with ``settings.qp='ipm'`` the generated interior-point method's.
    With ``ipm`` and a compensation that has a CasADi form, the filter, the QP and the
    compensation's memory run as :attr:`functions`
    (:class:`~hystmpc.mpc.embedded_planner.PlannerFunctions`, compiled where it can be):
    the Functions a generated NMPC embeds, so that it repeats this planner to the last bit.

    Parameters
    ----------
    model : PredictionModel
        The linear remainder, input ``v``; its disturbance ``d`` is estimated.
    compensation : Compensation
        The inverse model between ``v`` and ``u``.
    bounds : InputBounds
        The actuator's input bounds and rate.
    settings : LinearMpcSettings
        Horizon and weights.
    process_noise, measurement_noise : array_like
        Diagonals of the Kalman filter's covariances (``[x; d]``, sensors).
    initial_state : callable
        ``z -> x0`` from the first sensor vector.
    initial_covariance : array_like
        Diagonal of the initial covariance of ``[x; d]``.
    """

    def __init__(self, model: PredictionModel, compensation: Compensation, bounds: InputBounds,
                 settings: LinearMpcSettings, process_noise, measurement_noise, initial_state,
                 initial_covariance):
        import osqp
        from scipy import sparse

        if model.nu != 1:
            raise ValueError(f"the linear MPC takes one virtual input, the model has {model.nu}")
        self.model, self.compensation, self.bounds, self.settings = model, compensation, bounds, settings
        self.sensor_names = model.sensor_names
        N = settings.horizon
        names = getattr(compensation, "sensor_names", None)
        if names is not None and len(names) != model.nz:
            raise ValueError(f"the compensation reads {len(names)} signals ({', '.join(names) or 'none'}); the linear "
                             f"model has {model.nz} sensors ({', '.join(model.sensor_names) or 'none'})")
        self.initial_state = initial_state
        self.matrices = condense(model, settings, process_noise, measurement_noise, initial_covariance)
        P = self.matrices.hessian
        try:
            if not np.all(np.isfinite(P)):
                raise ValueError("its Hessian is not finite")
            if settings.qp == "ipm":
                from hystmpc.mpc.qp import interior_point_qp
                self._rows = ca.sparsify(ca.DM(self.qp_rows()))
                self._ipm = interior_point_qp(ca.Sparsity.dense(N, N), self._rows.sparsity())
            else:
                self._qp = osqp.OSQP()
                self._qp.setup(P=sparse.csc_matrix(np.triu(P)), q=np.zeros(N),
                               A=sparse.csc_matrix(np.vstack((np.eye(N), self.matrices.D))),
                               l=np.full(2 * N, -1e30), u=np.full(2 * N, 1e30), verbose=False, warm_starting=True,
                               eps_abs=1e-7, eps_rel=1e-7, max_iter=10000, polishing=False)
        except (ValueError, osqp.OSQPException) as exc:  # an unstable model's prediction over N samples explodes
            reason = exc if isinstance(exc, ValueError) else "OSQP could not factor it"
            raise ValueError(f"the linear MPC's QP over {N} samples cannot be set up ({reason}): "
                             f"its linear model's prediction is not usable (largest |P| entry "
                             f"{np.max(np.abs(np.nan_to_num(P, nan=np.inf))):.3g}); check the model's "
                             "parameters") from None
        self.functions, self._compiled = _compiled_planner(self) if settings.qp == "ipm" else (None, None)
        self.reset()

    @property
    def horizon(self) -> int:
        """Reference preview in samples (the horizon)."""
        return self.settings.horizon

    def reset(self) -> None:
        """Forget estimate, plan, compensation memory and counters."""
        self.compensation.reset()
        if self.functions is not None:
            self._memory = self.functions.memory_at_rest.copy()
        self._started = False
        self._u_last = 0.0
        self._v_last = 0.0
        self._plan = None
        self.failures = 0
        self.solve_times: list[float] = []
        self.predicted_output = float("nan")

    def _restart(self, z) -> None:
        self._z = np.concatenate((np.asarray(self.initial_state(z), float).ravel(), np.zeros(self.model.nd)))
        self._P = self.matrices.initial_covariance.copy()

    def step(self, measurement, ref_window) -> float:
        """One sample: a measurement and the references ``r_k..r_{k+N}`` in, the input out.

        Parameters
        ----------
        measurement : Measurement
            This sample's measurement.
        ref_window : array_like
            References ``r_k..r_{k+N}``; the QP tracks ``r_{k+1}..r_{k+N}``.

        Returns
        -------
        float
            The actuator input sent, inside the bounds (the last one where the compensation
            gives no finite input).
        """
        v = self._solve(measurement, ref_window)
        u = self.compensation.to_input(v)
        u_prev = self._u_last if self._started else 0.0
        if not np.isfinite(u):
            u = u_prev
        u = self.bounds.clip(u, u_prev if self._started else None)
        self.applied(u)
        return u

    def plan(self, measurement, ref_window) -> np.ndarray:
        """One sample's estimate and QP without sending anything: the planned actuator inputs.

        The planned inputs are ``u_0..u_{N−1}`` (the virtual plan through the compensation, from
        its present memory; NaN where out of reach). :meth:`applied` must then be told the input
        sent.

        This is the warm start ``nmpc.inverse_plan=linear-mpc`` gives the NMPC.

        Parameters
        ----------
        measurement : Measurement
            This sample's measurement.
        ref_window : array_like
            References ``r_k..r_{k+N}``, as in :meth:`step`.

        Returns
        -------
        ndarray
            The planned actuator inputs ``u_0..u_{N−1}``.
        """
        v = self._solve(measurement, ref_window)
        if self.functions is not None:
            return np.asarray(self._compiled["inputs_along"](self._memory, self._virtual_plan), float).ravel()
        virtual = self._plan if self._plan is not None else np.full(self.horizon, v)
        return np.asarray(self.compensation.inputs_along(virtual), float)

    def prepare_plan(self) -> None:
        """Build what :meth:`plan` needs ahead of the first sample.

        That is the compensation's compiled inverse over the horizon, where it has one.
        """
        prepare = getattr(self.compensation, "prepare_chain", None)
        if prepare is not None and self.functions is None:  # else the compiled functions' chain is used
            prepare(self.horizon)

    def applied(self, u: float) -> None:
        """The input sent this sample: the Kalman filter and the compensation's memory follow it.

        Parameters
        ----------
        u : float
            Actuator input sent.
        """
        if self.functions is not None:  # as the generated controller: the same Functions
            memory, state, covariance = self._compiled["applied"](self._memory, self._z, self._P.ravel(order="F"), u)
            self._memory, self._z = np.asarray(memory, float).ravel(), np.asarray(state, float).ravel()
            self._P = np.asarray(covariance, float).reshape(len(self._z), -1, order="F")
        else:
            self._v_last = self.compensation.to_virtual(u)
        self.compensation.applied(u)
        self._u_last = u
        self._started = True

    def _solve(self, measurement, ref_window) -> float:
        """The estimate's updates and the QP: this sample's virtual input.

        The input is the plan's first, or after a failed QP the previous plan's next, or the
        last one held.
        """
        N = self.horizon
        ref = np.asarray(ref_window, float).ravel()[1: N + 1]
        self.compensation.update(measurement)
        z = np.asarray(self.compensation.sensors(measurement), float)
        if self.functions is not None:
            return self._solve_as_generated(z, ref)
        kf = self.matrices
        if self._started:
            self._z = kf.A @ self._z + kf.B * self._v_last + kf.f
            self._P = kf.A @ self._P @ kf.A.T + kf.Q
        else:
            self._restart(z)
        self.predicted_output = float(kf.Cy @ self._z + kf.y0)
        if self.model.nz:  # a feed-forward remainder (no sensors) only predicts
            C = kf.C
            gain = np.linalg.solve(C @ self._P @ C.T + kf.R, C @ self._P).T
            self._z = self._z + gain @ (z - C @ self._z - kf.z0)
            joseph = np.eye(len(self._z)) - gain @ C
            self._P = joseph @ self._P @ joseph.T + gain @ kf.R @ gain.T
        if not np.all(np.isfinite(self._z)):
            self._restart(z)
        state = self._z
        b, s = self.bounds, self.settings
        to_v = self.compensation.to_virtual
        u_prev = self._u_last if self._started else 0.0
        v_prev = to_v(u_prev)
        v_low, v_high = sorted((to_v(b.lower), to_v(b.upper)))
        rate_low, rate_high = -np.inf, np.inf
        if np.isfinite(b.rate):
            steps = (to_v(max(u_prev - b.rate, b.lower)) - v_prev, to_v(min(u_prev + b.rate, b.upper)) - v_prev)
            least = SMALLEST_WIDTH * (v_high - v_low) if s.qp == "ipm" else 0.0  # the method needs l < u
            rate_low, rate_high = -max(-min(steps), least), max(max(steps), least)
        free = kf.Phi @ state + kf.offset
        e0 = np.zeros(N)
        e0[0] = v_prev
        grad = 2 * (s.q_output * kf.G.T @ (free - ref) - s.r_rate * kf.D.T @ e0)
        lower = np.concatenate((np.full(N, v_low), np.full(N, rate_low)))
        upper = np.concatenate((np.full(N, v_high), np.full(N, rate_high)))
        lower[N] += v_prev
        upper[N] += v_prev
        start = time.perf_counter()
        if s.qp == "ipm":  # rows of finite bounds only (qp_rows)
            rows = self._rows.size1()
            x, residual, _ = self._ipm(kf.hessian, grad, self._rows, lower[:rows], upper[:rows])
            x = np.asarray(x, float).ravel()
            solved = float(residual) <= QP_TOLERANCE
        else:
            lower, upper = np.maximum(lower, -1e30), np.minimum(upper, 1e30)
            self._qp.update(q=grad, l=lower, u=upper)
            result = self._qp.solve(raise_error=False)
            x, solved = result.x, result.info.status_val in (1, 2)
        self.solve_times.append(time.perf_counter() - start)
        if solved and np.all(np.isfinite(x)):
            self._plan = x
            return float(x[0])
        self.failures += 1
        v = float(self._plan[1]) if self._plan is not None else v_prev
        self._plan = None
        return v

    def _solve_as_generated(self, z, ref) -> float:
        """:meth:`_solve` by :attr:`functions` (the filter's time update ran in :meth:`applied`)."""
        kf, N = self.matrices, self.horizon
        started = self._started
        if started:
            self.predicted_output = float(kf.Cy @ self._z + kf.y0)
        state = self._z if started else np.zeros(len(kf.A))
        covariance = self._P.ravel(order="F") if started else np.zeros(len(kf.A) ** 2)
        plan = self._plan if self._plan is not None else np.zeros(N)
        start = time.perf_counter()
        out = self._compiled["plan"](self._memory, state, covariance, plan, float(self._plan is not None), z,
                                  float(started), ref, self._u_last if started else 0.0)
        self.solve_times.append(time.perf_counter() - start)
        state, covariance, plan, solved, virtual = (np.asarray(v, float).ravel() for v in out)
        self._z, self._P = state, covariance.reshape(len(state), -1, order="F")
        if not started:  # from the state the filter starts from, before its measurement update
            restart = np.concatenate((np.asarray(self.initial_state(z), float).ravel(), np.zeros(self.model.nd)))
            self.predicted_output = float(kf.Cy @ restart + kf.y0)
        self._virtual_plan = virtual
        if solved[0] > 0.5:
            self._plan = plan
        else:
            self.failures += 1
            self._plan = None
        return float(virtual[0])

    def qp_rows(self) -> np.ndarray:
        """The constraint rows of the ``ipm`` QP: bounds on ``v``, and on its changes when the rate is bounded.

        Returns
        -------
        ndarray
            ``I``, or ``[I; D]`` with a finite rate (the interior-point QP needs finite bounds).
        """
        N = self.horizon
        return np.vstack((np.eye(N), self.matrices.D)) if np.isfinite(self.bounds.rate) else np.eye(N)

    def stats(self) -> dict:
        """QP failures (each one a fallback).

        Returns
        -------
        dict
            ``name`` (``osqp`` or ``ipm``), ``failures`` and ``fallbacks`` (the same count).
        """
        return {"name": self.settings.qp, "failures": self.failures, "fallbacks": self.failures}



def _compiled_planner(planner: InverseLinearMpc):
    """``(functions, compiled)``: the generated controller's :class:`PlannerFunctions` of ``planner``.

    Also their ``applied``, ``plan`` and ``inputs_along`` compiled where they can be; ``(None,
    None)`` where its compensation has no CasADi form.
    """
    from hystmpc.mpc.codegen.toolchain import LOG, compiled_or_slower
    from hystmpc.mpc.embedded_planner import PlannerFunctions
    from hystmpc.mpc.expressions import NotGeneratable
    try:
        functions = PlannerFunctions(planner)
    except NotGeneratable as exc:
        LOG.info(f"lmpc.qp=ipm: {str(exc).split('; or set')[0]}: the linear MPC runs its NumPy sample, which a "
                 "generated controller does not repeat to the last bit")
        return None, None
    compiled = {name: compiled_or_slower(getattr(functions, name), "the linear MPC runs in-process, slower")
                for name in ("applied", "plan", "inputs_along")}
    return functions, compiled
