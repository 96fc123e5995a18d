"""What the NMPC knows each sample: the state estimate and the problem's initial condition.

Two observers cover the prediction models of :mod:`hystmpc.models.prediction`:

* :class:`StateObserver`: an EKF on the whole model, for a hysteresis driven by a state
  (its memory can only be estimated);
* :class:`MemoryObserver`: for an input-driven model, the dead time, the hysteresis and
  the creep follow exactly from the inputs applied, so they are run exactly; an EKF
  estimates only the dynamics (or nothing, for a feed-forward actuator without sensors).

Both restart from the sensors when the estimate stops being finite, and count it.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass

import casadi as ca
import numpy as np

from hystmpc.models.base import symbolic
from hystmpc.models.fractional import gl_weights, window_functions
from hystmpc.models.prediction import CreepPredictionModel, InputMemory, PredictionModel
from hystmpc.mpc.codegen.toolchain import compiled_or_slower
from hystmpc.mpc.estimator import DisturbanceEKF


@dataclass
class Estimate:
    """The observer's knowledge at one sample."""

    x: np.ndarray
    """State of the prediction model (for a creep model: of its dynamics)."""
    d: np.ndarray
    """Disturbance estimate."""
    hysteresis: np.ndarray | None = None
    """Exact hysteresis state (input-driven models)."""
    history: np.ndarray | None = None
    """Creep history terms over the horizon (creep models)."""
    queue: np.ndarray | None = None
    """Inputs applied but still in the dead time, oldest first (input-driven models)."""


def _finite(*arrays) -> bool:
    return all(np.all(np.isfinite(a)) for a in arrays)


class StateObserver:
    """EKF on ``[x; d]`` of the whole prediction model.

    Parameters
    ----------
    model : PredictionModel
        The prediction model.
    ekf : DisturbanceEKF
        An EKF on ``model``.
    initial_state : callable
        ``z -> x0``: a state estimate from the first sensor vector.
    initial_covariance : array_like
        Diagonal of the EKF's covariance on ``[x; d]`` at a (re)start.
    """

    def __init__(self, model: PredictionModel, ekf: DisturbanceEKF, initial_state: Callable,
                 initial_covariance):
        self.model, self.ekf, self.initial_state = model, ekf, initial_state
        self.initial_covariance = np.asarray(initial_covariance, float)
        self.predicted_output = float("nan")

    def reset(self) -> None:
        """Nothing to forget: the first :meth:`update` starts the estimate."""
        self.predicted_output = float("nan")

    def _restart(self, z) -> None:
        self.ekf.reset(np.asarray(self.initial_state(z), float), np.zeros(self.model.nd), self.initial_covariance)

    def update(self, z, u_last: float | None) -> bool:
        """Time update with the input applied last sample (None: first sample), measurement update.

        Parameters
        ----------
        z : array_like
            The sensor vector of this sample.
        u_last : float or None
            The input applied last sample (None: first sample, a start from ``z``).

        Returns
        -------
        bool
            True when the estimate was not finite and restarted from ``z``.
        """
        ekf = self.ekf
        if u_last is None:
            self._restart(z)
        else:
            ekf.predict([u_last])
        self.predicted_output = float(self.model.output(ekf.x, ekf.d))
        ekf.update(z)
        if _finite(ekf.x, ekf.d):
            return False
        self._restart(z)
        return True

    def estimate(self, horizon: int) -> Estimate:
        """The current estimate.

        Parameters
        ----------
        horizon : int
            Prediction horizon (samples); not used here (as :meth:`MemoryObserver.estimate`).

        Returns
        -------
        Estimate
            Copies of the EKF's ``x`` and ``d``.
        """
        return Estimate(self.ekf.x.copy(), self.ekf.d.copy())

    def condition(self, estimate: Estimate) -> np.ndarray:
        """``[x; d]``: the multiple-shooting problem's initial condition.

        Parameters
        ----------
        estimate : Estimate
            An estimate of this observer.

        Returns
        -------
        ndarray
            ``[x; d]``.
        """
        return np.concatenate((estimate.x, estimate.d))


