"""Simulated actuators (the truth the controllers never see directly) and their prediction models.

Each actuator's prediction model is beside its physics, where the controllers' model is that
physics with nominal parameters (pam, compliant, dea). Where the controllers know the
actuator only through a model identified from measurements, that model is a model family
in :mod:`hystmpc.models` (reluctance's look-up tables, :mod:`hystmpc.models.reluctance`;
an actuator file's identified family), and the plant here is the truth alone.

Every plant follows :class:`Plant`: ``reset(seed) -> Measurement``, ``step(u) ->
Measurement`` and ``sample_period``; it runs the exact, non-smooth hysteresis with its own
(deliberately off-nominal) parameters. :class:`HysteresisActuator` builds one from any
hysteresis model and dynamics.
"""

from hystmpc.plants.actuator import HysteresisActuator
from hystmpc.plants.base import Measurement, Plant
from hystmpc.plants.compliant import CompliantActuator, CompliantParams
from hystmpc.plants.dea import DeaActuator, DeaParams
from hystmpc.plants.pam_joint import PamJoint, PamJointParams
from hystmpc.plants.reluctance import ReluctanceActuator, ReluctanceParams

__all__ = ["CompliantActuator", "CompliantParams", "DeaActuator", "DeaParams", "HysteresisActuator", "Measurement",
           "PamJoint", "PamJointParams", "Plant", "ReluctanceActuator", "ReluctanceParams"]
