"""Hysteresis models: an exact NumPy step, a smooth CasADi step and an inverse for each.

Every model follows one shape (see :mod:`models.maxwell_slip` for the first):

* parameters in a frozen dataclass, validated on construction;
* ``initial_state(...)`` returns the model's memory as a NumPy array;
* ``step(state, u) -> (state, y)``: the exact, non-smooth discrete-time definition;
* ``smooth_step(eps)``: a CasADi ``Function`` ``(state, u) -> (state_next, y)`` in which
  switching logic is replaced by smooth blends of width ``eps``;
* ``inverse_step(state, y_target) -> (state, u)``: the input that drives the output to
  ``y_target`` from ``state``.

The memory is always passed in and returned, never kept on the object.
"""

from models.lambertw import lambertw, lambertw_function
from models.maxwell_slip import MaxwellSlip
from models.parametric import ParametricHysteresis, identify_major_loop
from models.power_function import PowerFunctionHysteresis, VirtualDeformation
from models.smooth import smooth_abs, smooth_clip, smooth_max, smooth_min

__all__ = ["MaxwellSlip", "ParametricHysteresis", "PowerFunctionHysteresis", "VirtualDeformation",
           "identify_major_loop", "lambertw", "lambertw_function", "smooth_abs", "smooth_clip",
           "smooth_max", "smooth_min"]