class MemoryObserver:
    """Exact dead time, hysteresis and creep from the applied inputs; an EKF on the rest.

    The EKF runs on ``model.memory.dynamics`` (the dynamics driven by the exact hysteresis
    output) where the model splits so; otherwise on the whole model, with the exact states
    held at their values (no process noise, no covariance: the measurement never moves them).

    Parameters
    ----------
    model : PredictionModel or CreepPredictionModel
        An input-driven model (``model.memory`` set).
    ekf : DisturbanceEKF, optional
        An EKF on ``model.memory.dynamics``, or on ``model`` when that is None; None for a
        model without dynamic states or sensors (the state then follows the inputs open loop).
    initial_state : callable, optional
        ``z -> x_dyn0``, the dynamic states from the first sensor vector (default: zeros).
    initial_covariance : array_like, optional
        Diagonal of the EKF's covariance at a (re)start (default: the EKF's own).
    creep_window : int, optional
        Past samples in the creep sums (None: the whole memory).
    rest_input : float
        Input the actuator rests at before the first sample.
    """

    def __init__(self, model: PredictionModel | CreepPredictionModel, ekf: DisturbanceEKF | None = None,
                 initial_state: Callable | None = None, initial_covariance=None,
                 creep_window: int | None = None, rest_input: float = 0.0):
        if model.memory is None:
            raise ValueError("a MemoryObserver needs an input-driven model (model.memory is None)")
        self.model, self.ekf = model, ekf
        self.memory: InputMemory = model.memory
        self.split = self.memory.dynamics is not None
        if ekf is None and (self.memory.n_dynamic or model.sensor_names):
            raise ValueError("a model with dynamic states or sensors needs an EKF")
        n_dyn = self.memory.n_dynamic
        self.initial_state = initial_state or (self._at_rest if self.memory.rest_state else
                                               (lambda z: ca.DM.zeros(n_dyn) if symbolic(z) else np.zeros(n_dyn)))
        covariance = np.diag(ekf.P).copy() if initial_covariance is None and ekf is not None else initial_covariance
        self.initial_covariance = None if covariance is None else np.asarray(covariance, float)
        if ekf is not None and not self.split:  # hold the exact states: no noise, no covariance
            held = np.arange(n_dyn, model.nx)
            ekf.Q[held, :] = 0.0
            ekf.Q[:, held] = 0.0
            self.initial_covariance[held] = 0.0
        self.creep_window, self.rest_input = creep_window, float(rest_input)
        self.creeping = isinstance(model, CreepPredictionModel)
        self.exact_step = exact_step(self.memory.hysteresis, rest_input)
        self._history: dict[int, ca.Function] = {}
        if self.creeping and creep_window is not None:  # fixed-size sums, as a generated controller runs them
            self._push = window_functions(-self.memory.creep_order, model.sample_period, creep_window, 1)[0]
        self.reset()

    def _at_rest(self, z):
        """The dynamic states at rest at the first sensor value (the dynamics' ``rest_state``)."""
        mem = self.memory
        h = mem.steady_input(z[0]) if mem.steady_input is not None else z[0]
        states = mem.rest_state(h)
        return ca.vertcat(*states) if symbolic(z) else np.array([float(v) for v in states])

    def reset(self) -> None:
        """At rest: relaxed hysteresis, a queue of the rest input, empty creep memory."""
        mem = self.memory
        self.hysteresis_state = mem.hysteresis.initial_state(self.rest_input)
        self.queue = [self.rest_input] * mem.delay_samples
        self.creep = None
        self.creep_buffer = np.zeros(self.creep_window + 1) if self.creeping and self.creep_window is not None else None
        if self.creeping and self.creep_buffer is None:
            from hystmpc.models.fractional import GrunwaldLetnikov
            self.creep = GrunwaldLetnikov(-mem.creep_order, self.model.sample_period, self.creep_window)
        self.x = np.zeros(mem.n_dynamic)
        self.d = np.zeros(self.model.nd)
        self.predicted_output = float("nan")

    def _hold(self) -> None:
        """The whole-model EKF's exact states set to the exact memory."""
        if self.ekf is not None and not self.split:
            self.ekf.x = self._state(self.ekf.x[: self.memory.n_dynamic])

    def _restart(self, z) -> None:
        if self.ekf is not None:
            x0 = np.asarray(self.initial_state(z), float)
            self.ekf.reset(x0 if self.split else self._state(x0), np.zeros(self.model.nd), self.initial_covariance)

    def update(self, z, u_last: float | None) -> bool:
        """Run the exact memory with the input applied last sample (None: first sample), then the EKF.

        Parameters
        ----------
        z : array_like
            The sensor vector of this sample.
        u_last : float or None
            The input applied last sample (None: first sample, a start from ``z``).

        Returns
        -------
        bool
            True when the estimate was not finite and restarted from ``z``.
        """
        if u_last is None:
            self._restart(z)
        else:
            self.queue.append(float(u_last))
            u_in = self.queue.pop(0)
            self.hysteresis_state, h = self.exact_step(self.hysteresis_state, u_in)
            if self.creep is not None:
                h = self.creep.push(h)
            elif self.creep_buffer is not None:
                buffer, h = self._push(self.creep_buffer, h)
                self.creep_buffer, h = np.asarray(buffer, float).ravel(), float(h)
            if self.ekf is not None:
                self.ekf.predict([h] if self.split else [u_last])
        self._hold()
        restarted = False
        if self.ekf is not None:
            ekf = self.ekf
            output = self.memory.dynamics.output if self.split else self.model.output
            self.predicted_output = float(output(ekf.x, ekf.d))
            ekf.update(z)
            self._hold()
            if not _finite(ekf.x, ekf.d):
                self._restart(z)
                restarted = True
            self.x, self.d = ekf.x[: self.memory.n_dynamic], ekf.d
        else:
            self.predicted_output = float(self.model.output(self._state(self.x), self.d))
        return restarted

    def _state(self, x_dyn) -> np.ndarray:
        return np.concatenate((x_dyn, self.hysteresis_state, self.queue))

    def estimate(self, horizon: int) -> Estimate:
        """The current estimate (with the creep history over ``horizon`` samples, if any).

        Parameters
        ----------
        horizon : int
            Prediction horizon (samples) of the creep history terms.

        Returns
        -------
        Estimate
            Copies of the state (for a creep model: of its dynamics; else the whole model's
            state), the disturbance, the hysteresis state, the creep history (None without
            creep) and the dead-time queue.
        """
        history = self.creep.history_terms(horizon) if self.creep is not None else None
        if self.creep_buffer is not None:
            if horizon not in self._history:
                self._history[horizon] = window_functions(-self.memory.creep_order, self.model.sample_period,
                                                          self.creep_window, horizon)[1]
            history = np.asarray(self._history[horizon](self.creep_buffer), float).ravel()
        x = self.x.copy() if self.creeping else self._state(self.x)
        return Estimate(x, self.d.copy(), self.hysteresis_state.copy(), history, np.array(self.queue))

    def condition(self, estimate: Estimate) -> np.ndarray:
        """The problem's initial condition.

        Parameters
        ----------
        estimate : Estimate
            An estimate of this observer.

        Returns
        -------
        ndarray
            ``[x; d]`` (Markov model) or the creep model's ``[hysteresis state, x_dyn, d, history]``.
        """
        if self.creeping:
            return np.concatenate((estimate.hysteresis, estimate.x, estimate.d, estimate.history))
        return np.concatenate((estimate.x, estimate.d))


