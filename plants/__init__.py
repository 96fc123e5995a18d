"""Simulated actuators (the truth the controllers never see directly).

Every plant has ``reset(seed) -> Measurement`` and ``step(u) -> Measurement`` and runs the
exact, non-smooth hysteresis with its own (deliberately off-nominal) parameters.
"""

from plants.base import Measurement
from plants.compliant import CompliantActuator, CompliantParams
from plants.pam_joint import PamJoint, PamJointParams
from plants.reluctance import ReluctanceActuator, ReluctanceParams

__all__ = ["CompliantActuator", "CompliantParams", "Measurement", "PamJoint", "PamJointParams",
           "ReluctanceActuator", "ReluctanceParams"]
