"""Generic nonlinear MPC: nothing in this package knows about a particular actuator.

* :class:`NmpcController`: the sampled controller (observer, warm starts, solve, fallback)
  for any prediction model of :mod:`hystmpc.models.prediction`.
* :class:`NmpcSettings`, :class:`InputBounds`, :class:`SolverSettings`: what it is told.
* :class:`MultipleShootingProblem`, :class:`SingleShootingProblem`: the tracking NLPs.
* :class:`DisturbanceEKF`, :class:`StateObserver`, :class:`MemoryObserver`: estimation.
* :class:`InverseLinearMpc`, :class:`LinearMpcSettings`: the strong conventional
  alternative, an inverse-model compensation plus an offset-free linear MPC (OSQP).
* :mod:`hystmpc.mpc.runtime`: where the NMPC runs (Python or its generated C) and where its
  inverse-model inputs come from, as :class:`NmpcSettings` ask (:func:`~hystmpc.mpc.runtime.assemble_nmpc`).
* :mod:`hystmpc.mpc.rti`: the real-time iteration step as one code-generatable Function;
  :mod:`hystmpc.mpc.qp`: the interior-point QP it can use instead of DAQP.
"""

from hystmpc.mpc.controller import NmpcController, default_observer
from hystmpc.mpc.estimator import DisturbanceEKF
from hystmpc.mpc.linear_mpc import InverseLinearMpc, LinearMpcSettings
from hystmpc.mpc.multiple_shooting import MultipleShootingProblem
from hystmpc.mpc.observer import Estimate, MemoryObserver, StateObserver, memory_inverse
from hystmpc.mpc.problem import Solution
from hystmpc.mpc.settings import (
    SOLVERS,
    GaussNewtonSettings,
    InputBounds,
    NlpSettings,
    NmpcSettings,
    RtiSettings,
    SolverSettings,
)
from hystmpc.mpc.single_shooting import SingleShootingProblem

__all__ = ["SOLVERS", "DisturbanceEKF", "Estimate", "GaussNewtonSettings", "InputBounds", "InverseLinearMpc",
           "LinearMpcSettings", "MemoryObserver",
           "MultipleShootingProblem", "NlpSettings", "NmpcController", "NmpcSettings",
           "RtiSettings", "SingleShootingProblem", "Solution", "SolverSettings", "StateObserver",
           "default_observer", "memory_inverse"]