def exact_step(hysteresis, rest_input: float = 0.0) -> Callable:
    """``(state, u) -> (state, y)`` of ``hysteresis`` in NumPy.

    Parameters
    ----------
    hysteresis : HysteresisModel
        The model whose exact ``step`` runs.
    rest_input : float, optional
        Rest input; only the size of the initial state at it is used.

    Returns
    -------
    callable
        Its exact step evaluated as a CasADi Function where the step accepts CasADi expressions
        (the same arithmetic as a generated controller, to the last bit), else the model's own
        ``step``.
    """
    n = len(hysteresis.initial_state(rest_input))
    state, u = ca.SX.sym("state", n), ca.SX.sym("u")
    try:
        with warnings.catch_warnings():  # a NumPy-only step on a CasADi symbol warns before it fails
            warnings.simplefilter("ignore")
            fun = ca.Function("exact_step", [state, u], [*hysteresis.step(state, u)])
    except Exception:  # noqa: BLE001 - a NumPy-only step fails in many ways: use it as it is
        return hysteresis.step

    def step(x, v):
        x_next, y = fun(x, v)
        return np.asarray(x_next, float).ravel(), float(y)
    return step



def memory_inverse(memory: InputMemory, sample_period: float) -> Callable[[Estimate, np.ndarray], np.ndarray]:
    """The inverse warm start of an input-driven model, from its parts.

    For each reference (the one the input reaches after the dead time): the static
    inverse of the dynamics gives the hysteresis output that holds it (corrected by the
    disturbance where it enters; in the dynamics, by the model's ``steady_correction``), the
    creep inverse the creep-free output (the GL sum solved for its newest term), and the
    hysteresis model's ``inverse_step`` the input.
    A target the hysteresis cannot reach keeps the previous input (NaN before the first).

    Parameters
    ----------
    memory : InputMemory
        The parts of an input-driven model (``model.memory``).
    sample_period : float
        Sample period (s), for the creep inverse.

    Returns
    -------
    callable
        ``(estimate, refs) -> inputs``, one input per reference; NumPy, or CasADi expressions
        for a symbolic estimate. Its ``prepare(estimate, n)`` builds (and compiles) the inverse
        for ``n`` references ahead of the first sample; ``hysteresis`` is the model inverted.

    Raises
    ------
    ValueError
        When the model's dynamics give no ``steady_input``.
    """
    if memory.steady_input is None:
        raise ValueError("no inverse warm start: the model's Dynamics give no steady_input (the hysteresis "
                         "output that holds an output at rest); give one, or an inverse, or use "
                         "nmpc.warm_start=shift")
    steady, mode, hysteresis = memory.steady_input, memory.disturbance, memory.hysteresis
    correct = memory.steady_correction or (lambda h, d: h)
    alpha = memory.creep_order

    functions: dict[tuple, ca.Function | None] = {}

    def as_function(est: Estimate, n: int) -> ca.Function | None:
        """The symbolic inverse for ``n`` references as a Function (None: no CasADi form)."""
        sizes = tuple(0 if v is None else len(v) for v in (est.x, est.d, est.hysteresis, est.history, est.queue))
        if (n, sizes) not in functions:
            names = ("x", "d", "hysteresis", "history", "queue")
            parts = [ca.MX.sym(name, size) for name, size in zip(names, sizes, strict=True)]
            refs = ca.MX.sym("refs", n)
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    out = symbolic_inverse(Estimate(parts[0], parts[1], parts[2], parts[3] if sizes[3] else None,
                                                    parts[4] if sizes[4] else None), refs)
                fun = ca.Function("memory_inverse", [*parts, refs], [out])
            except Exception:  # noqa: BLE001 - no CasADi form: the NumPy steps below
                functions[n, sizes] = None
            else:
                # compiled: the same numbers, several times faster
                functions[n, sizes] = compiled_or_slower(fun, "the inverse model runs in-process, slower")
        return functions[n, sizes]

    def inverse(est: Estimate, refs) -> np.ndarray:
        if symbolic(est.hysteresis):
            return symbolic_inverse(est, refs)
        refs = np.asarray(refs, float)
        fun = as_function(est, len(refs))
        if fun is not None:  # the arithmetic of a generated controller
            empty = np.zeros(0)
            return np.asarray(fun(est.x, est.d, est.hysteresis, empty if est.history is None else est.history,
                                  empty if est.queue is None else est.queue, refs), float).ravel()
        n, D = len(refs), memory.delay_samples
        reached = refs[np.minimum(np.arange(n) + D, n - 1)]  # the input acts after the dead time
        d = float(est.d[0]) if len(est.d) else 0.0
        targets = np.asarray(steady(reached - d) if mode == "output" else
                             steady(reached) - d if mode == "hysteresis" else
                             correct(steady(reached), np.asarray(est.d, float)), float)
        state = est.hysteresis.copy()
        for queued in () if est.queue is None else est.queue:  # what the dead time still holds comes first
            state, _ = hysteresis.step(state, float(queued))
        c = gl_weights(-alpha, n) if alpha else None
        ws, out = [], np.empty(n)
        u = np.nan  # until the first reachable target (the controller fills in the last input)
        for j in range(n):
            h = targets[j]
            if c is not None:
                past = sum(c[i] * ws[j - i] for i in range(1, j + 1))
                h = (h - est.history[j]) / sample_period**alpha - past
            try:
                state, u = hysteresis.inverse_step(state, float(h))
            except ValueError:
                pass  # out of the hysteresis' reach: hold the input
            ws.append(hysteresis.output(state))
            out[j] = u
        return out

    def symbolic_inverse(est: Estimate, refs):
        """The same steps on CasADi expressions, for a generated controller.

        An unreachable target (the hysteresis model's symbolic ``inverse_step`` gives a NaN
        input) holds the input and the state.
        """
        n, D = refs.shape[0], memory.delay_samples
        reached = ca.vertcat(*[refs[min(j + D, n - 1)] for j in range(n)])
        d = est.d[0] if est.d.numel() else 0.0
        targets = (steady(reached - d) if mode == "output" else
                   steady(reached) - d if mode == "hysteresis" else correct(steady(reached), est.d))
        state = est.hysteresis
        for i in range(est.queue.numel() if est.queue is not None else 0):
            state, _ = hysteresis.step(state, est.queue[i])
        sym_state, sym_target = ca.SX.sym("state", state.numel()), ca.SX.sym("target")
        step = ca.Function("hysteresis_inverse_step", [sym_state, sym_target],  # one Function, called per sample
                           [*hysteresis.inverse_step(sym_state, sym_target)])
        c = gl_weights(-alpha, n) if alpha else None
        u, out, ws = ca.MX(np.nan), [], []
        for j in range(n):
            h = targets[j]
            if c is not None:  # the creep inverse, as in the NumPy steps above
                past = sum(c[i] * ws[j - i] for i in range(1, j + 1))
                h = (h - est.history[j]) / sample_period**alpha - past
            state_next, u_next = step(state, h)
            reachable = ca.fabs(u_next) < ca.inf
            state = ca.if_else(reachable, state_next, state)
            u = ca.if_else(reachable, u_next, u)
            ws.append(hysteresis.output(state))
            out.append(u)
        return ca.vertcat(*out)
    inverse.hysteresis = hysteresis  # whose inverse_step it runs (named when it has no CasADi form)
    inverse.prepare = as_function  # build (and compile) ahead of the first sample: (estimate, n) -> Function
    return inverse
