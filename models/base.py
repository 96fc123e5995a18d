"""The shape every hysteresis model shares: :class:`HysteresisModel`.

A hysteresis model maps an input sequence to an output sequence with memory. hystmpc
keeps three faces of each model and one state layout for all of them:

* **state**: a NumPy vector, named by ``state_names``. ``state[0]`` is always the last
  input, the point the next move is measured from; the rest is the model's memory
  (element forces, turning points, kernel outputs...). The memory is passed in and
  returned, never kept on the object, so one model object serves any number of plants,
  controllers and predictions at once.
* ``step(state, u) -> (state, y)``: the exact, non-smooth discrete-time definition (the
  paper's). Plants and feed-forward baselines use it.
* ``smooth_step(eps, direction_eps=None)``: a CasADi ``Function`` ``(state, u) ->
  (state_next, y)`` with the switching logic replaced by smooth blends of width ``eps``
  (and the detection of the input's direction by ``direction_eps`` where the model has
  one; a model without raises ``ValueError`` when given one). As ``eps -> 0`` it
  converges to ``step``; each model states how fast in its docstring. The NMPC's
  prediction models use it.
* ``inverse_step(state, y_target) -> (state, u)``: an input that drives the output to
  ``y_target`` from ``state``, and the state after it. Warm starts and inverse
  feed-forward use it.

``tests/test_hysteresis_contract.py`` runs every model through the same checks.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import casadi as ca
import numpy as np


@runtime_checkable
class HysteresisModel(Protocol):
    """Exact step, smooth CasADi step and inverse of one hysteresis model (see the module)."""

    @property
    def state_names(self) -> tuple[str, ...]:
        """One name per state entry; the first is the last input."""

    def initial_state(self, u0: float = 0.0) -> np.ndarray:
        """A relaxed (demagnetised) state at input ``u0``.

        Parameters
        ----------
        u0 : float, optional
            Input the state rests at.

        Returns
        -------
        ndarray
            The state, one entry per ``state_names``.
        """

    def output(self, state):
        """Output of a state: a float for a NumPy state, an expression for a CasADi one.

        Parameters
        ----------
        state : ndarray or CasADi expression
            A state.

        Returns
        -------
        float or CasADi expression
            The output at ``state``.
        """

    def step(self, state, u: float) -> tuple[np.ndarray, float]:
        """Exact step to input ``u``: ``(state_next, y)``.

        Parameters
        ----------
        state : ndarray
            State before the step.
        u : float
            New input.

        Returns
        -------
        state_next : ndarray
            State after the step.
        y : float
            Output after the step.
        """

    def smooth_step(self, eps: float, direction_eps: float | None = None) -> ca.Function:
        """Smooth step ``(state, u) -> (state_next, y)`` as a CasADi Function.

        Parameters
        ----------
        eps : float
            Width of the smooth blends, > 0.
        direction_eps : float, optional
            Width of the input-direction detection, for models that have one (a model
            without raises ``ValueError`` when given one).

        Returns
        -------
        casadi.Function
            ``(state, u) -> (state_next, y)``.
        """

    def inverse_step(self, state, y_target: float) -> tuple[np.ndarray, float]:
        """Input that moves the output to ``y_target``, and the state after it: ``(state, u)``.

        Parameters
        ----------
        state : ndarray
            State to move from.
        y_target : float
            Output to reach.

        Returns
        -------
        state : ndarray
            State after the move.
        u : float
            The input.
        """


class SteppedModel:
    """Mixin for models with ``initial_state(u0)`` and ``step(state, u) -> (state, y)``."""

    @property
    def n_state(self) -> int:
        """Length of the state vector."""
        return len(self.state_names)

    def simulate(self, inputs, state=None) -> tuple[np.ndarray, np.ndarray]:
        """Exact response to an input sequence; returns ``(outputs, final_state)``.

        Parameters
        ----------
        inputs : array_like
            Input at each sample.
        state : array_like, optional
            Initial state (default: ``initial_state(inputs[0])``).

        Returns
        -------
        outputs : ndarray
            Output after each input.
        final_state : ndarray
            State after the last input.
        """
        state = self.initial_state(inputs[0]) if state is None else np.asarray(state, float)
        out = np.empty(len(inputs))
        for i, u in enumerate(inputs):
            state, out[i] = self.step(state, u)
        return out, state


def symbolic(value) -> bool:
    """Whether ``value`` is a CasADi expression (``output`` methods then return one too).

    Parameters
    ----------
    value : object
        A NumPy or CasADi value.

    Returns
    -------
    bool
        True for ``casadi.SX`` and ``casadi.MX`` (a ``casadi.DM`` is a number, not an expression).
    """
    return isinstance(value, (ca.SX, ca.MX))


def clip(value, lower, upper):
    """``numpy.clip`` on CasADi expressions: a NaN stays NaN.

    Unlike with ``fmin``/``fmax``, which would return a bound, code generated from a model thus
    fails where the NumPy model does.

    Parameters
    ----------
    value : CasADi expression
        Value to clip (elementwise).
    lower, upper : float, casadi.DM or CasADi expression
        Bounds.

    Returns
    -------
    CasADi expression
        ``value`` held within ``[lower, upper]``.
    """
    return ca.if_else(value < lower, lower, ca.if_else(value > upper, upper, value))


def interp(x, xp, fp):
    """``numpy.interp(x, xp, fp)`` for NumPy values, and the same formula for a CasADi ``x``.

    For a CasADi ``x`` the formula (the segment's slope times the distance from its left point,
    plus that point's value; the end values held outside) is built as nested ``if_else``.

    Parameters
    ----------
    x : float, ndarray or CasADi expression
        Where to interpolate.
    xp : array_like
        Increasing abscissae.
    fp : array_like
        Values at ``xp``.

    Returns
    -------
    float, ndarray or CasADi expression
        The interpolated value(s), a CasADi expression for a CasADi ``x``.
    """
    if not symbolic(x):
        return np.interp(x, xp, fp)
    xp, fp = np.asarray(xp, float), np.asarray(fp, float)
    slopes = (fp[1:] - fp[:-1]) / (xp[1:] - xp[:-1])
    value = ca.if_else(x >= xp[-1], fp[-1], x * np.nan)  # x >= the last point, or NaN
    for j in range(len(xp) - 2, -1, -1):
        value = ca.if_else(x < xp[j + 1], slopes[j] * (x - xp[j]) + fp[j], value)
    return ca.if_else(x < xp[0], fp[0], value)


def builtin_max(a, b):
    """Python's ``max(a, b)`` on CasADi expressions: ``a`` unless ``b > a`` (NaN included).

    Parameters
    ----------
    a, b : float or CasADi expression
        The two values.

    Returns
    -------
    CasADi expression
        The larger.
    """
    return ca.if_else(b > a, b, a)


def builtin_min(a, b):
    """Python's ``min(a, b)`` on CasADi expressions: ``a`` unless ``b < a`` (NaN included).

    Parameters
    ----------
    a, b : float or CasADi expression
        The two values.

    Returns
    -------
    CasADi expression
        The smaller.
    """
    return ca.if_else(b < a, b, a)


def smooth_function(name: str, n_state: int, expressions) -> ca.Function:
    """``(state, u) -> (state_next, y)`` from ``expressions(state, u) -> (state_next, y)`` on SX symbols.

    Every model's ``smooth_step`` returns its Function through this, so all share the
    input and output names ``state``, ``u``, ``state_next``, ``y``.

    Parameters
    ----------
    name : str
        Name of the Function.
    n_state : int
        Length of the state.
    expressions : callable
        ``(state, u) -> (state_next, y)`` on SX symbols.

    Returns
    -------
    casadi.Function
        ``(state, u) -> (state_next, y)``.
    """
    state = ca.SX.sym("state", n_state)
    u = ca.SX.sym("u")
    nxt, y = expressions(state, u)
    return ca.Function(name, [state, u], [nxt, y], ["state", "u"], ["state_next", "y"])


def check_smoothing(eps: float, direction_eps: float | None = None, has_direction: bool = True) -> None:
    """``ValueError`` unless ``eps > 0`` and ``direction_eps`` is None or > 0 (and allowed).

    Parameters
    ----------
    eps : float
        Smoothing width; must be finite.
    direction_eps : float, optional
        Width of the direction detection; None: unset.
    has_direction : bool, optional
        Whether the model detects the input's direction; without, ``direction_eps`` must be None.
    """
    if not (np.isfinite(eps) and eps > 0):
        raise ValueError(f"eps must be finite and > 0, got {eps}")
    if direction_eps is None:
        return
    if not has_direction:
        raise ValueError("this model detects no input direction: direction_eps does not apply (leave it unset)")
    if not (np.isfinite(direction_eps) and direction_eps > 0):
        raise ValueError(f"direction_eps must be finite and > 0, got {direction_eps}")
