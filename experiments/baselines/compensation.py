"""Hysteresis compensation beside a feedback loop.

* :class:`HysteresisCompensation`: the hysteresis model fed by the *measured* output, added to
  the command (vo2012 Fig. 1);
* :class:`AdditiveCompensation` and :class:`InverseCompensation`: the two ways an inverse model
  sits between the virtual input of :class:`hystmpc.mpc.linear_mpc.InverseLinearMpc`
  (``inverse-lmpc``) and the actuator: an offset added to it, or the inverse hysteresis in series.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable

import casadi as ca
import numpy as np

from hystmpc.models.base import HysteresisModel
from hystmpc.mpc.codegen.toolchain import LOG, compiled_or_slower


class HysteresisCompensation:
    """The hysteresis model's output along the *measured* output, added to the command (vo2012 Fig. 1).

    Parameters
    ----------
    hysteresis : HysteresisModel
        The model, driven by the measured output ``measurement.y`` from the first sample on.
    """

    def __init__(self, hysteresis: HysteresisModel):
        self.hysteresis = hysteresis
        self.reset()

    def reset(self) -> None:
        """Forget the model's memory (it starts at the first measurement)."""
        self._state = None

    def __call__(self, measurement, ref_window) -> float:
        """The model's output along the measured output, this sample."""
        if self._state is None:
            self._state = self.hysteresis.initial_state(measurement.y)
        self._state, value = self.hysteresis.step(self._state, measurement.y)
        return float(value)


class AdditiveCompensation:
    """``u = v + c(measurement)``: a compensation computed from what is measured (vo2012 Fig. 1 style).

    For :class:`hystmpc.mpc.linear_mpc.InverseLinearMpc`.

    Parameters
    ----------
    offset : callable
        ``measurement -> c``, called once per sample; may keep a memory (``offset.reset()``
        is called on reset when it exists).
    sensors : callable
        ``(measurement, c) -> z``: the linear model's sensor vector.
    """

    def __init__(self, offset: Callable, sensors: Callable):
        self._offset, self._sensors = offset, sensors
        self.reset()

    def reset(self) -> None:
        """Forget the offset and its memory."""
        if hasattr(self._offset, "reset"):
            self._offset.reset()
        self.offset = 0.0

    def update(self, measurement) -> None:
        """Take this sample's offset.

        Parameters
        ----------
        measurement : Measurement
            This sample's measurement.
        """
        self.offset = float(self._offset(measurement))

    def to_input(self, v: float) -> float:
        """``v + c``.

        Parameters
        ----------
        v : float
            A virtual input.

        Returns
        -------
        float
            The actuator input.
        """
        return v + self.offset

    def to_virtual(self, u: float) -> float:
        """``u − c``.

        Parameters
        ----------
        u : float
            An actuator input.

        Returns
        -------
        float
            The virtual input.
        """
        return u - self.offset

    def applied(self, u: float) -> None:
        """Nothing: the offset follows the measurement.

        Parameters
        ----------
        u : float
            The input sent (unused).
        """

    def inputs_along(self, vs) -> np.ndarray:
        """``v + c`` for each virtual input.

        Parameters
        ----------
        vs : array_like
            Virtual inputs.

        Returns
        -------
        ndarray
            The actuator inputs.
        """
        return np.asarray(vs, float) + self.offset

    def sensors(self, measurement) -> np.ndarray:
        """The linear model's sensors.

        Parameters
        ----------
        measurement : Measurement
            This sample's measurement.

        Returns
        -------
        ndarray
            ``sensors(measurement, c)``.
        """
        return np.asarray(self._sensors(measurement, self.offset), float)


