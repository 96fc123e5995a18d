"""Hysteresis models and the prediction models built from them.

Each hysteresis model has an exact NumPy step, a smooth CasADi step and an inverse.

Every hysteresis model follows :class:`HysteresisModel` (:mod:`hystmpc.models.base`): the
memory is a state vector passed in and returned, never kept on the object.
:func:`build_prediction_model` composes a hysteresis model with an actuator's
:class:`Dynamics` into the NMPC's prediction model.
"""

from hystmpc.models.base import HysteresisModel
from hystmpc.models.bouc_wen import BoucWen
from hystmpc.models.document import model_document, read_model_document
from hystmpc.models.fckp import Fckp, FckpParams
from hystmpc.models.fractional import GrunwaldLetnikov, gl_weights
from hystmpc.models.generalised_pi import GeneralisedPI
from hystmpc.models.identification import FAMILIES, FitError, Identified, identify
from hystmpc.models.identify_auto import identify_auto
from hystmpc.models.integrators import rk4
from hystmpc.models.kp import KrasnoselskiiPokrovskii
from hystmpc.models.lambertw import lambertw, lambertw_function
from hystmpc.models.linear_dynamics import LinearDynamics
from hystmpc.models.maxwell_slip import MaxwellSlip, play_operator
from hystmpc.models.parametric import ParametricHysteresis, identify_major_loop
from hystmpc.models.power_function import PowerFunctionHysteresis, VirtualDeformation
from hystmpc.models.prandtl_ishlinskii import PrandtlIshlinskii
from hystmpc.models.prediction import (
    CreepPredictionModel,
    Dynamics,
    InputMemory,
    PredictionModel,
    Smoothing,
    build_prediction_model,
)
from hystmpc.models.preisach import Preisach
from hystmpc.models.scaled import Offset, Scaled
from hystmpc.models.smooth import smooth_abs, smooth_clip, smooth_max, smooth_min

__all__ = ["FAMILIES", "BoucWen", "CreepPredictionModel", "Dynamics", "Fckp", "FckpParams", "FitError",
           "GeneralisedPI", "GrunwaldLetnikov", "HysteresisModel", "Identified", "InputMemory",
           "KrasnoselskiiPokrovskii", "LinearDynamics", "MaxwellSlip", "Offset", "ParametricHysteresis",
           "PowerFunctionHysteresis", "PrandtlIshlinskii", "PredictionModel", "Preisach", "Scaled",
           "Smoothing", "VirtualDeformation", "build_prediction_model", "gl_weights", "identify", "identify_auto",
           "identify_major_loop", "lambertw", "lambertw_function", "model_document", "play_operator",
           "read_model_document", "rk4", "smooth_abs", "smooth_clip", "smooth_max", "smooth_min"]
