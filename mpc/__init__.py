"""Generic nonlinear MPC: nothing in this package knows about a particular actuator.

* :class:`mpc.model.PredictionModel`: discrete-time nominal model ``x+ = F(x, u, d)``,
  ``y = h(x, d)`` with a disturbance ``d`` held constant over the horizon (offset-free).
* :class:`mpc.estimator.DisturbanceEKF`: extended Kalman filter on ``[x; d]``.
* :class:`mpc.nmpc.Nmpc`: multiple-shooting tracking NLP (IPOPT by default).
* :class:`mpc.controller.NmpcController`: estimator + NLP + warm starts + fallback.
* :mod:`mpc.rti`: the real-time iteration step as one code-generatable Function;
  :mod:`mpc.qp`: the interior-point QP it uses; :mod:`mpc.shooting`: single shooting.
"""

from mpc.controller import NmpcController
from mpc.estimator import DisturbanceEKF, OpenLoopEstimator
from mpc.model import PredictionModel
from mpc.nmpc import SOLVERS, Nmpc, NmpcSettings, NmpcStep

__all__ = ["SOLVERS", "DisturbanceEKF", "OpenLoopEstimator", "Nmpc", "NmpcController", "NmpcSettings", "NmpcStep",
           "PredictionModel"]