class InverseCompensation:
    """The inverse hysteresis in series with the actuator input.

    ``u = input_of(H⁻¹[hysteresis_output_of(v)])``, for
    :class:`hystmpc.mpc.linear_mpc.InverseLinearMpc`. The virtual input ``v`` is the hysteresis
    output (through an optional static map).

    Parameters
    ----------
    hysteresis : HysteresisModel
        The nominal model (its ``step`` and ``inverse_step``).
    sensors : callable or sequence of str
        ``(measurement, compensation) -> z``: the linear model's sensor vector
        (``compensation.output`` is the model's output at its memory); or the names of the
        measured signals it is (``("y",)``: the measured output), which a generated controller
        can read too.
    driven_by : callable, optional
        ``measurement -> hysteresis input``: the memory follows a measured signal; None:
        it follows the applied inputs.
    input_of, hysteresis_input_of : callable, optional
        Between the hysteresis input and the actuator input, both ways (default: the same).
    virtual_of, hysteresis_output_of : callable, optional
        Between the hysteresis output and the virtual input, both ways, monotone
        (default: the same; a static output map, such as force from flux).
    rest_input : float, optional
        The hysteresis input the memory starts from when it follows the inputs sent (the
        plant's rest input; default: the model's own initial state).
    """

    def __init__(self, hysteresis: HysteresisModel, sensors: Callable, driven_by: Callable | None = None,
                 input_of: Callable | None = None, hysteresis_input_of: Callable | None = None,
                 virtual_of: Callable | None = None, hysteresis_output_of: Callable | None = None,
                 rest_input: float | None = None):
        self.hysteresis, self._driven_by = hysteresis, driven_by
        names = not callable(sensors) and not isinstance(sensors, str) and hasattr(sensors, "__iter__")
        if not (callable(sensors) or (names and all(isinstance(n, str) for n in sensors))):
            raise ValueError(f"sensors must be a function (measurement, compensation) -> z or a sequence of measured "
                             f"signals' names such as ('y',); got {sensors!r}")
        self.sensor_names = None if callable(sensors) else tuple(sensors)
        self._sensors = sensors if callable(sensors) else (
            lambda m, comp: [m.y if name == "y" else m.sensors[name] for name in self.sensor_names])
        self._rest_input = rest_input
        self._input_of = input_of or (lambda s: s)
        self._hysteresis_input_of = hysteresis_input_of or (lambda u: u)
        self._virtual_of = virtual_of or (lambda h: h)
        self._hysteresis_output_of = hysteresis_output_of or (lambda v: v)
        self._chains: dict[int, ca.Function | None] = {}
        self.reset()

    def reset(self) -> None:
        """The model at rest."""
        self._state = None

    @property
    def output(self) -> float:
        """The model's output at its memory."""
        return float(self.hysteresis.output(self._state))

    def update(self, measurement) -> None:
        """Move the memory along the measured hysteresis input (when it follows one).

        When it follows the inputs sent, the first call sets the memory at rest.

        Parameters
        ----------
        measurement : Measurement
            This sample's measurement.
        """
        if self._driven_by is not None:
            s = float(self._driven_by(measurement))
            self._state = (self.hysteresis.initial_state(s) if self._state is None
                           else self.hysteresis.step(self._state, s)[0])
        elif self._state is None:
            self._state = (self.hysteresis.initial_state() if self._rest_input is None
                           else self.hysteresis.initial_state(self._rest_input))

    def to_input(self, v: float) -> float:
        """The input that gives the virtual input ``v`` from the present memory.

        Parameters
        ----------
        v : float
            A virtual input.

        Returns
        -------
        float
            The actuator input; NaN when ``v`` is beyond the model's reach.
        """
        try:
            target = float(self._hysteresis_output_of(v))
            return float(self._input_of(self.hysteresis.inverse_step(self._state, target)[1]))
        except ValueError:  # beyond the model's reach: the nearest input the bounds allow follows
            return np.nan

    def to_virtual(self, u: float) -> float:
        """The virtual input the input ``u`` gives from the present memory.

        Parameters
        ----------
        u : float
            An actuator input.

        Returns
        -------
        float
            The virtual input (the memory is left as it is).
        """
        return float(self._virtual_of(self.hysteresis.step(self._state, float(self._hysteresis_input_of(u)))[1]))

    def applied(self, u: float) -> None:
        """Move the memory with the applied input (when it follows the inputs).

        Parameters
        ----------
        u : float
            The input sent.
        """
        if self._driven_by is None:
            self._state = self.hysteresis.step(self._state, float(self._hysteresis_input_of(u)))[0]

    def inputs_along(self, vs) -> np.ndarray:
        """The inputs that give the virtual inputs ``vs`` one after another.

        The memory moves along them from its present state (which is left as it is).

        Where the model's inverse takes CasADi expressions (hystmpc's own models: by bisection,
        close to the search :meth:`to_input` runs) the chain is one compiled Function, faster
        than the search repeated in Python.

        Parameters
        ----------
        vs : array_like
            Virtual inputs, in order.

        Returns
        -------
        ndarray
            The actuator inputs; NaN where one is out of reach, the memory then held.
        """
        vs = np.asarray(vs, float).ravel()
        fun = self._chain(len(vs))
        if fun is not None:
            return np.asarray(fun(self._state, vs), float).ravel()
        state, inputs = self._state, []
        for v in vs:
            try:
                state, h = self.hysteresis.inverse_step(state, float(self._hysteresis_output_of(v)))
                inputs.append(float(self._input_of(h)))
            except ValueError:
                inputs.append(np.nan)
        return np.array(inputs)

    def sensors(self, measurement) -> np.ndarray:
        """The linear model's sensors.

        Parameters
        ----------
        measurement : Measurement
            This sample's measurement.

        Returns
        -------
        ndarray
            ``sensors(measurement, self)``.
        """
        return np.asarray(self._sensors(measurement, self), float)

    def memory_at_rest(self) -> np.ndarray:
        """The memory before the first sample (it follows the inputs sent).

        Returns
        -------
        ndarray
            The hysteresis state at rest.

        Raises
        ------
        ValueError
            When the memory follows a measured signal instead.
        """
        self._follows_inputs()
        return np.asarray(self.hysteresis.initial_state() if self._rest_input is None
                          else self.hysteresis.initial_state(self._rest_input), float).ravel()

    def step_expression(self, memory, u):
        """The memory moved by the input ``u``, and the virtual input ``u`` gives, as CasADi expressions.

        This is :meth:`to_virtual` then :meth:`applied`, for a generated controller.

        Parameters
        ----------
        memory : casadi.MX
            The hysteresis state.
        u : casadi.MX
            The input sent.

        Returns
        -------
        tuple
            ``(memory_next, v)``.

        Raises
        ------
        ValueError
            When the memory follows a measured signal, or the model or the maps take no
            CasADi expressions.
        """
        self._follows_inputs()
        memory_next, h = self.hysteresis.step(memory, self._hysteresis_input_of(u))
        return memory_next, self._virtual_of(h)

    def inputs_along_function(self, n: int) -> ca.Function:
        """:meth:`inputs_along` for ``n`` virtual inputs: ``(memory, vs) -> inputs``, not compiled.

        Parameters
        ----------
        n : int
            Number of virtual inputs.

        Returns
        -------
        casadi.Function
            NaN where an input is out of reach (the memory then held).

        Raises
        ------
        ValueError
            When the model's inverse or the maps take no CasADi expressions.
        """
        size = len(self.hysteresis.initial_state() if self._state is None else self._state)
        x, target = ca.SX.sym("state", size), ca.SX.sym("target")
        step = ca.Function("inverse_step", [x, target], [*self.hysteresis.inverse_step(x, target)])
        start, vs = ca.MX.sym("state", size), ca.MX.sym("v", n)
        state, inputs = start, []
        for j in range(n):
            state_next, h = step(state, self._hysteresis_output_of(vs[j]))
            reachable = ca.fabs(h) < ca.inf
            state = ca.if_else(reachable, state_next, state)
            inputs.append(ca.if_else(reachable, self._input_of(h), np.nan))
        return ca.Function("inputs_along", [start, vs], [ca.vertcat(*inputs)])

    def _follows_inputs(self) -> None:
        if self._driven_by is not None:
            raise ValueError("this compensation's memory follows a measured signal, not the inputs sent")

    def prepare_chain(self, n: int) -> None:
        """Build (and compile) :meth:`inputs_along` for ``n`` virtual inputs now, not at the first sample.

        Parameters
        ----------
        n : int
            Length of the plans (the horizon).
        """
        self._chain(n)

    def _chain(self, n: int) -> ca.Function | None:
        """:meth:`inputs_along` for ``n`` virtual inputs as a compiled Function.

        None when the model's inverse has no CasADi form; the Python loop then runs, after a notice.
        """
        if n not in self._chains:
            fun = None
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    fun = self.inputs_along_function(n)
            except Exception as exc:  # noqa: BLE001 - a NumPy-only inverse fails in many ways
                LOG.warning(f"{type(self.hysteresis).__name__}'s inverse takes no CasADi expressions "
                            f"({str(exc)[:200]}): a planned sequence of inputs is inverted in Python, slower")
            self._chains[n] = None if fun is None else compiled_or_slower(
                fun, "a planned sequence of inputs is inverted in-process, slower")
        return self._chains[n]
